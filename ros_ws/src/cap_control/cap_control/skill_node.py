"""The ROS plumbing every skill node (cap_control.<skill>.node) shares, one module below them all, so that no node
imports another: the latest joint state, the serving of one long action goal at a time that a cancel or cap/stop
interrupts, the ports of the executors over ROS (the arm's FollowJointTrajectory action, the gripper's
GripperCommand action, the perception services), an rclpy action goal as a PendingGoal, and main()'s spinning.

`GoalNode` is the base of the nodes that move the robot (the navigation node's too), `ArmNode` (with the arm's
action client) that of pick_place, follow_path and mobile_pick_place. A GoalNode keeps the latest /joint_states (and
completes futures waiting for named joints), listens to the stop topic, and runs an action goal (`serve`): one at a
time (a second goal is refused), with an `Interruption` that the goal's cancel and the stop topic set, ending
CANCELED, aborted (stopped, failed) or succeeded as the executor's outcome says.

Threading: every callback is in one reentrant group, and main() spins a MultiThreadedExecutor (`spin_node`, the
controller node's too), so the execute callback may wait on service and action futures whose done callbacks other
executor threads run.

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

from cap_ros_common.time import to_seconds
from rclpy.action import CancelResponse, GoalResponse
from cap_ros_common.actions import ActionClient
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Empty

from cap_control import ros_conversions as conv
from cap_control.ports import (
    Arm, Ending, Gripper, GripperOutcome, Interruption, PendingGoal, Perception, interruption_message,
)
from cap_control.robot_interfaces import ArmInterfaces, StateInterfaces
from cap_control.trajectory import JointTrajectory
from cap_interfaces.msg import GraphNames
from cap_ros_common.nodes import spin_node as spin
from cap_ros_common.parameters import declare_config
from control_msgs.action import FollowJointTrajectory, GripperCommand
from cap_interfaces.srv import GetObjectNames, GetObjectState

READY_CHECK_PERIOD = 0.02  # [s] steady time between looks at a server's availability (rclpy has no event for it)


def relay(source, convert: Callable[[Any], Any] = lambda value: value, target: Future | None = None) -> Future:
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


def done_future() -> Future:
    future: Future = Future()
    future.set_result(None)
    return future


class ActionGoal(PendingGoal):
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
            self._result = relay(handle.get_result_async(), lambda response: self._convert(response.result))
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
            relay(handle.cancel_goal_async(), target=early)
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
            return done_future()
        return relay(handle.cancel_goal_async())


class ArmPort(Arm):
    def __init__(self, node: 'ArmNode'):
        self._node = node
        self.server_description = f'the arm action {node.interfaces.arm_controller_action}'
        self.joints_description = f'{node.state_interfaces.joint_states_topic} with the arm joints'

    def server_ready(self) -> Future:
        return self._node.when_ready(self._node.arm_client.server_is_ready)

    def joints(self) -> Future:
        return self._node.arm_joints()

    def opening(self) -> float | None:
        msg = self._node.joint_state()
        if msg is None:
            return None
        interfaces = self._node.interfaces
        if not interfaces.gripper_joint:
            return conv.gripper_opening(msg)
        position = conv.joint_positions(msg, (interfaces.gripper_joint,))
        return None if position is None else interfaces.opening(float(position[0]))

    def state_time(self) -> float | None:
        msg = self._node.joint_state()
        return None if msg is None else to_seconds(msg.header.stamp)

    def follow(self, trajectory: JointTrajectory, contact_tolerance: float | None,
               goal_tolerance: float | None = None) -> PendingGoal:
        goal = conv.follow_trajectory_goal(trajectory, contact_tolerance, goal_tolerance,
                                           self._node.interfaces.arm_joints)
        return ActionGoal(self._node.arm_client, goal, conv.arm_outcome)


class GripperPort(Gripper):
    """The gripper's GripperCommand action, through the node's `gripper_client`: openings [m] in, the controller's
    units on the wire (ArmInterfaces)."""

    def __init__(self, node: 'ArmNode'):
        self._node = node
        self.server_description = f'the gripper action {node.interfaces.gripper_action}'

    def server_ready(self) -> Future:
        return self._node.when_ready(self._node.gripper_client.server_is_ready)

    def command(self, position: float, max_effort: float) -> PendingGoal:
        interfaces = self._node.interfaces
        return ActionGoal(self._node.gripper_client, conv.gripper_goal(interfaces.command_position(position),
                                                                       max_effort),
                          lambda result: GripperOutcome(interfaces.opening(float(result.position)),
                                                        bool(result.stalled)))


class PerceptionPort(Perception):
    """Perception's object services, through the node's `state_client` and `names_client`."""

    service_description = f'the perception service {GraphNames.PERCEPTION_OBJECT_STATE_SERVICE}'

    def __init__(self, node: 'ArmNode'):
        self._node = node

    def state_service_ready(self) -> Future:
        return self._node.when_ready(lambda: self._node.state_client.service_is_ready())

    def names_available(self) -> bool:
        return self._node.names_client.service_is_ready()

    def object_names(self, visible_only: bool = True) -> Future:
        return relay(self._node.names_client.call_async(GetObjectNames.Request(visible_only=visible_only)),
                     lambda response: list(response.names))

    def object_state(self, name: str) -> Future:
        return relay(self._node.state_client.call_async(GetObjectState.Request(name=name)), conv.object_report)


class GoalNode(Node):
    """A node that serves one long action goal at a time that a cancel or the stop topic interrupts, with the latest
    joint state (see the module docstring); ArmNode adds the arm's action client, the navigation node the base's.

    `goal_description` names the goals in log lines ("pick-and-place"). A subclass declares its parameters, then
    gives its timeouts with `set_timeouts`.
    """

    goal_description = 'motion'
    unknown_error_code = 1  # the action's UNKNOWN (PickPlace's and FollowPath's; Navigate's is 9000)
    moving_part = 'the arm'  # what a cancel or stop halts, in the result's message

    def __init__(self, name: str, **kwargs) -> None:
        super().__init__(name, **kwargs)
        self._server_timeout, self._service_timeout = 10.0, 5.0
        self._callbacks = callbacks = ReentrantCallbackGroup()
        # Readiness looks go by wall time: with use_sim_time the node's clock is the simulator's.
        self._steady_clock = Clock(clock_type=ClockType.STEADY_TIME)
        self._joint_lock = threading.Lock()
        self._joint_state: JointState | None = None
        self._joint_waiters: list[tuple[tuple[str, ...], Future]] = []
        self._busy = threading.Lock()
        self._run_lock = threading.Lock()
        self._running: tuple[bytes, Interruption] | None = None  # the goal id being executed and its interruption
        self._early_cancels: set[bytes] = set()  # goals cancelled before their execution began
        self.state_interfaces = declare_config(self, StateInterfaces)
        self.create_subscription(JointState, self.state_interfaces.joint_states_topic, self._on_joint_state, 10,
                                 callback_group=callbacks)
        self.create_subscription(Empty, GraphNames.STOP_TOPIC, self._on_stop, 10, callback_group=callbacks)

    def set_timeouts(self, server_timeout: float, service_timeout: float) -> None:
        """How long `when_ready` looks for a server [s], and how long an interrupted run waits for the controller to
        confirm a cancel [s] (named in the message of an interrupted goal)."""
        self._server_timeout, self._service_timeout = server_timeout, service_timeout

    @property
    def callbacks(self) -> ReentrantCallbackGroup:
        """The callback group of every callback of the node."""
        return self._callbacks

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

    def joints(self, names: tuple[str, ...]) -> Future:
        """Completes with the positions of the named joints from the first joint state that has them all."""
        future: Future = Future()
        with self._joint_lock:
            joints = None if self._joint_state is None else conv.joint_positions(self._joint_state, names)
            if joints is None:
                self._joint_waiters.append((names, future))
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
        deadline = time.monotonic() + self._server_timeout
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
        answered = []
        with self._joint_lock:
            self._joint_state = msg
            if self._joint_waiters:
                waiting = []
                for names, future in self._joint_waiters:
                    joints = conv.joint_positions(msg, names)
                    if joints is None:
                        waiting.append((names, future))
                    else:
                        answered.append((future, joints))
                self._joint_waiters = waiting
        for future, joints in answered:
            future.set_result(joints)

    def _on_stop(self, _: Empty) -> None:
        with self._run_lock:
            if self._running is not None:
                self._running[1].stop()

    def _on_goal(self, _request) -> GoalResponse:
        if self._busy.locked():
            self.get_logger().warning(f'refusing a {self.goal_description} goal: another one is running')
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
    def serve(self, goal_handle, result, run: Callable[[Interruption], Any]):
        """Run one goal: `run(interruption)` does the work, fills `result` (error_code, error_msg, ...) and returns
        the executor's outcome (its `ending` and `halt_confirmed`); the goal ends as the outcome says."""
        if not self._busy.acquire(blocking=False):
            goal_handle.abort()
            result.error_code = self.unknown_error_code
            result.error_msg = f'another {self.goal_description} is running'
            return result
        goal_id = bytes(goal_handle.goal_id.uuid)
        interruption = Interruption()
        with self._run_lock:
            self._running = (goal_id, interruption)
            if goal_id in self._early_cancels or goal_handle.is_cancel_requested:
                self._early_cancels.discard(goal_id)
                interruption.cancel()
        try:
            try:
                outcome = run(interruption)
            except Exception as error:  # noqa: BLE001 - a goal must end with a code, and the node go on
                self.get_logger().error(f'{self.goal_description} failed unexpectedly: {error!r}')
                result.error_code = self.unknown_error_code
                result.error_msg = f'{self.goal_description} failed unexpectedly: {error}'
                goal_handle.abort()
                return result
            if outcome.ending == Ending.SUCCEEDED:
                goal_handle.succeed()
            elif outcome.ending == Ending.CANCELLED or (outcome.ending == Ending.STOPPED
                                                        and goal_handle.is_cancel_requested):
                result.error_msg = interruption_message(Ending.CANCELLED, GraphNames.STOP_TOPIC,
                                                        outcome.halt_confirmed, self._service_timeout,
                                                        self.moving_part)
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


