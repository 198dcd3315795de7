"""What a preflight checks before anything moves on a real robot, and how it says what is missing (no ROS).

A profile names actions, topics and frames; `requirements(profile)` lists each with the type the graph expects and
what it is for. `problems(...)` compares them with what the ROS graph offers (names and types, as rclpy lists
them; the frames tf connects; the joints /joint_states names) and returns one line per missing or mistyped piece,
with the exact name and type to provide. The ROS side asks the graph (cap_bringup.preflight).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

from cap_hardware.profile import HardwareProfile

FOLLOW_JOINT_TRAJECTORY = 'control_msgs/action/FollowJointTrajectory'
GRIPPER_COMMAND = 'control_msgs/action/GripperCommand'
NAVIGATE_TO_POSE = 'nav2_msgs/action/NavigateToPose'
NAVIGATE_THROUGH_POSES = 'nav2_msgs/action/NavigateThroughPoses'
JOINT_STATE = 'sensor_msgs/msg/JointState'
IMAGE = 'sensor_msgs/msg/Image'
CAMERA_INFO = 'sensor_msgs/msg/CameraInfo'
OCCUPANCY_GRID = 'nav_msgs/msg/OccupancyGrid'


@dataclass(frozen=True)
class Requirement:
    kind: str  # 'action', 'topic' or 'frame'
    name: str
    type: str  # the interface type; for a frame, the frame it must be connected to on tf
    purpose: str

    def describe(self) -> str:
        if self.kind == 'frame':
            return f'frame {self.name} connected to {self.type} on /tf or /tf_static ({self.purpose})'
        return f'{self.kind} {self.name} ({self.type}): {self.purpose}'


def requirements(profile: HardwareProfile) -> list[Requirement]:
    """Everything the profile names, in the order a person would wire it: arm, gripper, camera, base."""
    arm, gripper, camera, world = profile.arm, profile.gripper, profile.camera, profile.world_frame
    needed = [
        Requirement('action', arm.controller_action, FOLLOW_JOINT_TRAJECTORY, "the arm's trajectory controller"),
        Requirement('topic', arm.joint_states, JOINT_STATE, "the arm's joint states"),
        Requirement('action', gripper.action, GRIPPER_COMMAND, "the gripper's action controller"),
        Requirement('topic', camera.color, IMAGE, "the camera's colour image"),
        Requirement('topic', camera.depth, IMAGE, "the camera's depth image, aligned with the colour image"),
        Requirement('topic', camera.camera_info, CAMERA_INFO, "the colour image's intrinsics"),
        Requirement('frame', camera.frame, world, "the camera's optical frame: the calibration's camera_mount and "
                                                  "the camera driver's frames"),
    ]
    navigation = profile.navigation
    if navigation is not None:
        needed += [
            Requirement('action', navigation.navigate_to_pose, NAVIGATE_TO_POSE, "nav2's navigator"),
            Requirement('action', navigation.navigate_through_poses, NAVIGATE_THROUGH_POSES, "nav2's navigator"),
            Requirement('topic', navigation.costmap, OCCUPANCY_GRID, "nav2's global costmap"),
            Requirement('frame', navigation.base_frame, world, 'the base on the map: map -> odom -> base_link'),
        ]
    return needed


def problems(profile: HardwareProfile, actions: Mapping[str, Sequence[str]], topics: Mapping[str, Sequence[str]],
             connected: Callable[[str, str], bool], joint_names: Sequence[str] | None) -> list[str]:
    """One line per requirement the graph does not meet (empty: ready). `actions` and `topics` map names to their
    types as the graph lists them; `connected(frame, other)` says whether tf joins them; `joint_names` are those
    of a joint state received (None: none came)."""
    found = []
    for need in requirements(profile):
        if need.kind == 'frame':
            if not connected(need.name, need.type):
                found.append(f'missing {need.describe()}')
            continue
        offered = (actions if need.kind == 'action' else topics).get(need.name)
        if not offered:
            found.append(f'missing {need.describe()}')
        elif need.type not in offered:
            found.append(f'wrong type: {need.kind} {need.name} is {", ".join(offered)}, expected {need.type} '
                         f'({need.purpose})')
    arm = profile.arm
    if topics.get(arm.joint_states) and JOINT_STATE in topics[arm.joint_states]:
        if joint_names is None:
            found.append(f'no message on {arm.joint_states}: the arm\'s driver publishes nothing')
        elif missing := [name for name in arm.joints if name not in joint_names]:
            found.append(f'{arm.joint_states} lacks the joints {missing} (it names {list(joint_names)})')
    return found


__all__ = ['CAMERA_INFO', 'FOLLOW_JOINT_TRAJECTORY', 'GRIPPER_COMMAND', 'IMAGE', 'JOINT_STATE',
           'NAVIGATE_THROUGH_POSES', 'NAVIGATE_TO_POSE', 'OCCUPANCY_GRID', 'Requirement', 'problems', 'requirements']
