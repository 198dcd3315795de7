"""The mobile kitchen domain as a unit: the mobile LMPs, the robot API over perception, the navigation node and
mobile pick-and-place, the 'mobile' simulator scene (the kitchen) and the packaged reference cassette. No rclpy at
import: the ROS binding is imported when the node builds it."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from cap_mobile import robot

from cap_lmp_ros.domains.mobile.lmps import build_engine
from cap_lmp_ros.domains.registry import PERCEPTION_NODE, Domain, NodeSpec, RobotBinding

ROBOT_FUNCTIONS = ('get_obj_names', 'get_visible_obj_names', 'is_obj_visible', 'get_obj_pos', 'get_loc_names',
                   'get_loc_pos', 'get_robot_pos_and_angle', 'goto_pos', 'goto_loc', 'follow_traj', 'pick_obj',
                   'place_at_pos', 'place_at_obj', 'say')
QUERY_FUNCTIONS = ('get_obj_names', 'get_visible_obj_names', 'is_obj_visible', 'get_obj_pos', 'get_loc_names',
                   'get_loc_pos', 'get_robot_pos_and_angle')  # read the world only
# The simulator's nav2: on a real robot, nav2 itself serves NavigateToPose and NavigateThroughPoses.
NAVIGATION_NODE = NodeSpec('navigation', 'cap_control', 'navigation', 'cap_control.navigation.node:NavigationNode',
                           'navigation.yaml', stand_in=True)
MOBILE_PICK_PLACE_NODE = NodeSpec('mobile_pick_place', 'cap_control', 'mobile_pick_place',
                                  'cap_control.mobile_pick_place.node:MobilePickPlaceNode', 'mobile_pick_place.yaml')


def robot_api(node: Any, say_publisher: Any, service_timeout_s: float, motion_timeout_s: float) -> RobotBinding:
    """RosMobileApi on `node`."""
    from cap_lmp_ros.domains.mobile.robot_api import RosMobileApi
    return RosMobileApi(node, say_publisher, service_timeout_s, motion_timeout_s)


DOMAIN = Domain(name='mobile', build_engine=build_engine, robot_functions=ROBOT_FUNCTIONS, robot_api=robot_api,
                scene='mobile', cassette=Path(__file__).resolve().parent / 'cassettes' / 'mobile_reference.yaml',
                nodes=(PERCEPTION_NODE, NAVIGATION_NODE, MOBILE_PICK_PLACE_NODE), query_functions=QUERY_FUNCTIONS,
                # The kitchen's detector on the head camera, which moves with the base.
                rgbd_perception=(('detector', 'mobile'), ('camera', robot.HEAD_CAMERA)))
