"""The launch files name executables and config files that the workspace really installs.

ROS 2's launch packages are not on PyPI, so the files are not run here; the launch file starts the nodes of the
domain's graph (cap_bringup.nodes.graph_nodes), and this checks every such node of every domain against the
packages' installed entry points (which a setup.py may derive from its folders), config folders and modules.
"""
from __future__ import annotations

import importlib.metadata
import pathlib

import pytest

from cap_bringup.nodes import graph_nodes
from cap_lmp_ros.domains.registry import domain_names, get_domain

SRC = pathlib.Path(__file__).resolve().parents[2]
LAUNCH_FILES = sorted((SRC / 'cap_bringup' / 'launch').glob('*.launch.py'))


def _console_scripts(package: str) -> set[str]:
    """The executables the built workspace installed for `package` (its console_scripts entry points)."""
    return {entry.name for entry in importlib.metadata.distribution(package).entry_points
            if entry.group == 'console_scripts'}


def test_there_is_a_launch_file():
    assert [path.name for path in LAUNCH_FILES] == ['hardware.launch.py', 'tabletop.launch.py']


@pytest.mark.parametrize('domain', domain_names())
def test_every_node_of_every_domain_is_an_installed_executable_with_its_config(domain):
    """The launch files start graph_nodes(domain) (simulated, and on a real robot) by executable and config file;
    cap up builds node_class."""
    nodes = graph_nodes(get_domain(domain))
    assert nodes[0].name == 'sim_bridge' and [spec.name for spec in nodes[-2:]] == ['lmp_node', 'visualization']
    on_hardware = graph_nodes(get_domain(domain), hardware=True)
    assert on_hardware[0].name == 'calibration' and not {'sim_bridge', 'robot_state', 'navigation'} & {
        spec.name for spec in on_hardware}
    for spec in {*nodes, *on_hardware}:
        assert spec.executable in _console_scripts(spec.package), spec
        assert (SRC / spec.package / 'config' / spec.config_file).is_file(), spec
        module, _, name = spec.node_class.partition(':')
        assert spec.package == module.split('.')[0], spec
        assert f'class {name}(' in (SRC / spec.package / (module.replace('.', '/') + '.py')).read_text(), spec


def test_the_table_top_runs_perception_and_pick_and_place():
    assert [spec.name for spec in graph_nodes(get_domain('tabletop'))] == [
        'sim_bridge', 'robot_state', 'perception_node', 'pick_place', 'lmp_node', 'visualization']


@pytest.mark.parametrize('path', LAUNCH_FILES, ids=lambda path: path.name)
def test_the_launch_file_starts_the_domain_nodes_and_is_installed(path):
    text = path.read_text(encoding='utf-8')
    assert 'graph_nodes(domain' in text and 'spec.executable' in text and 'spec.config_file' in text
    assert "('share/' + package_name + '/launch', glob('launch/*.launch.py'))" in (
        SRC / 'cap_bringup' / 'setup.py').read_text(encoding='utf-8')
