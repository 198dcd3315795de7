"""The mobile robot API of generated code, bound to the graph's perception and navigation nodes.

Objects are perception's: `get_obj_names()` every object it knows of, `get_visible_obj_names()` and
`is_obj_visible(name)` what the head camera sees now, `get_obj_pos(name)` where an object is (np.array([x, y]) on
the floor plan). Locations are the kitchen's facts (cap_mobile.layout): `get_loc_names()` and `get_loc_pos(name)`
answer without asking the graph. The robot's pose comes from the navigation node (`get_base_pose`); `goto_loc(name)`,
`goto_pos(pos, angle=None)` and `follow_traj(pts)` are goals of its Navigate and NavigateThroughPoses actions.
`pick_obj(name)`, `place_at_pos(pos)` and `place_at_obj(name)` are goals of mobile_pick_place's MobilePickPlace
action (the base drives within reach first). `say` and the plumbing are the shared RosRobotApi's
(cap_lmp_ros.domains.ros_api). A goal the navigation node refuses (a point inside furniture, no way there) raises
RobotApiError with its reason; a stop cancels the drive and raises StoppedError.
"""
from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np
from cap_mobile import layout
from cap_ros_common.actions import ActionClient
from geometry_msgs.msg import PoseStamped
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node

from cap_interfaces.action import MobilePickPlace, Navigate, NavigateThroughPoses
from cap_interfaces.msg import GraphNames
from cap_interfaces.srv import GetBasePose, GetObjectNames
from cap_lmp.errors import RobotApiError, StoppedError
from cap_lmp_ros.domains.mobile.poses import floor_point, heading, location_name, traj_poses
from cap_lmp_ros.domains.ros_api import RosRobotApi

WORLD_FRAME = 'world'  # the frame of every cap-ros pose (the navigation node also takes nav2's 'map')


def pose_stamped(x: float, y: float, yaw: float) -> PoseStamped:
    msg = PoseStamped()
    msg.header.frame_id = WORLD_FRAME
    msg.pose.position.x, msg.pose.position.y = float(x), float(y)
    msg.pose.orientation.z, msg.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
    return msg


