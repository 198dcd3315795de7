"""The nodes of a domain's graph, as `cap up` and the launch files start them (no rclpy here).

A simulated graph starts with the simulator and robot_state (the robot's links on /tf), which stand in for a robot's
drivers; the domain's perception and control nodes come next (`Domain.nodes`), then lmp_node and the visualization
node (/cap/markers for RViz). On a real robot (hardware mode) the drivers are the robot's own: the graph starts the
calibration's publisher instead, and none of the domain's nodes that stand in for a robot's servers (the navigation
node, where nav2 runs). Nodes are named by strings (cap_lmp_ros.domains.registry.NodeSpec), so that a domain is
described without importing its nodes; the one-process graph loads the classes, a launch file starts the executables.
"""
from __future__ import annotations

import importlib
from typing import Callable

from cap_lmp_ros.domains.registry import Domain, NodeSpec

SIM_BRIDGE_NODE = NodeSpec('sim_bridge', 'cap_sim_bridge', 'sim_bridge', 'cap_sim_bridge.bridge_node:SimBridgeNode',
                           'sim_bridge.yaml')
ROBOT_STATE_NODE = NodeSpec('robot_state', 'cap_sim_bridge', 'robot_state',
                            'cap_sim_bridge.robot_state_node:RobotStateNode', 'robot_state.yaml')
CALIBRATION_NODE = NodeSpec('calibration', 'cap_bringup', 'calibration', 'cap_bringup.calibration_node:CalibrationNode',
                            'calibration.yaml')
LMP_NODE = NodeSpec('lmp_node', 'cap_lmp_ros', 'lmp_node', 'cap_lmp_ros.lmp_node:LmpNode', 'lmp_node.yaml')
VISUALIZATION_NODE = NodeSpec('visualization', 'cap_bringup', 'visualization_node',
                              'cap_bringup.visualization_node:VisualizationNode', 'visualization.yaml')


def graph_nodes(domain: Domain, hardware: bool = False) -> tuple[NodeSpec, ...]:
    """The nodes of `domain`'s graph in start order: the simulator (or, on a real robot, the calibration) first, what
    serves commands last. In simulation every node but the simulator takes its time from the simulator's /clock (the
    simulator keeps the wall clock it paces by)."""
    if hardware:
        return (CALIBRATION_NODE, *(spec for spec in domain.nodes if not spec.stand_in), LMP_NODE,
                VISUALIZATION_NODE)
    return (SIM_BRIDGE_NODE, ROBOT_STATE_NODE, *domain.nodes, LMP_NODE, VISUALIZATION_NODE)


# The twin's simulator while no rehearsal runs: simulated seconds per wall second (it waits for the next command).
TWIN_IDLE_SPEED = 1.0


def twin_nodes(domain: Domain) -> tuple[NodeSpec, ...]:
    """The nodes of the twin that rehearses `domain`'s programs (under <namespace>/twin): the simulator and the
    domain's perception and control nodes, those that stand in for a robot's servers included."""
    return (SIM_BRIDGE_NODE, *domain.nodes)


def twin_parameters(domain: Domain) -> dict[str, dict]:
    """{node name: {parameter: value}} of the twin's nodes, beside their packages' config files: the domain's scene
    simulated as fast as it goes, without cameras, watching for harm; ground-truth perception; every node but the
    simulator on the twin's clock. The same in simulation and on a real robot: the twin is always a simulator."""
    chosen = {'sim_bridge': {'scene': domain.scene, 'real_time': False, 'camera_rate': 0.0, 'twin': True,
                             'idle_speed': TWIN_IDLE_SPEED},
              'perception_node': {'source': 'ground_truth'}, 'pick_place': {'clear_view': False}}
    return {spec.name: {**chosen.get(spec.name, {}), **({} if spec is SIM_BRIDGE_NODE else {'use_sim_time': True})}
            for spec in twin_nodes(domain)}


def twin_launch_arguments(domain: Domain, namespace: str, rehearse: str,
                          config_file: Callable[[str, str], str]) -> list[dict]:
    """The arguments of launch_ros's Node for each of the twin's nodes, under <namespace>/twin on its own clock,
    when lmp_node rehearses (`rehearse` neither empty nor off); `config_file(package, filename)` is the path of a
    package's config file. What the launch files start; `cap up` starts the same nodes in one process."""
    if rehearse in ('', 'off'):
        return []
    twin = f"{namespace.rstrip('/')}/twin"
    parameters = twin_parameters(domain)
    return [{'package': spec.package, 'executable': spec.executable, 'name': spec.name, 'namespace': twin,
             'remappings': [('/clock', f'{twin}/clock')], 'output': 'screen',
             'parameters': [config_file(spec.package, spec.config_file), parameters[spec.name]]}
            for spec in twin_nodes(domain)]


def node_class(spec: NodeSpec) -> type:
    """The class a NodeSpec names ('module:Class'); ValueError (one line) if it cannot be loaded."""
    module_name, _, class_name = spec.node_class.partition(':')
    try:
        return getattr(importlib.import_module(module_name), class_name)
    except (ImportError, AttributeError) as error:
        raise ValueError(f'node {spec.name!r}: cannot load {spec.node_class!r} ({error})') from None


__all__ = ['CALIBRATION_NODE', 'LMP_NODE', 'ROBOT_STATE_NODE', 'SIM_BRIDGE_NODE', 'VISUALIZATION_NODE', 'graph_nodes',
           'node_class', 'twin_launch_arguments', 'twin_nodes', 'twin_parameters']
