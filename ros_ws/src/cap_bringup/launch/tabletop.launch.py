"""The table-top graph as four processes, for a regular ROS 2 Jazzy install (`ros2 launch` of this file).

    ros2 launch cap_bringup tabletop.launch.py                       # simulator in real time, reference cassette
    ros2 launch cap_bringup tabletop.launch.py namespace:=robot1     # every name under /robot1
    ros2 launch cap_bringup tabletop.launch.py perception:=rgbd llm_backend:=http   # CAP_LLM_* from the environment

Each node reads its package's config/*.yaml (overrides of the defaults its config dataclass declares), then the
arguments below. The nodes take their time from the simulator's clock (use_sim_time); under a namespace that clock
is <namespace>/clock, as in `cap up --namespace`. The one-process graph of `cap up` (cap_bringup/graph.py) runs
the same nodes with the same files.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

ARGUMENTS = (
    ('namespace', '', 'namespace of the whole graph, e.g. robot1 (empty: none)'),
    ('seed', '0', 'scene seed'),
    ('objects', '', 'comma-separated objects, e.g. "red block, blue bowl" (empty: the seed\'s default episode)'),
    ('perception', 'ground_truth', 'ground_truth or rgbd'),
    ('llm_backend', 'cassette', 'cassette (offline) or http (CAP_LLM_BASE_URL, CAP_LLM_MODEL from the environment)'),
    ('domain', 'tabletop', 'the domain whose prompts and robot API lmp_node runs'),
)


def _config(package: str, filename: str) -> str:
    return os.path.join(get_package_share_directory(package), 'config', filename)


def _nodes(context):
    value = {name: LaunchConfiguration(name).perform(context) for name, _, _ in ARGUMENTS}
    namespace = value['namespace'].strip('/')
    clock = f'/{namespace}/clock' if namespace else '/clock'
    common = {'namespace': namespace, 'remappings': [('/clock', clock)], 'output': 'screen'}
    sim_time = {'use_sim_time': True}
    rgbd = value['perception'] == 'rgbd'
    return [
        Node(package='cap_sim_bridge', executable='sim_bridge', name='sim_bridge',
             parameters=[_config('cap_sim_bridge', 'sim_bridge.yaml'),
                         {'seed': int(value['seed']), 'objects': value['objects'], 'real_time': True}], **common),
        Node(package='cap_perception', executable='perception_node', name='perception_node',
             parameters=[_config('cap_perception', 'perception.yaml'), {'source': value['perception']}, sim_time],
             **common),
        Node(package='cap_control', executable='pick_place', name='pick_place',
             parameters=[_config('cap_control', 'pick_place.yaml'), {'clear_view': rgbd}, sim_time], **common),
        Node(package='cap_lmp_ros', executable='lmp_node', name='lmp_node',
             parameters=[_config('cap_lmp_ros', 'lmp_node.yaml'),
                         {'llm_backend': value['llm_backend'], 'domain': value['domain']}, sim_time], **common),
    ]


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription(
        [DeclareLaunchArgument(name, default_value=default, description=description)
         for name, default, description in ARGUMENTS] + [OpaqueFunction(function=_nodes)])
