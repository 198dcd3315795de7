"""The names and units under which a robot serves the skills' standard interfaces: node parameters, one dataclass per
kind of node, whose defaults are the simulator's (cap_sim_bridge) and which a hardware profile sets for a real robot
(cap_bringup.hardware). No rclpy.

- `StateInterfaces`: where joint states come from (every node that serves goals);
- `ArmInterfaces`: the arm's trajectory controller (control_msgs/FollowJointTrajectory) and its joints, the gripper's
  action controller (control_msgs/GripperCommand) and the units of its positions;
- `NavigationInterfaces`: what the navigation node serves (nav2's actions and costmap, under nav2's names) and the
  base trajectory it drives;
- `MobileInterfaces`: what mobile pick-and-place uses of a navigator: nav2's NavigateToPose, its costmap, and the
  base's frame on tf.
"""
from __future__ import annotations

import dataclasses

from cap_interfaces.msg import GraphNames
from cap_ros_common.parameters import parameter

from cap_control.kinematics import JOINT_NAMES

SIM_GRIPPER_OPENING = 0.085  # [m] the simulated gripper's opening when open: its positions are openings


@dataclasses.dataclass(frozen=True)
class StateInterfaces:
    joint_states_topic: str = parameter(GraphNames.JOINT_STATES_TOPIC, 'sensor_msgs/JointState topic of the robot\'s '
                                        'joints.')


@dataclasses.dataclass(frozen=True)
class ArmInterfaces:
    arm_controller_action: str = parameter(GraphNames.SIM_FOLLOW_JOINT_TRAJECTORY_ACTION,
                                           'control_msgs/FollowJointTrajectory action of the arm\'s trajectory '
                                           'controller (ur_robot_driver: /scaled_joint_trajectory_controller/'
                                           'follow_joint_trajectory).')
    arm_joints: tuple[str, ...] = parameter(JOINT_NAMES, 'The arm\'s joints as the controller and the joint states '
                                            'name them, from the base to the wrist (the kinematics\' order).')
    gripper_action: str = parameter(GraphNames.SIM_GRIPPER_ACTION, 'control_msgs/GripperCommand action of the '
                                    'gripper\'s controller.')
    gripper_open_position: float = parameter(SIM_GRIPPER_OPENING, 'The gripper command position of a fully open '
                                             'gripper, in the controller\'s units (the simulator\'s: the opening in '
                                             'metres; a Robotiq 2F-85\'s knuckle: 0.0 rad).')
    gripper_closed_position: float = parameter(0.0, 'The command position of a fully closed gripper (a Robotiq '
                                               '2F-85\'s knuckle: 0.8 rad).')
    gripper_max_opening: float = parameter(SIM_GRIPPER_OPENING, 'The opening between the fingers of the open '
                                           'gripper [m].')
    gripper_joint: str = parameter('', 'A joint of the joint states whose position is in the command\'s units (a '
                                   'Robotiq\'s knuckle joint); empty: the simulator\'s two finger slides, whose sum '
                                   'is the opening.')

    def command_position(self, opening: float) -> float:
        """The command position that opens the fingers `opening` metres (clamped to what the gripper can)."""
        fraction = min(max(opening / self.gripper_max_opening, 0.0), 1.0)
        return self.gripper_closed_position + fraction * (self.gripper_open_position - self.gripper_closed_position)

    def opening(self, position: float) -> float:
        """The opening [m] a command or joint position means."""
        span = self.gripper_open_position - self.gripper_closed_position
        return self.gripper_max_opening * (position - self.gripper_closed_position) / span

    def validate(self) -> None:
        if len(self.arm_joints) != len(JOINT_NAMES) or len(set(self.arm_joints)) != len(JOINT_NAMES):
            raise ValueError(f'arm_joints must name the arm\'s {len(JOINT_NAMES)} joints once each, not '
                             f'{list(self.arm_joints)}')
        if self.gripper_open_position == self.gripper_closed_position or self.gripper_max_opening <= 0:
            raise ValueError('gripper_open_position and gripper_closed_position must differ and '
                             'gripper_max_opening be positive')


@dataclasses.dataclass(frozen=True)
class NavigationInterfaces:
    navigate_to_pose_action: str = parameter(GraphNames.NAVIGATE_TO_POSE_ACTION, 'nav2_msgs/NavigateToPose action '
                                             'served (nav2\'s name).')
    navigate_through_poses_action: str = parameter(GraphNames.NAVIGATE_THROUGH_POSES_ACTION,
                                                   'nav2_msgs/NavigateThroughPoses action served (nav2\'s name).')
    costmap_topic: str = parameter(GraphNames.COSTMAP_TOPIC, 'nav_msgs/OccupancyGrid where the base\'s centre may '
                                   'not stand (100) or may (0), sent once (nav2\'s global costmap name).')
    base_controller_action: str = parameter(GraphNames.SIM_FOLLOW_BASE_TRAJECTORY_ACTION,
                                            'control_msgs/FollowJointTrajectory action over the base\'s x, y and yaw '
                                            'joints that drives it.')


@dataclasses.dataclass(frozen=True)
class MobileInterfaces:
    navigate_to_pose_action: str = parameter(GraphNames.NAVIGATE_TO_POSE_ACTION, 'nav2_msgs/NavigateToPose action '
                                             'that brings the base within reach (nav2\'s).')
    costmap_topic: str = parameter(GraphNames.COSTMAP_TOPIC, 'nav_msgs/OccupancyGrid of where the base\'s centre '
                                   'may not stand (99 or more), e.g. nav2\'s global costmap.')
    world_frame: str = parameter('world', 'The frame of the map and of every position (nav2: map).')
    base_frame: str = parameter('base_link', 'The base\'s frame on tf (REP-105: base_link), whose pose in '
                                'world_frame is the base\'s.')


__all__ = ['ArmInterfaces', 'MobileInterfaces', 'NavigationInterfaces', 'SIM_GRIPPER_OPENING', 'StateInterfaces']
