"""pick_place: the PickPlace action over the arm's FollowJointTrajectory and GripperCommand actions.

The work is cap_control.pick_place.executor's (planned by cap_control.pick_place.plan): this node binds its ports to
ROS (the sim's trajectory and gripper actions, the perception services, /joint_states) and serves the PickPlace
action with it: feedback per stage, and a cancel of the goal or a message on the stop topic interrupts the run (the
arm holds where it is; the goal ends CANCELLED, aborted for a stop). Parameters are declared from PickPlaceConfig
(nested: workspace.x_min, cartesian_limits.speed), MotionSettings and ExecutionConfig, whose fields hold every
default. What it shares with the other nodes that move the arm (joint state, the arm, gripper and perception ports,
one goal at a time, stop) is cap_control.skill_node's.
"""
from __future__ import annotations

from cap_ros_common.actions import RESULT_TIMEOUT_S
from cap_ros_common.parameters import declare_config
from rclpy.action import ActionServer
from rclpy.callback_groups import ReentrantCallbackGroup

from cap_control import ros_conversions as conv
from cap_control.pick_place.executor import ExecutionConfig, MotionSettings, PickPlaceExecutor, PickPlaceRequest
from cap_control.pick_place.plan import PickPlaceConfig, StageName
from cap_control.skill_node import ArmNode, ArmPort, GripperPort, PerceptionPort, spin_node
from cap_interfaces.action import PickPlace
from cap_interfaces.msg import GraphNames
from cap_interfaces.srv import GetObjectNames, GetObjectState


class PickPlaceNode(ArmNode):
    goal_description = 'pick-and-place'

    def __init__(self, **kwargs) -> None:
        super().__init__('pick_place', **kwargs)
        settings = declare_config(self, MotionSettings)
        self.config = settings.apply(declare_config(
            self, PickPlaceConfig, skip=('joint_limits', 'clear_view_from', 'look_again_joints')))
        self.timeouts = declare_config(self, ExecutionConfig)
        self.set_timeouts(self.timeouts.server_timeout, self.timeouts.service_timeout)
        self._create_perception_clients(self)
        self.pick_place = PickPlaceExecutor(ArmPort(self), GripperPort(self), PerceptionPort(self), self.config,
                                           self.timeouts, stop_source=GraphNames.STOP_TOPIC, log=self._log)
        self._server = ActionServer(self, PickPlace, GraphNames.PICK_PLACE_ACTION, self._execute,
                                    goal_callback=self._on_goal, cancel_callback=self._on_cancel,
                                    result_timeout=RESULT_TIMEOUT_S, callback_group=self.callbacks)
        self.get_logger().info(f'pick-and-place ready; workspace {self.config.workspace.describe()}')

    def _create_perception_clients(self, node) -> None:
        group = ReentrantCallbackGroup()
        self.state_client = node.create_client(GetObjectState, GraphNames.PERCEPTION_OBJECT_STATE_SERVICE,
                                               callback_group=group)
        self.names_client = node.create_client(GetObjectNames, GraphNames.PERCEPTION_OBJECT_NAMES_SERVICE,
                                               callback_group=group)

    def bind_perception_clients(self, node) -> None:
        """Move the perception clients onto `node` (call before the first goal).

        The middleware hands each perception answer to every client of that service in the process, and each
        client then wakes its executor. A graph that composes this node with lmp_node binds these clients to a node
        on its events executor, so that the robot API's many perception calls do not wake the multi-threaded
        executor (a whole Python wait set rebuilt each time) through these idle clients.
        """
        old = (self.state_client, self.names_client)
        self._create_perception_clients(node)
        for client in old:
            self.destroy_client(client)

    def destroy_node(self) -> None:
        self._server.destroy()
        super().destroy_node()

    def _execute(self, goal_handle) -> PickPlace.Result:
        request = goal_handle.request
        result = PickPlace.Result()

        def run(interruption):
            outcome = self.pick_place.run(
                PickPlaceRequest(request.object_name, request.target_name,
                                 (request.target_position.x, request.target_position.y)),
                interruption, lambda stage, progress: self._feedback(goal_handle, stage, progress))
            result.error_code, result.error_msg = int(outcome.code), outcome.message
            if outcome.final_position is not None:
                result.final_position = conv.point_msg(outcome.final_position)
            return outcome

        return self.serve(goal_handle, result, run)

    @staticmethod
    def _feedback(goal_handle, stage: StageName, progress: float) -> None:
        goal_handle.publish_feedback(PickPlace.Feedback(stage=stage.value, progress=float(progress)))


def main(args=None) -> None:
    spin_node(PickPlaceNode, args)


if __name__ == '__main__':
    main()
