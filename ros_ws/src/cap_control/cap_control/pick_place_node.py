"""pick_place: the PickPlace action over the arm's FollowJointTrajectory and GripperCommand actions.

The work is cap_control.pick_place_executor's: this node binds its ports to ROS (the sim's trajectory and gripper
actions, the perception services, /joint_states) and serves the PickPlace action with it: feedback per stage, and
a cancel of the goal or a message on the stop topic interrupts the run (the arm holds where it is; the goal ends
CANCELLED, aborted for a stop). Parameters are declared from PickPlaceConfig (nested: workspace.x_min,
cartesian_limits.speed), MotionSettings and ExecutionConfig, whose fields hold every default.

Threading: every callback is in one reentrant group, and main() spins a MultiThreadedExecutor, so the execute
callback may wait on service and action futures whose done callbacks other executor threads run.

Two waits are timed retries, because rclpy offers no event for what they wait for: whether an action server or
service is available is looked at every READY_CHECK_PERIOD (a timer on the steady clock, so simulated time, which
may run faster than real time or not at all before the first /clock, does not pace it), and `_mark_canceling`
waits out, in short sleeps, the moment the action server marks a cancelled goal CANCELING.
"""
from __future__ import annotations

import threading
import time
from concurrent.futures import Future, InvalidStateError
from typing import Any, Callable

import rclpy
from cap_ros_common.parameters import declare_config
from cap_ros_common.time import to_seconds
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.clock import Clock, ClockType
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Empty

from cap_control import ros_conversions as conv
from cap_control.kinematics import JOINT_NAMES
from cap_control.pick_place import PickPlaceConfig, PickPlaceErrorCode, StageName
from cap_control.pick_place_executor import (
    Arm, Ending, ExecutionConfig, Gripper, GripperOutcome, Interruption, MotionSettings, PendingGoal, Perception,
    PickPlaceExecutor, PickPlaceRequest, interruption_message,
)
from cap_control.trajectory import JointTrajectory
from cap_interfaces.action import FollowJointTrajectory, GripperCommand, PickPlace
from cap_interfaces.msg import GraphNames
from cap_interfaces.srv import GetObjectNames, GetObjectState

READY_CHECK_PERIOD = 0.02  # [s] steady time between looks at a server's availability (rclpy has no event for it)


def _relay(source, convert: Callable[[Any], Any] = lambda value: value, target: Future | None = None) -> Future:
    """A concurrent Future (`target`, or a new one) completed through `convert` when the rclpy future `source`
    completes."""
    target = Future() if target is None else target

    def done(finished) -> None:
        try:
            target.set_result(convert(finished.result()))
        except Exception as error:  # noqa: BLE001 - handed to whoever waits on the future
            target.set_exception(error)

    source.add_done_callback(done)
    return target


def _done() -> Future:
    future: Future = Future()
    future.set_result(None)
    return future


class _ActionGoal(PendingGoal):
    """A goal of an rclpy action client as the executor's PendingGoal.

    A cancel asked for before the server's answer to the goal is remembered and sent as soon as the goal handle
    comes (only a handle can cancel a goal); its future completes once the server has taken it, or at once when
    the goal was refused or never reached the server.
    """

    def __init__(self, client: ActionClient, goal, convert: Callable[[Any], Any]):
        self._accepted: Future = Future()
        self._result: Future = Future()  # replaced by the relay of the result once accepted
        self._handle = None
        self._sent = False  # the server's answer to the goal came (or sending failed)
        self._early_cancel: Future | None = None  # a cancel asked for before that
        self._lock = threading.Lock()
        self._convert = convert
        client.send_goal_async(goal).add_done_callback(self._on_sent)

    @property
    def accepted(self) -> Future:
        return self._accepted

    @property
    def result(self) -> Future:
        return self._result

    def _on_sent(self, future) -> None:
        try:
            handle = future.result()
        except Exception as error:  # noqa: BLE001
            self._settle(None)
            self._accepted.set_exception(error)
            return
        if handle.accepted:
            # The result relay is in place before anyone learns of the acceptance.
            self._result = _relay(handle.get_result_async(), lambda response: self._convert(response.result))
        self._settle(handle)
        self._accepted.set_result(bool(handle.accepted))

    def _settle(self, handle) -> None:
        """Keep the handle (None: sending failed) and send a cancel that was asked for before it came."""
        with self._lock:
            self._handle, self._sent = handle, True
            early, self._early_cancel = self._early_cancel, None
        if early is None:
            return
        if handle is not None and handle.accepted:
            _relay(handle.cancel_goal_async(), target=early)
        else:
            early.set_result(None)  # refused or never sent: nothing moves

    def cancel(self) -> Future:
        with self._lock:
            if not self._sent:
                if self._early_cancel is None:
                    self._early_cancel = Future()
                return self._early_cancel
            handle = self._handle
        if handle is None or not handle.accepted:
            return _done()
        return _relay(handle.cancel_goal_async())


