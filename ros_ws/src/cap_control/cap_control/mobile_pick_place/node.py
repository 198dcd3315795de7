"""mobile_pick_place: the MobilePickPlace action (/cap/control/mobile_pick_place) for the mobile manipulator.

The work is cap_control.mobile_pick_place.executor's: this node binds its ports to ROS (nav2's NavigateToPose action
to bring the base within reach, the base's pose on tf, the arm's trajectory and gripper actions, the perception
services, the joint states for the arm) and serves the action: pick an object, or put the held one down
at a point (on the furniture there, or into a bin) or on another object; feedback per stage ("navigate", then the
arm's); a cancel of the goal or a message on the stop topic interrupts the run (the base and the arm hold where
they are). What it shares with the other nodes that move the arm (the arm, gripper and perception ports) is
cap_control.skill_node's. Parameters: ExecutionConfig (timeouts), ArmInterfaces, MobileInterfaces (the navigator's
names and frames); where the base may stand is the navigator's own costmap (the navigation node's, or nav2's global
costmap), so its parameters decide that here too; goals wait for it like for the navigation action.
"""
from __future__ import annotations

from concurrent.futures import Future

from cap_ros_common.actions import RESULT_TIMEOUT_S, ActionClient
from cap_ros_common.parameters import declare_config
from cap_ros_common.qos import LATCHED_QOS
from cap_ros_common.tf import TfListener
from cap_ros_common.transforms import TransformError
from nav2_msgs.action import NavigateToPose
from nav_msgs.msg import OccupancyGrid as OccupancyGridMsg
from rclpy.action import ActionServer
from std_srvs.srv import Trigger

from cap_control import ros_conversions as conv
from cap_control.mobile_pick_place.executor import (
    TASK_PICK, TASK_PLACE_AT_OBJECT, TASK_PLACE_AT_POSITION, MobilePickPlaceExecutor, MobileRequest, Navigator,
)
from cap_control.navigation.plan import OccupancyGrid
from cap_control.pick_place.executor import ExecutionConfig
from cap_control.ports import PendingGoal
from cap_control.robot_interfaces import MobileInterfaces
from cap_control.skill_node import ActionGoal, ArmNode, ArmPort, GripperPort, PerceptionPort, spin_node
from cap_interfaces.action import MobilePickPlace
from cap_interfaces.msg import GraphNames

TASKS = {MobilePickPlace.Goal.TASK_PICK: TASK_PICK,
         MobilePickPlace.Goal.TASK_PLACE_AT_POSITION: TASK_PLACE_AT_POSITION,
         MobilePickPlace.Goal.TASK_PLACE_AT_OBJECT: TASK_PLACE_AT_OBJECT}


class _NavigatorPort(Navigator):
    def __init__(self, node: 'MobilePickPlaceNode'):
        self._node = node
        names = node.mobile_interfaces
        self.server_description = f'the navigation action {names.navigate_to_pose_action} and its costmap ' \
                                  f'{names.costmap_topic}'

    def server_ready(self) -> Future:
        return self._node.when_ready(lambda: self._node.navigate_client.server_is_ready()
                                     and self._node.navigation_map() is not None
                                     and self._node.base_pose() is not None)

    def map(self) -> OccupancyGrid:
        return self._node.navigation_map()

    def go(self, pose: tuple[float, float, float]) -> PendingGoal:
        goal = NavigateToPose.Goal(pose=conv.pose_msg(pose, self._node.get_clock().now().to_msg(),
                                                      self._node.mobile_interfaces.world_frame))
        return ActionGoal(self._node.navigate_client, goal, lambda result: (int(result.error_code),
                                                                            result.error_msg))

    def pose(self) -> Future:
        future: Future = Future()
        pose = self._node.base_pose()
        if pose is None:
            future.set_exception(RuntimeError('the base\'s pose is not on tf'))
        else:
            future.set_result(pose)
        return future


class MobilePickPlaceNode(ArmNode):
    goal_description = 'mobile pick-and-place'
    moving_part = 'the robot'

    def __init__(self, **kwargs) -> None:
        super().__init__('mobile_pick_place', **kwargs)
        self.timeouts = declare_config(self, ExecutionConfig)
        self.set_timeouts(self.timeouts.server_timeout, self.timeouts.service_timeout)
        self.state_client = self.names_client = None
        self._create_perception_clients()
        self.mobile_interfaces = names = declare_config(self, MobileInterfaces)
        self.navigate_client = ActionClient(self, NavigateToPose, names.navigate_to_pose_action,
                                            callback_group=self.callbacks)
        self._map: OccupancyGrid | None = None  # replaced whole by the callback, read by goals' threads
        self.create_subscription(OccupancyGridMsg, names.costmap_topic, self._on_map, LATCHED_QOS,
                                 callback_group=self.callbacks)
        self.tf = TfListener(self, callback_group=self.callbacks)
        self.executor_ = MobilePickPlaceExecutor(ArmPort(self), GripperPort(self), PerceptionPort(self),
                                                 _NavigatorPort(self), timeouts=self.timeouts,
                                                 stop_source=GraphNames.STOP_TOPIC, log=self._log)
        self._server = ActionServer(self, MobilePickPlace, GraphNames.MOBILE_PICK_PLACE_ACTION, self._execute,
                                    goal_callback=self._on_goal, cancel_callback=self._on_cancel,
                                    result_timeout=RESULT_TIMEOUT_S, callback_group=self.callbacks)
        self.create_service(Trigger, GraphNames.CONTROL_FORGET_SERVICE, self._on_forget,
                            callback_group=self.callbacks)
        self.get_logger().info('mobile pick-and-place ready')

    def _on_forget(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        """The scene was replaced: the gripper holds nothing it knows of."""
        self.executor_.held = None
        response.success, response.message = True, 'the gripper holds nothing'
        return response

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

    def base_pose(self) -> tuple[float, float, float] | None:
        """The base's x, y and yaw in the world frame, from tf (None while tf does not join them)."""
        names = self.mobile_interfaces
        try:
            return conv.planar_pose(self.tf.buffer.lookup(names.world_frame, names.base_frame))
        except TransformError:
            return None

    def destroy_node(self) -> None:
        self._server.destroy()
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
