"""The launch files name executables and config files that the workspace really installs.

ROS 2's launch packages are not on PyPI, so the files are not run here; this reads them and checks every node they
start against the packages' entry points and config folders.
"""
from __future__ import annotations

import ast
import pathlib
import re

import pytest

SRC = pathlib.Path(__file__).resolve().parents[2]
LAUNCH_FILES = sorted((SRC / 'cap_bringup' / 'launch').glob('*.launch.py'))


def _keywords(call: ast.Call) -> dict[str, object]:
    return {k.arg: k.value.value for k in call.keywords if isinstance(k.value, ast.Constant)}


def _nodes(path: pathlib.Path) -> list[dict[str, object]]:
    tree = ast.parse(path.read_text(encoding='utf-8'))
    return [_keywords(node) for node in ast.walk(tree)
            if isinstance(node, ast.Call) and getattr(node.func, 'id', None) == 'Node']


def _configs(path: pathlib.Path) -> list[tuple[str, str]]:
    tree = ast.parse(path.read_text(encoding='utf-8'))
    return [(node.args[0].value, node.args[1].value) for node in ast.walk(tree)
            if isinstance(node, ast.Call) and getattr(node.func, 'id', None) == '_config']


def _console_scripts(package: str) -> set[str]:
    text = (SRC / package / 'setup.py').read_text(encoding='utf-8')
    return set(re.findall(r"'(\w+) = [\w.]+:\w+'", text))


def test_there_is_a_launch_file():
    assert [path.name for path in LAUNCH_FILES] == ['tabletop.launch.py']


@pytest.mark.parametrize('path', LAUNCH_FILES, ids=lambda path: path.name)
def test_every_node_is_an_installed_executable_with_its_config(path):
    nodes = _nodes(path)
    assert {node['package'] for node in nodes} == {'cap_sim_bridge', 'cap_perception', 'cap_control', 'cap_lmp_ros',
                                                  'cap_bringup'}
    for node in nodes:
        assert node['executable'] in _console_scripts(node['package']), node
    for package, filename in _configs(path):
        assert (SRC / package / 'config' / filename).is_file(), (package, filename)
    assert "('share/' + package_name + '/launch', glob('launch/*.launch.py'))" in (
        SRC / 'cap_bringup' / 'setup.py').read_text(encoding='utf-8')