class _ArmPort(Arm):
    server_description = f'the arm action {GraphNames.SIM_FOLLOW_JOINT_TRAJECTORY_ACTION}'
    joints_description = f'{GraphNames.JOINT_STATES_TOPIC} with the arm joints'

    def __init__(self, node: 'PickPlaceNode'):
        self._node = node

    def server_ready(self) -> Future:
        return self._node.when_ready(self._node.arm_client.server_is_ready)

    def joints(self) -> Future:
        return self._node.arm_joints()

    def opening(self) -> float | None:
        msg = self._node.joint_state()
        return None if msg is None else conv.gripper_opening(msg)

    def state_time(self) -> float | None:
        msg = self._node.joint_state()
        return None if msg is None else to_seconds(msg.header.stamp)

    def follow(self, trajectory: JointTrajectory, contact_tolerance: float | None) -> PendingGoal:
        return _ActionGoal(self._node.arm_client, conv.follow_trajectory_goal(trajectory, contact_tolerance),
                           conv.arm_outcome)


class _GripperPort(Gripper):
    server_description = f'the gripper action {GraphNames.SIM_GRIPPER_ACTION}'

    def __init__(self, node: 'PickPlaceNode'):
        self._node = node

    def server_ready(self) -> Future:
        return self._node.when_ready(self._node.gripper_client.server_is_ready)

    def command(self, position: float, max_effort: float) -> PendingGoal:
        return _ActionGoal(self._node.gripper_client, conv.gripper_goal(position, max_effort),
                           lambda result: GripperOutcome(float(result.position), bool(result.stalled)))


class _PerceptionPort(Perception):
    service_description = f'the perception service {GraphNames.PERCEPTION_OBJECT_STATE_SERVICE}'

    def __init__(self, node: 'PickPlaceNode'):
        self._node = node

    def state_service_ready(self) -> Future:
        return self._node.when_ready(lambda: self._node.state_client.service_is_ready())

    def names_available(self) -> bool:
        return self._node.names_client.service_is_ready()

    def object_names(self) -> Future:
        return _relay(self._node.names_client.call_async(GetObjectNames.Request(visible_only=True)),
                      lambda response: list(response.names))

    def object_state(self, name: str) -> Future:
        return _relay(self._node.state_client.call_async(GetObjectState.Request(name=name)), conv.object_report)


