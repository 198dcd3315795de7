"""A domain's graph as one process per node, for a regular ROS 2 Jazzy install (`ros2 launch` of this file): the
simulator and robot_state (/robot_description and the robot's links on /tf), the domain's perception and control
nodes (the table top's by default: perception and pick-and-place), lmp_node and the visualization node (/cap/markers
for RViz), and with console:=true the web console. On a real robot: hardware.launch.py.

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

from cap_bringup.nodes import SIM_BRIDGE_NODE, graph_nodes, twin_launch_arguments
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
    ('rehearse', 'always or on_approval: rehearse each program on a twin (its nodes under <namespace>/twin) before '
                 'the robot moves (lmp_node; empty: off)'),
    ('console', 'true: also the web console on 127.0.0.1 (port 8765)'),
)


def _config(package: str, filename: str) -> str:
    return os.path.join(get_package_share_directory(package), 'config', filename)


def _nodes(context):
    value = {name: LaunchConfiguration(name).perform(context).strip() for name, _ in ARGUMENTS}
    namespace = normalise_namespace(value['namespace'])
    common = {'namespace': namespace, 'remappings': [('/clock', f'{namespace}/clock')], 'output': 'screen'}
    domain = get_domain(value['domain'] or 'tabletop')
    chosen: dict[str, dict] = {spec.name: {} for spec in graph_nodes(domain)}
    chosen.setdefault('perception_node', {})
    chosen.setdefault('pick_place', {})
    if value['seed']:
        chosen['sim_bridge']['seed'] = int(value['seed'])
    if value['objects']:
        chosen['sim_bridge']['objects'] = value['objects']
    if value['perception']:
        chosen['perception_node']['source'] = value['perception']
        if value['perception'] == 'rgbd':
            chosen['perception_node'].update(domain.rgbd_perception)  # the domain's detector and camera
        chosen['pick_place']['clear_view'] = value['perception'] == 'rgbd'
    if value['llm_backend']:
        chosen['lmp_node']['llm_backend'] = value['llm_backend']
    if value['require_approval']:
        chosen['lmp_node']['require_approval'] = value['require_approval'].lower() == 'true'
    if value['domain']:
        chosen['lmp_node']['domain'] = value['domain']
        chosen['sim_bridge']['scene'] = domain.scene  # the domain brings its scene, as in `cap up --domain`
    chosen['robot_state']['scene'] = domain.scene
    if value['rehearse']:
        chosen['lmp_node']['rehearse'] = value['rehearse']
    console = [Node(package='cap_bringup', executable='console', name='console', **common)] \
        if value['console'].lower() == 'true' else []
    # The simulator, the domain's perception and control nodes, lmp_node, visualization: `cap up`'s graph.
    graph = [Node(package=spec.package, executable=spec.executable, name=spec.name,
                  parameters=[_config(spec.package, spec.config_file), chosen.get(spec.name, {})]
                  + ([] if spec is SIM_BRIDGE_NODE else [{'use_sim_time': True}]), **common)
             for spec in graph_nodes(domain)]
    twin = [Node(**arguments) for arguments in twin_launch_arguments(domain, namespace, value['rehearse'], _config)]
    return console + graph + twin


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription(
        [DeclareLaunchArgument(name, default_value='', description=description) for name, description in ARGUMENTS]
        + [OpaqueFunction(function=_nodes)])
