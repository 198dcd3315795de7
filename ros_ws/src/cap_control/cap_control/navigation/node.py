"""navigation: nav2's NavigateToPose and NavigateThroughPoses actions (under nav2's names, navigate_to_pose and
navigate_through_poses) over the mobile base's FollowJointTrajectory action: the simulator's stand-in for nav2.

The work is cap_control.navigation.executor's: this node binds its port to ROS (the simulator's base trajectory
action, the base's joints in the joint states: its localisation is perfect) and serves the actions with it, one goal
at a time: a NavigateToPose goal is a pose in the map (or world) frame, a NavigateThroughPoses goal poses to reach in
order; feedback carries the base's pose, the time since the goal began, the time and distance left, the recoveries
made (and the poses left); a cancel of the goal or a message on the stop topic halts the base where it is (the goal
ends CANCELED, aborted for a stop). Named locations are the robot API's to resolve into poses (nav2 takes poses).
Its map (the furniture inflated by the base, where the base's centre may not stand) goes out once under the name of
nav2's global costmap, so that other nodes choose spots it accepts. Error codes follow nav2's (the planner's
NO_VALID_PATH, 208, for an unreachable goal; the navigator's from 9000). Parameters: NavigationConfig and
NavigationInterfaces, whose fields hold every default.
"""
from __future__ import annotations

from concurrent.futures import Future

import numpy as np
from cap_mobile.robot import BASE_JOINT_NAMES
from cap_ros_common.actions import RESULT_TIMEOUT_S, ActionClient
from cap_ros_common.parameters import declare_config
from cap_ros_common.qos import LATCHED_QOS
from cap_ros_common.time import duration_msg
from nav_msgs.msg import OccupancyGrid as OccupancyGridMsg
from rclpy.action import ActionServer
from trajectory_msgs.msg import JointTrajectoryPoint

from cap_control import ros_conversions as conv
from cap_control.navigation.executor import (
    Base, NavigateOutcome, NavigateProgress, NavigateRequest, NavigationConfig, NavigationExecutor,
)
from cap_control.navigation.plan import NavigateErrorCode
from cap_control.ports import ArmOutcome, ArmResult, Ending, PendingGoal
from cap_control.skill_node import ActionGoal, GoalNode, spin_node
from cap_control.robot_interfaces import NavigationInterfaces
from control_msgs.action import FollowJointTrajectory
from control_msgs.msg import JointTolerance
from nav2_msgs.action import NavigateThroughPoses, NavigateToPose

# Poses are in the world frame (conv.WORLD_FRAME); goals may also name it "map", nav2's name.
ACCEPTED_FRAMES = ('', conv.WORLD_FRAME, 'map')


class _BasePort(Base):
    def __init__(self, node: 'NavigationNode'):
        self._node = node
        self.server_description = f'the base action {node.interfaces.base_controller_action}'

    def server_ready(self) -> Future:
        return self._node.when_ready(self._node.base_client.server_is_ready)

    def pose(self) -> Future:
        return self._node.joints(BASE_JOINT_NAMES)

    def latest_pose(self) -> np.ndarray | None:
        msg = self._node.joint_state()
        return None if msg is None else conv.joint_positions(msg, BASE_JOINT_NAMES)

    def follow(self, times: np.ndarray, positions: np.ndarray, velocities: np.ndarray,
               path_tolerance: float) -> PendingGoal:
        goal = FollowJointTrajectory.Goal()
        goal.trajectory.joint_names = list(BASE_JOINT_NAMES)
        goal.trajectory.points = [JointTrajectoryPoint(positions=p.tolist(), velocities=v.tolist(),
                                                       time_from_start=duration_msg(float(t)))
                                  for t, p, v in zip(times, positions, velocities)]
        goal.path_tolerance = [JointTolerance(name=name, position=path_tolerance, velocity=-1.0, acceleration=-1.0)
                               for name in BASE_JOINT_NAMES]
        # The end is checked against the navigation's own tolerances afterwards: the controller's goal check only
        # has to say that the base came to rest at the end (not the arm's 2 mm).
        goal.goal_tolerance = [JointTolerance(name=name, position=END_TOLERANCE, velocity=0.0, acceleration=0.0)
                               for name in BASE_JOINT_NAMES]
        return ActionGoal(self._node.base_client, goal, base_outcome)


END_TOLERANCE = 0.02  # [m, rad] of the base controller's goal check


def base_outcome(result: FollowJointTrajectory.Result) -> ArmOutcome:
    """The base trajectory's result: only a path tolerance violation means the base was held back (blocked); a goal
    tolerance miss is left to the navigation's own check of the end."""
    if result.error_code == FollowJointTrajectory.Result.GOAL_TOLERANCE_VIOLATED:
        return ArmOutcome(ArmResult.SUCCEEDED, result.error_string)
    return conv.arm_outcome(result)