class PickPlaceNode(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__('pick_place', **kwargs)
        settings = declare_config(self, MotionSettings)
        self.config = settings.apply(declare_config(self, PickPlaceConfig, skip=('joint_limits', 'clear_view_from')))
        self.timeouts = declare_config(self, ExecutionConfig)

        self._callbacks = callbacks = ReentrantCallbackGroup()
        # Readiness looks go by wall time: with use_sim_time the node's clock is the simulator's.
        self._steady_clock = Clock(clock_type=ClockType.STEADY_TIME)
        self._joint_lock = threading.Lock()
        self._joint_state: JointState | None = None
        self._joint_waiters: list[Future] = []
        self._busy = threading.Lock()
        self._run_lock = threading.Lock()
        self._running: tuple[bytes, Interruption] | None = None  # the goal id being executed and its interruption
        self._early_cancels: set[bytes] = set()  # goals cancelled before their execution began
        self.create_subscription(JointState, GraphNames.JOINT_STATES_TOPIC, self._on_joint_state, 10,
                                 callback_group=callbacks)
        self.create_subscription(Empty, GraphNames.STOP_TOPIC, self._on_stop, 10, callback_group=callbacks)
        self._create_perception_clients(self)
        self.arm_client = ActionClient(self, FollowJointTrajectory, GraphNames.SIM_FOLLOW_JOINT_TRAJECTORY_ACTION,
                                       callback_group=callbacks)
        self.gripper_client = ActionClient(self, GripperCommand, GraphNames.SIM_GRIPPER_ACTION,
                                           callback_group=callbacks)
        self.pick_place = PickPlaceExecutor(_ArmPort(self), _GripperPort(self), _PerceptionPort(self), self.config,
                                           self.timeouts, stop_source=GraphNames.STOP_TOPIC, log=self._log)
        self._server = ActionServer(self, PickPlace, GraphNames.PICK_PLACE_ACTION, self._execute,
                                    goal_callback=self._on_goal, cancel_callback=self._on_cancel,
                                    callback_group=callbacks)
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
        self.arm_client.destroy()
        self.gripper_client.destroy()
        super().destroy_node()

    def _log(self, level: str, message: str) -> None:
        # rclpy refuses one call site logging at different severities: one call per level.
        logger = self.get_logger()
        if level == 'debug':
            logger.debug(message)
        elif level == 'info':
            logger.info(message)
        else:
            logger.warning(message)

    # ------------------------------------------------------------------------------------------- port support
    def joint_state(self) -> JointState | None:
        with self._joint_lock:
            return self._joint_state

    def arm_joints(self) -> Future:
        """Completes with the arm joints of the first joint state that has them all."""
        future: Future = Future()
        with self._joint_lock:
            joints = None if self._joint_state is None else conv.joint_positions(self._joint_state, JOINT_NAMES)
            if joints is None:
                self._joint_waiters.append(future)
                return future
        future.set_result(joints)
        return future

    def when_ready(self, ready: Callable[[], bool]) -> Future:
        """Completes once `ready()` holds, looked at every READY_CHECK_PERIOD of steady time until server_timeout
        (wall time) has passed; then it stays pending. Cancelling the future stops the looking."""
        future: Future = Future()
        if ready():
            future.set_result(None)
            return future
        deadline = time.monotonic() + self.timeouts.server_timeout
        ended = threading.Event()
        lock = threading.Lock()

        def end(*_: Any) -> None:
            # Ready, given up, or the waiter stopped waiting (cancelled the future): the timer goes.
            with lock:
                if ended.is_set():
                    return
                ended.set()
            self.destroy_timer(timer)  # a no-op if the node went first (it destroyed its timers then)

        def look() -> None:
            if ended.is_set():
                return
            if ready():
                try:
                    future.set_result(None)  # ends the timer through the done callback
                except InvalidStateError:
                    pass  # cancelled meanwhile
            elif time.monotonic() >= deadline:
                end()

        timer = self.create_timer(READY_CHECK_PERIOD, look, callback_group=self._callbacks, clock=self._steady_clock)
        future.add_done_callback(end)
        return future

    # ------------------------------------------------------------------------------------------- inputs
    def _on_joint_state(self, msg: JointState) -> None:
        with self._joint_lock:
            self._joint_state = msg
            waiters = self._joint_waiters
            joints = conv.joint_positions(msg, JOINT_NAMES) if waiters else None
            if joints is not None:
                self._joint_waiters = []
        if joints is not None:
            for future in waiters:
                future.set_result(joints.copy())

    def _on_stop(self, _: Empty) -> None:
        with self._run_lock:
            if self._running is not None:
                self._running[1].stop()

    def _on_goal(self, _request) -> GoalResponse:
        if self._busy.locked():
            self.get_logger().warning('refusing a pick-and-place goal: another one is running')
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _on_cancel(self, goal_handle) -> CancelResponse:
        goal_id = bytes(goal_handle.goal_id.uuid)
        with self._run_lock:
            if self._running is not None and self._running[0] == goal_id:
                self._running[1].cancel()
            else:
                self._early_cancels.add(goal_id)
        return CancelResponse.ACCEPT

    # ------------------------------------------------------------------------------------------- execution
    def _execute(self, goal_handle) -> PickPlace.Result:
        result = PickPlace.Result()
        if not self._busy.acquire(blocking=False):
            goal_handle.abort()
            result.error_code, result.error_msg = int(PickPlaceErrorCode.UNKNOWN), 'another pick-and-place is running'
            return result
        goal_id = bytes(goal_handle.goal_id.uuid)
        interruption = Interruption()
        with self._run_lock:
            self._running = (goal_id, interruption)
            if goal_id in self._early_cancels or goal_handle.is_cancel_requested:
                self._early_cancels.discard(goal_id)
                interruption.cancel()
        request = goal_handle.request
        try:
            outcome = self.pick_place.run(
                PickPlaceRequest(request.object_name, request.target_name,
                                 (request.target_position.x, request.target_position.y)),
                interruption, lambda stage, progress: self._feedback(goal_handle, stage, progress))
            result.error_code, result.error_msg = int(outcome.code), outcome.message
            if outcome.final_position is not None:
                result.final_position = conv.point_msg(outcome.final_position)
            if outcome.ending == Ending.SUCCEEDED:
                goal_handle.succeed()
            elif outcome.ending == Ending.CANCELLED or (outcome.ending == Ending.STOPPED
                                                        and goal_handle.is_cancel_requested):
                result.error_msg = interruption_message(Ending.CANCELLED, GraphNames.STOP_TOPIC,
                                                        outcome.halt_confirmed, self.timeouts.service_timeout)
                if _mark_canceling(goal_handle):
                    goal_handle.canceled()
                else:
                    goal_handle.abort()
            else:
                goal_handle.abort()
        finally:
            with self._run_lock:
                self._running = None
            self._busy.release()
        return result

    @staticmethod
    def _feedback(goal_handle, stage: StageName, progress: float) -> None:
        goal_handle.publish_feedback(PickPlace.Feedback(stage=stage.value, progress=float(progress)))


def _mark_canceling(goal_handle, timeout_s: float = 1.0) -> bool:
    """Wait (at most `timeout_s`) until the action server has marked the goal CANCELING; True once it has.

    The server marks it just after our cancel callback returns, and the run that callback interrupted may end
    before that; a goal can end CANCELED only from CANCELING. rclpy offers no event for that moment, so this one
    rare race is waited out in short sleeps.
    """
    deadline = time.monotonic() + timeout_s
    while not goal_handle.is_cancel_requested and time.monotonic() < deadline:
        time.sleep(0.002)
    return goal_handle.is_cancel_requested


def main(args=None) -> None:
    rclpy.init(args=args)
    node = None
    try:
        node = PickPlaceNode()
        executor = MultiThreadedExecutor(num_threads=4)
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
