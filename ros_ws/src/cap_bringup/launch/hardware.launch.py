"""A domain's graph on a real robot, one process per node, for a regular ROS 2 Jazzy install: the robot's own drivers
(arm controller, gripper controller, camera, robot_state_publisher, nav2 on a mobile robot) must be running; this
starts the calibration's publisher, the domain's perception and control nodes pointed at the profile's interfaces,
lmp_node and the visualization node, and with console:=true the web console. Run `cap preflight PROFILE` first: it
says what the robot still lacks.

    ros2 launch cap_bringup hardware.launch.py profile:=/path/to/my_robot.yaml
    ros2 launch cap_bringup hardware.launch.py profile:=ur5e_robotiq_d435 llm_backend:=local console:=true

Each node takes its defaults from its config dataclass, then its package's config/*.yaml, then the profile's values
(cap_bringup.hardware); `cap up --hardware PROFILE` runs the same nodes with the same values in one process.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from cap_bringup.hardware import hardware_overrides
from cap_bringup.namespaces import normalise_namespace
from cap_bringup.nodes import graph_nodes, twin_launch_arguments
from cap_hardware.profile import load_profile
from cap_lmp_ros.domains.registry import get_domain

ARGUMENTS = (
    ('profile', 'the hardware profile: a YAML file, or the name of a shipped one (cap_hardware/profiles)'),
    ('namespace', 'namespace of the graph, e.g. robot1 (empty: none)'),
    ('llm_backend', 'cassette, http (CAP_LLM_BASE_URL, CAP_LLM_MODEL from the environment) or local'),
    ('console', 'true: also the web console on 127.0.0.1 (port 8765)'),
    ('rehearse', 'always (the default on a robot), on_approval or off: rehearse each program on a twin first'),
)


def _config(package: str, filename: str) -> str:
    return os.path.join(get_package_share_directory(package), 'config', filename)


def _nodes(context):
    value = {name: LaunchConfiguration(name).perform(context).strip() for name, _ in ARGUMENTS}
    if not value['profile']:
        raise RuntimeError('hardware.launch.py needs profile:=<a hardware profile>')
    profile = load_profile(value['profile'])
    common = {'namespace': normalise_namespace(value['namespace']), 'output': 'screen'}
    domain = get_domain(profile.domain)
    chosen = hardware_overrides(profile)
    if value['llm_backend']:
        chosen['lmp_node']['llm_backend'] = value['llm_backend']
    if value['rehearse']:
        chosen['lmp_node']['rehearse'] = value['rehearse']
    console = [Node(package='cap_bringup', executable='console', name='console', **common)] \
        if value['console'].lower() == 'true' else []
    robot = [Node(package=spec.package, executable=spec.executable, name=spec.name,
                  parameters=[_config(spec.package, spec.config_file), chosen.get(spec.name, {})], **common)
             for spec in graph_nodes(domain, hardware=True)]
    # The twin is a simulator on every robot: the same nodes as tabletop.launch.py starts for it.
    twin = [Node(**arguments) for arguments in twin_launch_arguments(domain, common['namespace'],
                                                                      chosen['lmp_node']['rehearse'], _config)]
    return console + robot + twin


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription(
        [DeclareLaunchArgument(name, default_value='', description=description) for name, description in ARGUMENTS]
        + [OpaqueFunction(function=_nodes)])