class NavigationNode(GoalNode):
    goal_description = 'navigation'
    unknown_error_code = int(NavigateErrorCode.UNKNOWN)
    moving_part = 'the base'

    def __init__(self, **kwargs) -> None:
        super().__init__('navigation', **kwargs)
        self.config = declare_config(self, NavigationConfig)
        self.set_timeouts(self.config.server_timeout, self.config.service_timeout)
        self.interfaces = names = declare_config(self, NavigationInterfaces)
        self.base_client = ActionClient(self, FollowJointTrajectory, names.base_controller_action,
                                        callback_group=self.callbacks)
        self.navigation = NavigationExecutor(_BasePort(self), self.config, log=self._log)
        self._servers = [
            ActionServer(self, NavigateToPose, names.navigate_to_pose_action, self._execute,
                         goal_callback=self._on_goal, cancel_callback=self._on_cancel,
                         result_timeout=RESULT_TIMEOUT_S, callback_group=self.callbacks),
            ActionServer(self, NavigateThroughPoses, names.navigate_through_poses_action,
                         self._execute_through_poses, goal_callback=self._on_goal, cancel_callback=self._on_cancel,
                         result_timeout=RESULT_TIMEOUT_S, callback_group=self.callbacks)]
        self.map_publisher = self.create_publisher(OccupancyGridMsg, names.costmap_topic,
                                                   LATCHED_QOS)  # sent once, never changes
        self.map_publisher.publish(conv.occupancy_grid_msg(self.navigation.static_grid, conv.WORLD_FRAME,
                                                           self.get_clock().now().to_msg()))
        self.get_logger().info('navigation ready')

    def destroy_node(self) -> None:
        for server in self._servers:
            server.destroy()
        self.base_client.destroy()
        super().destroy_node()

    def _execute(self, goal_handle) -> NavigateToPose.Result:
        goal = goal_handle.request
        result = NavigateToPose.Result()

        def run(interruption):
            if goal.pose.header.frame_id not in ACCEPTED_FRAMES:
                return self._refuse_frame(result, goal.pose.header.frame_id)
            position = goal.pose.pose.position
            request = NavigateRequest(pose=(position.x, position.y, conv.yaw_of(goal.pose)))
            outcome = self.navigation.run(request, interruption,
                                          lambda progress: self._feedback(goal_handle, progress))
            result.error_code, result.error_msg = int(outcome.code), outcome.message
            return outcome

        return self.serve(goal_handle, result, run)

    def _execute_through_poses(self, goal_handle) -> NavigateThroughPoses.Result:
        goal = goal_handle.request
        result = NavigateThroughPoses.Result()

        def run(interruption):
            poses = tuple((p.pose.position.x, p.pose.position.y, conv.yaw_of(p)) for p in goal.poses)
            if not poses:
                outcome = NavigateOutcome(Ending.FAILED, NavigateErrorCode.UNREACHABLE, 'the goal has no poses')
                result.error_code, result.error_msg = int(outcome.code), outcome.message
                return outcome
            frames = {p.header.frame_id for p in goal.poses} - set(ACCEPTED_FRAMES)
            if frames:
                return self._refuse_frame(result, sorted(frames)[0])
            outcome = self.navigation.run(NavigateRequest(poses=poses), interruption,
                                          lambda progress: self._feedback(goal_handle, progress, through=True))
            result.error_code, result.error_msg = int(outcome.code), outcome.message
            return outcome

        return self.serve(goal_handle, result, run)

    @staticmethod
    def _refuse_frame(result, frame: str) -> NavigateOutcome:
        """A goal in another frame: no transforms here (the base's pose is known in the world frame only)."""
        result.error_code = int(NavigateErrorCode.TF_ERROR)
        result.error_msg = f'goal poses must be in the world frame ("world", "map" or empty), not {frame!r}'
        return NavigateOutcome(Ending.FAILED, NavigateErrorCode.TF_ERROR, result.error_msg)

    def _feedback(self, goal_handle, progress: NavigateProgress, through: bool = False) -> None:
        fields = dict(current_pose=conv.pose_msg(progress.pose, self.get_clock().now().to_msg()),
                      navigation_time=duration_msg(progress.elapsed),
                      estimated_time_remaining=duration_msg(progress.time_remaining),
                      number_of_recoveries=int(progress.recoveries),
                      distance_remaining=float(progress.distance_remaining))
        if through:
            goal_handle.publish_feedback(NavigateThroughPoses.Feedback(
                number_of_poses_remaining=int(progress.poses_remaining), **fields))
        else:
            goal_handle.publish_feedback(NavigateToPose.Feedback(**fields))


def main(args=None) -> None:
    spin_node(NavigationNode, args)


if __name__ == '__main__':
    main()