class RosMobileApi(RosRobotApi):
    """The objects' and locations' names and positions, the robot's pose, driving, picking and placing, say."""

    surface = 'the kitchen'

    def _create_clients(self, node: Node) -> None:
        super()._create_clients(node)
        group = ReentrantCallbackGroup()
        self._navigate = ActionClient(node, Navigate, GraphNames.NAVIGATE_ACTION, callback_group=group)
        self._through = ActionClient(node, NavigateThroughPoses, GraphNames.NAVIGATE_THROUGH_POSES_ACTION,
                                     callback_group=group)
        self._base_pose = node.create_client(GetBasePose, GraphNames.BASE_POSE_SERVICE, callback_group=group)
        self._pick_place = ActionClient(node, MobilePickPlace, GraphNames.MOBILE_PICK_PLACE_ACTION,
                                        callback_group=group)

    def _clients(self) -> list[Any]:
        return super()._clients() + [self._navigate, self._through, self._base_pose, self._pick_place]

    def functions(self) -> dict[str, Callable[..., Any]]:
        """The names generated code sees."""
        return {'get_obj_names': self.get_obj_names, 'get_visible_obj_names': self.get_visible_obj_names,
                'is_obj_visible': self.is_obj_visible, 'get_obj_pos': self.get_obj_pos,
                'get_loc_names': self.get_loc_names, 'get_loc_pos': self.get_loc_pos,
                'get_robot_pos_and_angle': self.get_robot_pos_and_angle, 'goto_pos': self.goto_pos,
                'goto_loc': self.goto_loc, 'follow_traj': self.follow_traj, 'pick_obj': self.pick_obj,
                'place_at_pos': self.place_at_pos, 'place_at_obj': self.place_at_obj, 'say': self.say}

    # -------------------------------------------------------------------------------------------- queries
    def get_visible_obj_names(self) -> list[str]:
        """The objects the head camera sees now."""
        return list(self._call(self._names, GetObjectNames.Request(visible_only=True), 'the perception service').names)

    def is_obj_visible(self, name: str) -> bool:
        """Whether the head camera sees the object now."""
        return bool(self._object(name).visible)

    def get_loc_names(self) -> list[str]:
        """The kitchen's locations, named after their furniture."""
        return list(layout.LOCATION_NAMES)

    def get_loc_pos(self, name: str) -> np.ndarray:
        """Centre of a location's furniture, np.array([x, y]) in metres."""
        return np.array(layout.location(location_name(name)).centre, dtype=float)

    def get_robot_pos_and_angle(self) -> tuple[np.ndarray, float]:
        """(np.array([x, y]) of the base's centre [m], its heading [rad, counterclockwise from +x])."""
        response = self._call(self._base_pose, GetBasePose.Request(), 'the navigation node')
        if not response.success:
            raise RobotApiError(response.message or 'the robot\'s pose is not known yet')
        pose = response.pose.pose
        yaw = math.atan2(2 * pose.orientation.w * pose.orientation.z, 1 - 2 * pose.orientation.z ** 2)
        return np.array([pose.position.x, pose.position.y]), yaw

    # -------------------------------------------------------------------------------------------- motion
    def goto_loc(self, name: str) -> None:
        """Drive to stand in front of a location, facing it."""
        name = location_name(name)
        self._navigate_to(Navigate.Goal(location_name=name), f'the {name}')

    def goto_pos(self, pos: Any, angle: Any = None) -> None:
        """Drive to a point of the floor, facing `angle` [rad] there (default: the direction from where the robot
        was to the point)."""
        target = floor_point(pos, 'the position to go to')
        if angle is None:
            here, yaw = self.get_robot_pos_and_angle()
            leg = target - here
            yaw = math.atan2(leg[1], leg[0]) if np.hypot(*leg) > 0.05 else yaw
        else:
            yaw = heading(angle)
        self._navigate_to(Navigate.Goal(pose=pose_stamped(target[0], target[1], yaw)),
                          f'({target[0]:.2f}, {target[1]:.2f})')

    def follow_traj(self, pts: Any) -> None:
        """Drive through the points (rows of [x, y] in metres) in order, facing along each leg."""
        here, yaw = self.get_robot_pos_and_angle()
        poses = traj_poses(pts, (here[0], here[1], yaw))
        if not poses:
            return  # every point is where the robot stands
        goal = NavigateThroughPoses.Goal(poses=[pose_stamped(*pose) for pose in poses])
        # One goal for the whole tour: allow a drive's time per pose.
        result = self._run_goal(self._through, goal, 'the navigation node',
                                'the navigation node refused the trajectory',
                                timeout_s=self.motion_timeout_s * max(1.0, len(poses) / 2))
        self._check(result, NavigateThroughPoses.Result, 'follow the trajectory')

    def pick_obj(self, name: str) -> None:
        """Drive within reach of the object and pick it up (the arm then carries it over the base)."""
        name = self._name(name)
        self._manipulate(MobilePickPlace.Goal(task=MobilePickPlace.Goal.TASK_PICK, object_name=name),
                         f'pick up the {name}')

    def place_at_pos(self, pos: Any) -> None:
        """Put the held object down at a point ([x, y] in metres): on the furniture there, or into a bin."""
        target = floor_point(pos, 'the position to place at')
        goal = MobilePickPlace.Goal(task=MobilePickPlace.Goal.TASK_PLACE_AT_POSITION)
        goal.target_position.x, goal.target_position.y = float(target[0]), float(target[1])
        self._manipulate(goal, f'put it down at ({target[0]:.2f}, {target[1]:.2f})')

    def place_at_obj(self, name: str) -> None:
        """Put the held object down on another object."""
        name = self._name(name)
        self._manipulate(MobilePickPlace.Goal(task=MobilePickPlace.Goal.TASK_PLACE_AT_OBJECT, object_name=name),
                         f'put it on the {name}')

    def _manipulate(self, goal: MobilePickPlace.Goal, doing: str) -> None:
        result = self._run_goal(self._pick_place, goal, 'mobile pick-and-place',
                                'mobile pick-and-place refused the goal')
        if self.stop_requested.is_set() or result.error_code == MobilePickPlace.Result.CANCELLED:
            raise StoppedError('stopped while picking or placing')
        if result.error_code != MobilePickPlace.Result.NONE:
            raise RobotApiError(f'could not {doing}: {result.error_msg}')

    def _navigate_to(self, goal: Navigate.Goal, where: str) -> None:
        result = self._run_goal(self._navigate, goal, 'the navigation node',
                                'the navigation node refused the goal')
        self._check(result, Navigate.Result, f'go to {where}')

    def _check(self, result, codes, doing: str) -> None:
        if self.stop_requested.is_set() or result.error_code == codes.CANCELLED:
            raise StoppedError('stopped while driving')
        if result.error_code != codes.NONE:
            raise RobotApiError(f'could not {doing}: {result.error_msg}')


__all__ = ['RosMobileApi']
