"""Conversions between cap_control's plain data and ROS messages (message types only, no rclpy)."""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from cap_ros_common.time import duration_msg, to_seconds
from control_msgs.action import FollowJointTrajectory, GripperCommand
from control_msgs.msg import JointTolerance
from geometry_msgs.msg import Point, Pose, PoseStamped
from nav_msgs.msg import MapMetaData
from nav_msgs.msg import OccupancyGrid as OccupancyGridMsg
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory as JointTrajectoryMsg
from trajectory_msgs.msg import JointTrajectoryPoint

from cap_interfaces.msg import ObjectState as ObjectStateMsg
from cap_interfaces.srv import GetObjectState

from cap_control.navigation.plan import OccupancyGrid
from cap_control.pick_place.plan import ObjectInfo, yaw_of_quaternion
from cap_control.ports import ArmOutcome, ArmResult, ObjectReport
from cap_control.trajectory import JointTrajectory

GRIPPER_FINGER_JOINTS = ('gripper_left_finger_joint', 'gripper_right_finger_joint')
WORLD_FRAME = 'world'  # the URDF's root: the frame of every cap-ros pose


def trajectory_msg(trajectory: JointTrajectory, joint_names: Sequence[str] | None = None) -> JointTrajectoryMsg:
    """The trajectory as trajectory_msgs/JointTrajectory, its joints named `joint_names` (the controller's names of
    the kinematics' joints, in order) or as the trajectory names them."""
    return JointTrajectoryMsg(joint_names=list(joint_names or trajectory.joint_names), points=[
        JointTrajectoryPoint(positions=q.tolist(), velocities=v.tolist(), accelerations=a.tolist(),
                             time_from_start=duration_msg(float(t)))
        for t, q, v, a in zip(trajectory.times, trajectory.positions, trajectory.velocities,
                              trajectory.accelerations)])


def follow_trajectory_goal(trajectory: JointTrajectory, contact_tolerance: float | None = None,
                           goal_tolerance: float | None = None,
                           joint_names: Sequence[str] | None = None) -> FollowJointTrajectory.Goal:
    """The goal for one trajectory (its joints named `joint_names`, the controller's names, if given); with a
    contact tolerance [rad], that is its path tolerance, so that the controller aborts with PATH_TOLERANCE_VIOLATED
    where the arm touches down; a goal tolerance [rad] is the position tolerance of the end (a tool pressing on a
    surface stops a few milliradians short)."""
    message = trajectory_msg(trajectory, joint_names)
    goal = FollowJointTrajectory.Goal(trajectory=message)
    if contact_tolerance is not None:
        goal.path_tolerance = [JointTolerance(name=name, position=contact_tolerance, velocity=-1.0,
                                              acceleration=-1.0) for name in message.joint_names]
    if goal_tolerance is not None:  # velocity and acceleration 0: the controller's defaults
        goal.goal_tolerance = [JointTolerance(name=name, position=goal_tolerance, velocity=0.0, acceleration=0.0)
                               for name in message.joint_names]
    return goal


def arm_outcome(result: FollowJointTrajectory.Result) -> ArmOutcome:
    """The trajectory action's result as the executor's outcome (a tolerance violation may mean contact)."""
    code = result.error_code
    if code == FollowJointTrajectory.Result.SUCCESSFUL:
        return ArmOutcome(ArmResult.SUCCEEDED)
    message = result.error_string or f'error code {code}'
    if code in (FollowJointTrajectory.Result.PATH_TOLERANCE_VIOLATED,
                FollowJointTrajectory.Result.GOAL_TOLERANCE_VIOLATED):
        return ArmOutcome(ArmResult.TOLERANCE_VIOLATED, message)
    return ArmOutcome(ArmResult.FAILED, message)


def gripper_goal(position: float, max_effort: float) -> GripperCommand.Goal:
    """A GripperCommand goal; `position` in the gripper controller's units (ArmInterfaces.command_position)."""
    goal = GripperCommand.Goal()
    goal.command.position, goal.command.max_effort = float(position), float(max_effort)
    return goal


def object_info(state: ObjectStateMsg) -> ObjectInfo:
    """Perception's object state (axis-aligned box + orientation) as the planner's object."""
    q = state.orientation
    yaw = yaw_of_quaternion(q.x, q.y, q.z, q.w) if (q.x, q.y, q.z, q.w) != (0.0, 0.0, 0.0, 0.0) else 0.0
    return ObjectInfo.from_bounding_box(
        state.name, (state.bbox_min.x, state.bbox_min.y, state.bbox_min.z),
        (state.bbox_max.x, state.bbox_max.y, state.bbox_max.z), state.category, yaw)


