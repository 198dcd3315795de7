"""The mobile robot API of generated code, bound to the graph's perception and navigation nodes.

Objects are perception's: `get_obj_names()` every object it knows of, `get_visible_obj_names()` and
`is_obj_visible(name)` what the head camera sees now, `get_obj_pos(name)` where an object is (np.array([x, y]) on
the floor plan). Locations are the kitchen's facts (cap_mobile.layout): `get_loc_names()` and `get_loc_pos(name)`
answer without asking the graph. The robot's pose is base_link's in the map frame on tf (REP-105); `goto_loc(name)`
(a location's approach pose), `goto_pos(pos, angle=None)` and `follow_traj(pts)` are goals of nav2's NavigateToPose
and NavigateThroughPoses actions, under nav2's names (the navigation node serves them in the simulator).
`pick_obj(name)`, `place_at_pos(pos)` and `place_at_obj(name)` are goals of mobile_pick_place's MobilePickPlace
action (the base drives within reach first). `say` and the plumbing are the shared RosRobotApi's
(cap_lmp_ros.domains.ros_api). A goal the navigation node refuses (a point inside furniture, no way there) raises
RobotApiError with its reason; a stop cancels the drive and raises StoppedError.
"""
from __future__ import annotations

import math
import time
from typing import Any, Callable

import numpy as np
from cap_mobile import layout
from cap_ros_common.actions import ActionClient
from geometry_msgs.msg import PoseStamped
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node

from cap_interfaces.action import MobilePickPlace
from cap_interfaces.msg import GraphNames
from cap_interfaces.srv import GetObjectNames
from cap_ros_common.tf import TfListener
from cap_ros_common.transforms import TransformError
from nav2_msgs.action import NavigateThroughPoses, NavigateToPose
from cap_lmp.errors import RobotApiError, StoppedError
from cap_lmp_ros.domains.mobile.poses import floor_point, heading, location_name, traj_poses
from cap_lmp_ros.domains.ros_api import RosRobotApi

MAP_FRAME, BASE_FRAME = 'map', 'base_link'  # REP-105: the simulator's map is its world, as a localised robot's is


def pose_stamped(x: float, y: float, yaw: float) -> PoseStamped:
    msg = PoseStamped()
    msg.header.frame_id = MAP_FRAME
    msg.pose.position.x, msg.pose.position.y = float(x), float(y)
    msg.pose.orientation.z, msg.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
    return msg


class RosMobileApi(RosRobotApi):
    """The objects' and locations' names and positions, the robot's pose, driving, picking and placing, say."""

    where = 'in the kitchen'

    def _create_clients(self, node: Node) -> None:
        super()._create_clients(node)
        group = ReentrantCallbackGroup()
        self._navigate = ActionClient(node, NavigateToPose, GraphNames.NAVIGATE_TO_POSE_ACTION, callback_group=group)
        self._through = ActionClient(node, NavigateThroughPoses, GraphNames.NAVIGATE_THROUGH_POSES_ACTION,
                                     callback_group=group)
        self._tf = TfListener(node, callback_group=group)
        self._pick_place = ActionClient(node, MobilePickPlace, GraphNames.MOBILE_PICK_PLACE_ACTION,
                                        callback_group=group)

    def _clients(self) -> list[Any]:
        return super()._clients() + [self._navigate, self._through, self._tf, self._pick_place]

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
        deadline = time.monotonic() + self.service_timeout_s
        while True:  # tf's first transforms come a moment after the graph starts
            try:
                pose = self._tf.buffer.lookup(MAP_FRAME, BASE_FRAME)
                break
            except TransformError as error:
                if self.stop_requested.is_set():
                    raise StoppedError('stopped while waiting for the robot\'s pose') from None
                if time.monotonic() > deadline:
                    raise RobotApiError(f'the robot\'s pose is not known: {error}') from None
                time.sleep(0.05)
        return np.array([pose[0, 3], pose[1, 3]]), math.atan2(pose[1, 0], pose[0, 0])

    # -------------------------------------------------------------------------------------------- motion
    def goto_loc(self, name: str) -> None:
        """Drive to stand in front of a location, facing it."""
        name = location_name(name)
        self._navigate_to(NavigateToPose.Goal(pose=pose_stamped(*layout.location(name).approach())), f'the {name}')

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
        self._navigate_to(NavigateToPose.Goal(pose=pose_stamped(target[0], target[1], yaw)),
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
        self._check(result, 'follow the trajectory')

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
        """Put the held object down on another object; given a location's name instead (no object has one), on
        that location, as place_at_pos(get_loc_pos(name)) would: what was meant is not in doubt."""
        try:
            name = self._name(name)
        except RobotApiError as no_object:
            try:
                location = location_name(name)
            except RobotApiError:
                raise no_object from None
            return self.place_at_pos(self.get_loc_pos(location))
        self._manipulate(MobilePickPlace.Goal(task=MobilePickPlace.Goal.TASK_PLACE_AT_OBJECT, object_name=name),
                         f'put it on the {name}')

    def _manipulate(self, goal: MobilePickPlace.Goal, doing: str) -> None:
        result = self._run_goal(self._pick_place, goal, 'mobile pick-and-place',
                                'mobile pick-and-place refused the goal')
        if self.stop_requested.is_set() or result.error_code == MobilePickPlace.Result.CANCELLED:
            raise StoppedError('stopped while picking or placing')
        if result.error_code != MobilePickPlace.Result.NONE:
            raise RobotApiError(f'could not {doing}: {result.error_msg}')

    def _navigate_to(self, goal: NavigateToPose.Goal, where: str) -> None:
        result = self._run_goal(self._navigate, goal, 'the navigation node',
                                'the navigation node refused the goal')
        self._check(result, f'go to {where}')

    def _check(self, result, doing: str) -> None:
        """A navigation result as nav2 gives it: error_code 0 (NONE) when the base arrived."""
        if self.stop_requested.is_set():
            raise StoppedError('stopped while driving')
        if result.error_code != NavigateToPose.Result.NONE:
            raise RobotApiError(f'could not {doing}: {result.error_msg or f"error code {result.error_code}"}')


__all__ = ['RosMobileApi']