class ArmNode(GoalNode):
    """A GoalNode that moves the arm and its gripper: pick_place, follow_path and mobile_pick_place. Where their
    controllers are is in its ArmInterfaces parameters."""

    def __init__(self, name: str, **kwargs) -> None:
        super().__init__(name, **kwargs)
        self.interfaces = declare_config(self, ArmInterfaces)
        self.interfaces.validate()
        self.arm_client = ActionClient(self, FollowJointTrajectory, self.interfaces.arm_controller_action,
                                       callback_group=self.callbacks)
        self.gripper_client = ActionClient(self, GripperCommand, self.interfaces.gripper_action,
                                           callback_group=self.callbacks)

    def destroy_node(self) -> None:
        self.arm_client.destroy()
        self.gripper_client.destroy()
        super().destroy_node()

    def arm_joints(self) -> Future:
        """Completes with the arm joints (in the kinematics' order) of the first joint state that has them all."""
        return self.joints(tuple(self.interfaces.arm_joints))


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


def spin_node(node_class: type, args: list[str] | None = None) -> None:
    """main() of a skill node: spun on a multi-threaded executor (4 threads), its goals block while they run."""
    spin(node_class, args, threads=4)


__all__ = ['ActionGoal', 'ArmNode', 'ArmPort', 'GoalNode', 'GripperPort', 'PerceptionPort', 'READY_CHECK_PERIOD',
           'done_future', 'relay', 'spin_node']
