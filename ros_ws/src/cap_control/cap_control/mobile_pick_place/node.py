"""mobile_pick_place: the MobilePickPlace action (/cap/control/mobile_pick_place) for the mobile manipulator.

The work is cap_control.mobile_pick_place.executor's: this node binds its ports to ROS (the navigation node's
Navigate action to bring the base within reach, the simulator's arm trajectory and gripper actions, the perception
services, /joint_states for the arm and the base) and serves the action: pick an object, or put the held one down
at a point (on the furniture there, or into a bin) or on another object; feedback per stage ("navigate", then the
arm's); a cancel of the goal or a message on the stop topic interrupts the run (the base and the arm hold where
they are). What it shares with the other nodes that move the arm (the arm, gripper and perception ports) is
cap_control.skill_node's. Parameters: ExecutionConfig (timeouts); where the base may stand is the navigation node's
own map (/cap/control/navigation/map), so its parameters decide that here too; goals wait for it like for the
navigation action.
"""
from __future__ import annotations

from concurrent.futures import Future

from cap_mobile.robot import BASE_JOINT_NAMES
from cap_ros_common.actions import RESULT_TIMEOUT_S, ActionClient
from cap_ros_common.parameters import declare_config
from cap_ros_common.qos import LATCHED_QOS
from nav_msgs.msg import OccupancyGrid as OccupancyGridMsg
from rclpy.action import ActionServer

from cap_control import ros_conversions as conv
from cap_control.mobile_pick_place.executor import (
    TASK_PICK, TASK_PLACE_AT_OBJECT, TASK_PLACE_AT_POSITION, MobilePickPlaceExecutor, MobileRequest, Navigator,
)
from cap_control.navigation.plan import OccupancyGrid
from cap_control.pick_place.executor import ExecutionConfig
from cap_control.ports import PendingGoal
from cap_control.skill_node import ActionGoal, ArmNode, ArmPort, GripperPort, PerceptionPort, spin_node
from cap_interfaces.action import GripperCommand, MobilePickPlace, Navigate
from cap_interfaces.msg import GraphNames

TASKS = {MobilePickPlace.Goal.TASK_PICK: TASK_PICK,
         MobilePickPlace.Goal.TASK_PLACE_AT_POSITION: TASK_PLACE_AT_POSITION,
         MobilePickPlace.Goal.TASK_PLACE_AT_OBJECT: TASK_PLACE_AT_OBJECT}


class _NavigatorPort(Navigator):
    server_description = f'the navigation action {GraphNames.NAVIGATE_ACTION} and its map'

    def __init__(self, node: 'MobilePickPlaceNode'):
        self._node = node

    def server_ready(self) -> Future:
        return self._node.when_ready(lambda: self._node.navigate_client.server_is_ready()
                                     and self._node.navigation_map() is not None)

    def map(self) -> OccupancyGrid:
        return self._node.navigation_map()

    def go(self, pose: tuple[float, float, float]) -> PendingGoal:
        goal = Navigate.Goal(pose=conv.pose_msg(pose, self._node.get_clock().now().to_msg()))
        return ActionGoal(self._node.navigate_client, goal, lambda result: (int(result.error_code),
                                                                            result.error_msg))

    def pose(self) -> Future:
        return self._node.joints(BASE_JOINT_NAMES)


class MobilePickPlaceNode(ArmNode):
    goal_description = 'mobile pick-and-place'
    moving_part = 'the robot'

    def __init__(self, **kwargs) -> None:
        super().__init__('mobile_pick_place', **kwargs)
        self.timeouts = declare_config(self, ExecutionConfig)
        self.set_timeouts(self.timeouts.server_timeout, self.timeouts.service_timeout)
        self.state_client = self.names_client = None
        self._create_perception_clients()
        self.gripper_client = ActionClient(self, GripperCommand, GraphNames.SIM_GRIPPER_ACTION,
                                           callback_group=self.callbacks)
        self.navigate_client = ActionClient(self, Navigate, GraphNames.NAVIGATE_ACTION, callback_group=self.callbacks)
        self._map: OccupancyGrid | None = None  # replaced whole by the callback, read by goals' threads
        self.create_subscription(OccupancyGridMsg, GraphNames.NAVIGATION_MAP_TOPIC, self._on_map, LATCHED_QOS,
                                 callback_group=self.callbacks)
        self.executor_ = MobilePickPlaceExecutor(ArmPort(self), GripperPort(self), PerceptionPort(self),
                                                 _NavigatorPort(self), timeouts=self.timeouts,
                                                 stop_source=GraphNames.STOP_TOPIC, log=self._log)
        self._server = ActionServer(self, MobilePickPlace, GraphNames.MOBILE_PICK_PLACE_ACTION, self._execute,
                                    goal_callback=self._on_goal, cancel_callback=self._on_cancel,
                                    result_timeout=RESULT_TIMEOUT_S, callback_group=self.callbacks)
        self.get_logger().info('mobile pick-and-place ready')

    def _create_perception_clients(self) -> None:
        from cap_interfaces.srv import GetObjectNames, GetObjectState
        self.state_client = self.create_client(GetObjectState, GraphNames.PERCEPTION_OBJECT_STATE_SERVICE,
                                               callback_group=self.callbacks)
        self.names_client = self.create_client(GetObjectNames, GraphNames.PERCEPTION_OBJECT_NAMES_SERVICE,
                                               callback_group=self.callbacks)

    def _on_map(self, msg: OccupancyGridMsg) -> None:
        try:
            grid = conv.occupancy_grid(msg)
        except ValueError as error:
            self.get_logger().error(f'the navigation map was dropped: {error}')
            return
        self._map = grid

    def navigation_map(self) -> OccupancyGrid | None:
        return self._map

    def destroy_node(self) -> None:
        self._server.destroy()
        self.gripper_client.destroy()
        self.navigate_client.destroy()
        super().destroy_node()

    def _execute(self, goal_handle) -> MobilePickPlace.Result:
        goal = goal_handle.request
        result = MobilePickPlace.Result()

        def run(interruption):
            task = TASKS.get(goal.task, f'code {goal.task}')
            outcome = self.executor_.run(
                MobileRequest(task, goal.object_name, (goal.target_position.x, goal.target_position.y)),
                interruption, lambda stage, progress: goal_handle.publish_feedback(
                    MobilePickPlace.Feedback(stage=stage, progress=float(progress))))
            result.error_code, result.error_msg = int(outcome.code), outcome.message
            if outcome.final_position is not None:
                result.final_position = conv.point_msg(outcome.final_position)
            return outcome

        return self.serve(goal_handle, result, run)


def main(args=None) -> None:
    spin_node(MobilePickPlaceNode, args)


if __name__ == '__main__':
    main()
