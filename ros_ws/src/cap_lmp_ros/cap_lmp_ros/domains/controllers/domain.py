"""The reactive-controller domain as a unit: its LMPs (a UI with a session, function generation), the robot
functions over controller_node and lmp_node's CallController service, the 'controllers' simulator scene (the UR5e
and a cart-pole) and the packaged reference cassette. No rclpy at import: the ROS binding is imported when the node
builds it."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from cap_lmp_ros.domains.controllers.lmps import build_engine
from cap_lmp_ros.domains.registry import Domain, NodeSpec, RobotBinding

CONTROLLER_NODE = NodeSpec('controller_node', 'cap_control', 'controller', 'cap_control.controller.node:ControllerNode',
                           'controller.yaml')
# The names RosControllersApi binds over ROS; build_engine shows generated code run_controller and the state
# functions in their place. start_controller takes the program's controller function (as a handle).
ROBOT_FUNCTIONS = ('start_controller', 'read_plant_state', 'say')


def robot_api(node: Any, say_publisher: Any, service_timeout_s: float, motion_timeout_s: float) -> RobotBinding:
    """RosControllersApi on `node`."""
    from cap_lmp_ros.domains.controllers.robot_api import RosControllersApi
    return RosControllersApi(node, say_publisher, service_timeout_s, motion_timeout_s)


DOMAIN = Domain(name='controllers', build_engine=build_engine, robot_functions=ROBOT_FUNCTIONS, robot_api=robot_api,
                scene='controllers',
                cassette=Path(__file__).resolve().parent / 'cassettes' / 'controllers_reference.yaml',
                nodes=(CONTROLLER_NODE,), function_arguments=('start_controller',))
