"""The table-top graph as processes, for a regular ROS 2 Jazzy install (`ros2 launch` of this file): the simulator,
perception, pick-and-place, lmp_node and the visualization node (/robot_description and /cap/markers for RViz),
and with console:=true the web console.

    ros2 launch cap_bringup tabletop.launch.py                       # simulator in real time, reference cassette
    ros2 launch cap_bringup tabletop.launch.py namespace:=robot1     # every name under /robot1
    ros2 launch cap_bringup tabletop.launch.py perception:=rgbd llm_backend:=http   # CAP_LLM_* from the environment
    ros2 launch cap_bringup tabletop.launch.py console:=true require_approval:=true   # approve each program first

Each node takes its defaults from its config dataclass, then its package's config/*.yaml (keyed `/**/<node>`, so
they apply under any namespace), then the arguments below that are given. The nodes take their time from the
simulator's clock (use_sim_time); under a namespace that clock is <namespace>/clock, as in `cap up --namespace`.
The one-process graph of `cap up` (cap_bringup/graph.py) runs the same nodes with the same files.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from cap_bringup.namespaces import normalise_namespace
from cap_lmp_ros.domains.registry import get_domain

# (name, description); an argument left empty leaves the node's own default (its config dataclass, then the YAML).
ARGUMENTS = (
    ('namespace', 'namespace of the whole graph, e.g. robot1 (empty: none)'),
    ('seed', 'scene seed'),
    ('objects', 'comma-separated objects, e.g. "red block, blue bowl" (empty: the seed\'s default episode)'),
    ('perception', 'ground_truth or rgbd'),
    ('llm_backend', 'cassette (offline), http (CAP_LLM_BASE_URL, CAP_LLM_MODEL from the environment) or local (the '
                    'llama.cpp server and model of `make model`, started by lmp_node)'),
    ('domain', 'the domain whose prompts, robot API and scene run (cap_lmp_ros.domains)'),
    ('require_approval', 'true: each generated program waits for approval on /cap/approve (lmp_node)'),
    ('console', 'true: also the web console on 127.0.0.1 (port 8765)'),
)


def _config(package: str, filename: str) -> str:
    return os.path.join(get_package_share_directory(package), 'config', filename)


def _nodes(context):
    value = {name: LaunchConfiguration(name).perform(context).strip() for name, _ in ARGUMENTS}
    namespace = normalise_namespace(value['namespace'])
    common = {'namespace': namespace, 'remappings': [('/clock', f'{namespace}/clock')], 'output': 'screen'}
    sim_time = {'use_sim_time': True}
    sim: dict = {}
    if value['seed']:
        sim['seed'] = int(value['seed'])
    if value['objects']:
        sim['objects'] = value['objects']
    perception: dict = {'source': value['perception']} if value['perception'] else {}
    control: dict = {'clear_view': value['perception'] == 'rgbd'} if value['perception'] else {}
    lmp: dict = {'llm_backend': value['llm_backend']} if value['llm_backend'] else {}
    if value['require_approval']:
        lmp['require_approval'] = value['require_approval'].lower() == 'true'
    visualization: dict = {}
    if value['domain']:
        lmp['domain'] = value['domain']
        sim['scene'] = get_domain(value['domain']).scene  # the domain brings its scene, as in `cap up --domain`
        visualization['scene'] = sim['scene']
    console = [Node(package='cap_bringup', executable='console', name='console', **common)] \
        if value['console'].lower() == 'true' else []
    return console + [
        Node(package='cap_sim_bridge', executable='sim_bridge', name='sim_bridge',
             parameters=[_config('cap_sim_bridge', 'sim_bridge.yaml'), sim], **common),
        Node(package='cap_perception', executable='perception_node', name='perception_node',
             parameters=[_config('cap_perception', 'perception.yaml'), perception, sim_time], **common),
        Node(package='cap_control', executable='pick_place', name='pick_place',
             parameters=[_config('cap_control', 'pick_place.yaml'), control, sim_time], **common),
        Node(package='cap_lmp_ros', executable='lmp_node', name='lmp_node',
             parameters=[_config('cap_lmp_ros', 'lmp_node.yaml'), lmp, sim_time], **common),
        Node(package='cap_bringup', executable='visualization_node', name='visualization',
             parameters=[visualization, sim_time], **common),
    ]


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription(
        [DeclareLaunchArgument(name, default_value='', description=description) for name, description in ARGUMENTS]
        + [OpaqueFunction(function=_nodes)])
