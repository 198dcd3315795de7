"""The nodes of a domain's graph, as `cap up` and the launch file start them (no rclpy here).

Every graph starts with the simulator; the domain's perception and control nodes come next (`Domain.nodes`), then
lmp_node and the visualization node (RViz's /robot_description and /cap/markers). Nodes are named by strings
(cap_lmp_ros.domains.registry.NodeSpec), so that a domain is described without importing its nodes; the one-process
graph loads the classes, a launch file starts the executables.
"""
from __future__ import annotations

import importlib

from cap_lmp_ros.domains.registry import Domain, NodeSpec

SIM_BRIDGE_NODE = NodeSpec('sim_bridge', 'cap_sim_bridge', 'sim_bridge', 'cap_sim_bridge.bridge_node:SimBridgeNode',
                           'sim_bridge.yaml')
LMP_NODE = NodeSpec('lmp_node', 'cap_lmp_ros', 'lmp_node', 'cap_lmp_ros.lmp_node:LmpNode', 'lmp_node.yaml')
VISUALIZATION_NODE = NodeSpec('visualization', 'cap_bringup', 'visualization_node',
                              'cap_bringup.visualization_node:VisualizationNode', 'visualization.yaml')


def graph_nodes(domain: Domain) -> tuple[NodeSpec, ...]:
    """The nodes of `domain`'s graph in start order: the simulator first, what serves commands last. Every node but
    the simulator takes its time from the simulator's /clock (the simulator keeps the wall clock it paces by)."""
    return (SIM_BRIDGE_NODE, *domain.nodes, LMP_NODE, VISUALIZATION_NODE)


def node_class(spec: NodeSpec) -> type:
    """The class a NodeSpec names ('module:Class'); ValueError (one line) if it cannot be loaded."""
    module_name, _, class_name = spec.node_class.partition(':')
    try:
        return getattr(importlib.import_module(module_name), class_name)
    except (ImportError, AttributeError) as error:
        raise ValueError(f'node {spec.name!r}: cannot load {spec.node_class!r} ({error})') from None


__all__ = ['LMP_NODE', 'SIM_BRIDGE_NODE', 'VISUALIZATION_NODE', 'graph_nodes', 'node_class']