def object_report(response: GetObjectState.Response) -> ObjectReport:
    """Perception's answer about one object as the executor's report."""
    if not response.success:
        return ObjectReport(False, response.message, stamp=to_seconds(response.stamp))
    state = response.state
    return ObjectReport(True, response.message, object_info(state),
                        (state.position.x, state.position.y, state.position.z), bool(state.visible),
                        to_seconds(response.stamp))


def joint_positions(msg: JointState, names: Sequence[str]) -> np.ndarray | None:
    """Positions of the named joints from a JointState message, or None if one is missing."""
    index = {name: i for i, name in enumerate(msg.name)}
    if any(name not in index or index[name] >= len(msg.position) for name in names):
        return None
    return np.array([msg.position[index[name]] for name in names])


def gripper_opening(msg: JointState) -> float | None:
    """Opening between the finger pads [m]: the sum of the two finger joints (each = pad distance from the tcp)."""
    fingers = joint_positions(msg, GRIPPER_FINGER_JOINTS)
    return None if fingers is None else float(np.sum(fingers))


def point_msg(xyz: Sequence[float]) -> Point:
    return Point(x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2]))


def pose_msg(pose: Sequence[float], stamp, frame_id: str = WORLD_FRAME) -> PoseStamped:
    """The mobile base's pose (x [m], y [m], yaw [rad]) in `frame_id` (the world frame)."""
    msg = PoseStamped()
    msg.header.frame_id, msg.header.stamp = frame_id, stamp
    msg.pose.position.x, msg.pose.position.y = float(pose[0]), float(pose[1])
    msg.pose.orientation.z, msg.pose.orientation.w = math.sin(pose[2] / 2), math.cos(pose[2] / 2)
    return msg


def yaw_of(msg: PoseStamped) -> float:
    """The yaw [rad] of a pose's orientation."""
    q = msg.pose.orientation
    return math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))


def planar_pose(matrix: np.ndarray) -> tuple[float, float, float]:
    """x [m], y [m] and yaw [rad] of a 4x4 pose (the base's on the floor)."""
    return float(matrix[0, 3]), float(matrix[1, 3]), math.atan2(matrix[1, 0], matrix[0, 0])


OCCUPIED, FREE = 100, 0  # nav_msgs/OccupancyGrid's cell values (-1 would be unknown: the map has none)
INSCRIBED = 99  # nav2's costmap: a base centred here touches an obstacle


def occupancy_grid_msg(grid: OccupancyGrid, frame_id: str, stamp) -> OccupancyGridMsg:
    """The grid as nav_msgs/OccupancyGrid: row-major, the row along y, the column along x, as OccupancyGrid's."""
    rows, columns = grid.occupied.shape
    msg = OccupancyGridMsg(info=MapMetaData(map_load_time=stamp, resolution=float(grid.resolution), width=columns,
                                            height=rows, origin=Pose(position=Point(x=float(grid.origin[0]),
                                                                                    y=float(grid.origin[1])))))
    msg.header.frame_id, msg.header.stamp = frame_id, stamp
    msg.data = np.where(grid.occupied, OCCUPIED, FREE).astype(np.int8).ravel().tolist()
    return msg


def occupancy_grid(msg: OccupancyGridMsg) -> OccupancyGrid:
    """The map back as an OccupancyGrid: the base's centre may not stand where a cell says 99 or more (nav2's
    inscribed and lethal costs; this project's maps say 100) or is unknown. ValueError for a malformed map."""
    info = msg.info
    if info.width <= 0 or info.height <= 0 or len(msg.data) != info.width * info.height or \
            not np.isfinite(info.resolution) or info.resolution <= 0:
        raise ValueError(f'a map of {info.width} x {info.height} cells needs as many values, not {len(msg.data)}, '
                         f'and a positive resolution, not {info.resolution:g}')
    data = np.asarray(msg.data, dtype=np.int16).reshape(info.height, info.width)
    # The message's resolution is a float32: 0.05 comes back as 0.0500000007, which would shift cell borders
    # by a nanometre per cell. Maps are given in whole micrometres.
    resolution = round(float(info.resolution), 6)
    blocked = (data >= INSCRIBED) | (data < 0)
    return OccupancyGrid(blocked, (float(info.origin.position.x), float(info.origin.position.y)), resolution)
