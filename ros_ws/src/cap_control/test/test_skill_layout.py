"""cap_control keeps one shape for every skill: a folder `<skill>/` with plan.py, executor.py and node.py; the plain
modules reach no ROS, no node imports another node, and every node is an executable of its folder's name with its
parameter file config/<skill>.yaml keyed by the node's name."""
from __future__ import annotations

import ast
import importlib.metadata
import pathlib
import re

import yaml

PACKAGE = pathlib.Path(__file__).resolve().parents[1]
CODE = PACKAGE / 'cap_control'
SKILLS = sorted(path.parent.name for path in CODE.glob('*/node.py'))
SHARED_PURE = ('kinematics', 'trajectory', 'ports')  # shared by the executors, below every node


def _module(path: pathlib.Path) -> str:
    parts = path.relative_to(CODE.parent).with_suffix('').parts
    return '.'.join(parts[:-1] if parts[-1] == '__init__' else parts)


MODULES = {_module(path): path for path in CODE.rglob('*.py')}


def _imports(module: str) -> set[str]:
    """Every module the module imports (lazy imports included): for `from a.b import c` a.b.c when it is a module of
    the package, else a.b."""
    found = set()
    for node in ast.walk(ast.parse(MODULES[module].read_text(encoding='utf-8'))):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found |= {f'{node.module}.{alias.name}' if f'{node.module}.{alias.name}' in MODULES else node.module
                      for alias in node.names}
    return found


def _reached(module: str) -> set[str]:
    """The modules `module` imports, and those of the package's modules it imports, and so on."""
    seen, todo = set(), [module]
    while todo:
        for name in _imports(todo.pop()) - seen:
            seen.add(name)
            if name in MODULES:
                todo.append(name)
    return seen


def test_every_skill_has_the_same_shape():
    assert SKILLS == ['controller', 'follow_path', 'mobile_pick_place', 'navigation', 'pick_place']
    for skill in SKILLS:
        assert {path.name for path in (CODE / skill).glob('*.py')} == {'__init__.py', 'plan.py', 'executor.py',
                                                                       'node.py'}, skill
        assert re.search(r'^def main\(', (CODE / skill / 'node.py').read_text(encoding='utf-8'), re.M), skill
    top = {path.stem for path in CODE.glob('*.py')}
    # Below the nodes too: the ROS plumbing they share, and the parameters naming the robot's interfaces.
    assert top == {'__init__', *SHARED_PURE, 'skill_node', 'ros_conversions', 'robot_interfaces'}


def test_no_node_module_imports_another_node_module():
    nodes = {f'cap_control.{skill}.node' for skill in SKILLS}
    for module in MODULES:
        assert _imports(module) & nodes - {module} == set(), module


def _is_ros(top: str) -> bool:
    """A ROS client library (rcl...) or a package of messages and interfaces."""
    return top.startswith('rcl') or top.endswith(('_msgs', '_interfaces'))


def test_plans_executors_and_the_shared_parts_reach_no_ros():
    pure = [f'cap_control.{skill}.{part}' for skill in SKILLS for part in ('plan', 'executor')] + \
        [f'cap_control.{name}' for name in SHARED_PURE]
    for module in pure:
        reached = _reached(module)
        assert not [name for name in reached if _is_ros(name.split('.')[0])], module
        assert not {'cap_control.skill_node', 'cap_control.ros_conversions'} & reached, module


def test_every_node_is_an_executable_of_its_folder_name_with_its_parameter_file():
    installed = {entry.name: entry.value for entry in importlib.metadata.distribution('cap_control').entry_points
                 if entry.group == 'console_scripts'}
    assert installed == {skill: f'cap_control.{skill}.node:main' for skill in SKILLS}
    for skill in SKILLS:
        name = re.search(r"super\(\).__init__\('(\w+)'", (CODE / skill / 'node.py').read_text(encoding='utf-8'))
        config = yaml.safe_load((PACKAGE / 'config' / f'{skill}.yaml').read_text(encoding='utf-8'))
        assert name is not None and list(config) == [f'/**/{name.group(1)}'], skill
    assert sorted(path.stem for path in (PACKAGE / 'config').glob('*.yaml')) == SKILLS
