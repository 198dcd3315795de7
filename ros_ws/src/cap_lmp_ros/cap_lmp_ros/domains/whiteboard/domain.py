"""The whiteboard domain as a unit: the drawing LMPs, the robot API over perception and follow_path, the
'whiteboard' simulator scene and the packaged reference cassette. No rclpy at import: the ROS binding is imported
when the node builds it."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from cap_lmp_ros.domains.registry import PERCEPTION_NODE, Domain, NodeSpec, RobotBinding
from cap_lmp_ros.domains.whiteboard.lmps import build_engine
from cap_lmp_ros.domains.whiteboard.plan import describe_call

ROBOT_FUNCTIONS = ('get_obj_names', 'get_obj_pos', 'draw', 'erase', 'say')
QUERY_FUNCTIONS = ('get_obj_names', 'get_obj_pos')  # read the world only: a plan-only run calls them
FOLLOW_PATH_NODE = NodeSpec('follow_path', 'cap_control', 'follow_path', 'cap_control.follow_path.node:FollowPathNode',
                            'follow_path.yaml')


def robot_api(node: Any, say_publisher: Any, service_timeout_s: float, motion_timeout_s: float) -> RobotBinding:
    """RosWhiteboardApi on `node`."""
    from cap_lmp_ros.domains.whiteboard.robot_api import RosWhiteboardApi
    return RosWhiteboardApi(node, say_publisher, service_timeout_s, motion_timeout_s)


DOMAIN = Domain(name='whiteboard', build_engine=build_engine, robot_functions=ROBOT_FUNCTIONS, robot_api=robot_api,
                scene='whiteboard',
                cassette=Path(__file__).resolve().parent / 'cassettes' / 'whiteboard_reference.yaml',
                nodes=(PERCEPTION_NODE, FOLLOW_PATH_NODE), query_functions=QUERY_FUNCTIONS, describe_call=describe_call)
