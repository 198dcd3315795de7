"""The standard interfaces the graph speaks are the real ones on the wire, and a regular ROS 2 install keeps its own.

control_msgs, nav2_msgs and tf2_msgs are not on PyPI, so ros_ws/standard_interfaces declares the types the graph
uses. Their type hashes (RIHS01, computed by rosidl from every field's name and type, nested types included; comments
and constants do not count) must equal those of ROS 2 Jazzy's packages, computed from the upstream `jazzy` branches:
then a driver built against the real package and a node built against these accept each other's messages.
"""
from __future__ import annotations

import json
import os
import pathlib
import subprocess
import sys

import pytest
from ament_index_python.packages import get_package_share_directory

ROOT = pathlib.Path(__file__).resolve().parents[1]
UPSTREAM_JAZZY = {
    'control_msgs/action/FollowJointTrajectory':
        'RIHS01_738ebcb7a2d7cfa42f9f1001cc99ce3a4383d1cfe508015d9be8485e4b1c66f6',
    'control_msgs/action/GripperCommand': 'RIHS01_e17c0e644eccf14bea84a0a93e0977182872c2eb7873ca6694900059b46dbc84',
    'nav2_msgs/action/NavigateToPose': 'RIHS01_a56dba8a3234a1215e610180dc703ae25bbf406dded8b54887891c9732857eab',
    'nav2_msgs/action/NavigateThroughPoses':
        'RIHS01_4e680a34fd27772095da6ffdb32ae348adbc3d948248d38cf8d5ca3fc7a3a6c4',
    'tf2_msgs/msg/TFMessage': 'RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087',
}
STANDARD = ('control_msgs', 'nav2_msgs', 'tf2_msgs')


@pytest.mark.parametrize('type_name', sorted(UPSTREAM_JAZZY))
def test_the_type_hash_is_upstream_jazzys(type_name):
    package, kind, name = type_name.split('/')
    description = pathlib.Path(get_package_share_directory(package)) / kind / f'{name}.json'
    hashes = {entry['type_name']: entry['hash_string'] for entry in json.loads(description.read_text())['type_hashes']}
    assert hashes[type_name] == UPSTREAM_JAZZY[type_name]


def _to_build(*prefixes: pathlib.Path) -> list[str]:
    answer = subprocess.run([sys.executable, str(ROOT / 'scripts' / 'standard_interfaces.py'), *map(str, prefixes)],
                            capture_output=True, text=True, timeout=60, check=True)
    return answer.stdout.split()


def _fake_prefix(root: pathlib.Path, packages: tuple[str, ...]) -> pathlib.Path:
    """An install prefix as apt's /opt/ros/jazzy looks to ament: one index marker per package."""
    index = root / 'share' / 'ament_index' / 'resource_index' / 'packages'
    index.mkdir(parents=True)
    for package in packages:
        (index / package).write_text('')
    return root


def test_setup_builds_only_the_standard_packages_the_ros_prefix_lacks(tmp_path):
    wheels = _fake_prefix(tmp_path / 'venv', ('rclpy', 'geometry_msgs'))
    apt = _fake_prefix(tmp_path / 'opt_ros_jazzy', ('rclpy', *STANDARD))
    assert _to_build(wheels) == [f'standard_interfaces/{package}' for package in STANDARD]
    assert _to_build(apt) == []
    assert _to_build(wheels, _fake_prefix(tmp_path / 'nav2', ('nav2_msgs',))) == [
        'standard_interfaces/control_msgs', 'standard_interfaces/tf2_msgs']


def test_a_plain_colcon_build_of_the_workspace_leaves_the_standard_packages_to_the_ros_install():
    """What `cd ros_ws && colcon build` on a regular install finds: the project's packages, none of the standard."""
    colcon = pathlib.Path(sys.executable).with_name('colcon')
    listed = subprocess.run([str(colcon), 'list', '--names-only'], cwd=ROOT / 'ros_ws', capture_output=True,
                            text=True, timeout=120, env={**os.environ, 'COLCON_LOG_PATH': os.devnull})
    assert listed.returncode == 0, listed.stderr
    names = set(listed.stdout.split())
    assert 'cap_interfaces' in names and 'cap_bringup' in names
    assert names.isdisjoint(STANDARD)
