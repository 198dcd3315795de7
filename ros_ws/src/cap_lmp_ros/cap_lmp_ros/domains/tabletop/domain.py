"""The table-top domain as a unit: the table-top LMPs, the robot API over perception and pick_place, the
'tabletop' simulator scene and the packaged reference cassette. No rclpy at import: the ROS binding is imported
when the node builds it."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from cap_lmp_ros.domains.registry import PERCEPTION_NODE, PICK_PLACE_NODE, Domain, RobotBinding
from cap_lmp_ros.domains.tabletop.lmps import build_engine
from cap_lmp_ros.domains.tabletop.plan import describe_call

# The names RosTabletopApi binds over ROS; the pure helpers (denormalize_xy, ...) are added by build_engine.
ROBOT_FUNCTIONS = ('get_obj_names', 'get_obj_pos', 'get_bbox', 'get_color', 'is_obj_visible', 'put_first_on_second',
                   'say', 'get_pos_before_last_command')
# Those that only read the world: a plan-only run calls them (and records put_first_on_second and say).
QUERY_FUNCTIONS = ('get_obj_names', 'get_obj_pos', 'get_bbox', 'get_color', 'is_obj_visible',
                   'get_pos_before_last_command')


def robot_api(node: Any, say_publisher: Any, service_timeout_s: float, motion_timeout_s: float) -> RobotBinding:
    """RosTabletopApi on `node`."""
    from cap_lmp_ros.domains.tabletop.robot_api import RosTabletopApi
    return RosTabletopApi(node, say_publisher, service_timeout_s, motion_timeout_s)


DOMAIN = Domain(name='tabletop', build_engine=build_engine, robot_functions=ROBOT_FUNCTIONS, robot_api=robot_api,
                scene='tabletop', cassette=Path(__file__).resolve().parent / 'cassettes' / 'tabletop_reference.yaml',
                nodes=(PERCEPTION_NODE, PICK_PLACE_NODE), query_functions=QUERY_FUNCTIONS, describe_call=describe_call)
