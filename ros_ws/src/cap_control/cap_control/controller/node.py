"""controller_node: the RunController action, a generated controller function run at a fixed rate.

The loop is cap_control.controller.executor's, the run's checks and limits cap_control.controller.plan's; this node
binds the loop's ports to ROS: the plant to the simulator's ControlStep service (lockstep stepping: the plant
advances one period per request, so the rate holds in simulated time), the controller to lmp_node's CallController
service (the function runs in lmp_node's sandbox process). The node owns the limits: the generated program cannot
reach them. Every run starts with ControlStep's START: the simulator puts the plant at its defined start (the
cart-pole at its seeded start, held; the arm on its servos, at rest) before the controller is called once, or the
run is refused with the simulator's reason (PLANT_ERROR). /cap/stop or a cancel ends the run at the next tick; every
end releases the plant (made safe). GetPlantState answers a plant's state now, from /joint_states, packed as a
controller would see it. Parameters: ControllerNodeConfig (cap_control.controller.plan), overridden in
config/controller.yaml.

Threading: the action's execute callback blocks for the whole run, so it needs a MultiThreadedExecutor (main()
spins one of 4 threads, cap_control.skill_node.spin_node); the per-tick requests are sent asynchronously and awaited
on events, never by spinning. The one-process graph may move the two per-tick clients onto a node of its events
executor (`bind_quick`).
"""
from __future__ import annotations

import threading
from typing import Any, Sequence

import numpy as np
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Empty

from cap_control.controller.executor import ControlLoop, Outcome, PlantError, Tick, percentile
from cap_control.controller.plan import (
    ControllerFailure, ControllerNodeConfig, Limits, Reading, RunError, make_run, state_vector,
)
from cap_control.skill_node import spin_node
from cap_controllers import plants
from cap_interfaces.action import RunController
from cap_interfaces.msg import GraphNames
from cap_interfaces.srv import CallController, ControlStep, GetPlantState
from cap_ros_common.actions import RESULT_TIMEOUT_S
from cap_ros_common.parameters import declare_config

STOP_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)  # a stop must not be lost
STATE_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
CODES = {Outcome.SUCCESSFUL: RunController.Result.SUCCESSFUL, Outcome.STOPPED: RunController.Result.STOPPED,
         Outcome.LIMIT_VIOLATED: RunController.Result.LIMIT_VIOLATED,
         Outcome.CONTROLLER_ERROR: RunController.Result.CONTROLLER_ERROR,
         Outcome.OVERRUN: RunController.Result.OVERRUN, Outcome.PLANT_ERROR: RunController.Result.PLANT_ERROR}


def _wait(future, timeout_s: float):
    """The result of an rclpy future another thread's executor completes; None when it did not within timeout_s.

    A future already done when the callback is added hands the callback to its executor as a task, which an events
    executor with nothing else to do may not run for a long time (in lockstep nothing else happens): hence the
    look at `done()` once the callback is in place."""
    done = threading.Event()
    future.add_done_callback(lambda _: done.set())
    if not future.done() and not done.wait(timeout_s):
        future.cancel()
        return None
    return future.result()


class RosPlant:
    """The loop's Plant port over the simulator's ControlStep service."""

    def __init__(self, client, spec: plants.PlantSpec, timeout_s: float) -> None:
        self._client, self._spec, self._timeout_s = client, spec, timeout_s

    def start(self) -> Reading:
        request = ControlStep.Request(action=ControlStep.Request.START, joint_names=list(self._spec.joints),
                                      actuator_names=list(self._spec.actuators))
        return self._reading(self._call(request, ''))  # the refusal is the plant's reason

    def step(self, efforts: Sequence[float], duration: float) -> Reading:
        request = ControlStep.Request(action=ControlStep.Request.STEP, joint_names=list(self._spec.joints),
                                      actuator_names=list(self._spec.actuators), efforts=list(efforts),
                                      duration=float(duration))
        return self._reading(self._call(request, 'the plant refused the step'))

    def release(self) -> None:
        self._call(ControlStep.Request(action=ControlStep.Request.RELEASE), 'the plant refused the release')

    @staticmethod
    def _reading(response) -> Reading:
        return Reading(response.time, np.asarray(response.positions), np.asarray(response.velocities))

    def _call(self, request, refused: str):
        name = self._client.srv_name
        if not self._client.service_is_ready() and not self._client.wait_for_service(timeout_sec=self._timeout_s):
            raise PlantError(f'the plant ({name}) is not running')
        response = _wait(self._client.call_async(request), self._timeout_s)
        if response is None:
            raise PlantError(f'the plant ({name}) did not answer within {self._timeout_s:g} s')
        if not response.success:
            raise PlantError(f'{refused}: {response.message}' if refused else response.message)
        return response


class RosController:
    """The loop's Controller port over lmp_node's CallController service."""

    def __init__(self, client, handle: int, plant: str, timeout_s: float) -> None:
        self._client, self._handle, self._plant, self._timeout_s = client, handle, plant, timeout_s

    def call(self, state: np.ndarray, budget_s: float) -> tuple[Sequence[float], float]:
        request = CallController.Request(handle=self._handle, plant=self._plant, state=state.tolist(),
                                         time_budget=float(budget_s))
        if not self._client.service_is_ready() and not self._client.wait_for_service(timeout_sec=self._timeout_s):
            raise ControllerFailure('ControllerOverrun', f'the session ({self._client.srv_name}) is not running')
        response = _wait(self._client.call_async(request), self._timeout_s)
        if response is None:
            raise ControllerFailure('ControllerOverrun', f'the controller did not answer within '
                                                         f'{self._timeout_s * 1000:g} ms')
        if not response.success:
            raise ControllerFailure(response.error_type or 'RuntimeError', response.error)
        return list(response.output), float(response.seconds)


class ControllerNode(Node):
    def __init__(self, **kwargs: Any) -> None:
        super().__init__('controller_node', **kwargs)
        self.config = declare_config(self, ControllerNodeConfig)
        self._group = ReentrantCallbackGroup()
        self._client_node: Node = self
        self._create_clients(self)
        self._run_lock = threading.Lock()  # one controller at a time
        self._stop = threading.Event()  # of the run in progress
        self._joints: dict[str, tuple[float, float]] = {}  # latest /joint_states: name -> (position, velocity)
        self._joints_lock = threading.Lock()
        self.last_result: Any = None  # cap_control.controller.executor.Result of the last run
        self._first_joints = threading.Event()
        self.create_subscription(Empty, GraphNames.STOP_TOPIC, lambda _: self._stop.set(), STOP_QOS,
                                 callback_group=self._group)
        self.create_subscription(JointState, GraphNames.JOINT_STATES_TOPIC, self._on_joint_states, STATE_QOS,
                                 callback_group=self._group)
        self.create_service(GetPlantState, GraphNames.PLANT_STATE_SERVICE, self._on_plant_state,
                            callback_group=self._group)
        self._server = ActionServer(self, RunController, GraphNames.RUN_CONTROLLER_ACTION, self._execute,
                                    goal_callback=lambda _: GoalResponse.ACCEPT, cancel_callback=self._on_cancel,
                                    result_timeout=RESULT_TIMEOUT_S, callback_group=self._group)

    def _create_clients(self, node: Node) -> None:
        self._step_client = node.create_client(ControlStep, GraphNames.SIM_CONTROL_STEP_SERVICE,
                                               callback_group=self._group if node is self else None)
        self._call_client = node.create_client(CallController, GraphNames.CONTROLLER_CALL_SERVICE,
                                               callback_group=self._group if node is self else None)

    def bind_quick(self, node: Node) -> None:
        """Move the per-tick clients (plant step, controller call) onto `node` (before the first goal): a graph
        that spins a small node on a fast executor keeps their round trips off this node's busy executor."""
        old_node, old = self._client_node, (self._step_client, self._call_client)
        self._create_clients(node)
        self._client_node = node
        for client in old:
            old_node.destroy_client(client)

    def destroy_node(self) -> None:
        self._stop.set()
        self._server.destroy()
        super().destroy_node()

    # ---------------------------------------------------------------------------------------------- state
    def _on_joint_states(self, message: JointState) -> None:
        with self._joints_lock:
            for name, position, velocity in zip(message.name, message.position, message.velocity):
                self._joints[name] = (position, velocity)
        self._first_joints.set()

    def _on_plant_state(self, request: GetPlantState.Request, response: GetPlantState.Response):
        try:
            spec = plants.plant(request.plant)
        except ValueError as error:
            response.success, response.message = False, str(error)
            return response
        self._first_joints.wait(self.config.plant_timeout)  # just started: the simulator's first state is near
        with self._joints_lock:
            known = [self._joints.get(name) for name in spec.joints]
        if any(value is None for value in known):
            response.success = False
            response.message = f'no state of the {spec.name} yet on {self.resolve_topic_name("joint_states")}'
            return response
        reading = Reading(0.0, np.array([v[0] for v in known]), np.array([v[1] for v in known]))
        response.success, response.state = True, state_vector(spec, 0.0, reading).tolist()
        return response

    # ---------------------------------------------------------------------------------------------- runs
    def _on_cancel(self, _request) -> CancelResponse:
        self._stop.set()
        return CancelResponse.ACCEPT

    def _limits(self, spec: plants.PlantSpec) -> Limits:
        config = self.config
        return Limits(effort=spec.effort_limits, max_pole_angle=config.max_pole_angle,
                      max_cart_position=config.max_cart_position, max_joint_speed=config.max_joint_speed,
                      workspace_min=tuple(config.workspace_min), workspace_max=tuple(config.workspace_max),
                      effort_stop_factor=config.effort_stop_factor)

    def _execute(self, goal_handle) -> RunController.Result:
        goal = goal_handle.request
        result = RunController.Result()
        if not self._run_lock.acquire(blocking=False):
            goal_handle.abort()
            result.error_code = RunController.Result.INVALID_GOAL
            result.error_msg = 'a controller is running already; stop it first'
            return result
        try:
            try:
                spec = plants.plant(goal.plant)
                run = make_run(goal.controller, goal.plant, goal.rate, goal.duration, goal.time_budget,
                               goal.max_pole_angle, goal.max_cart_position, goal.max_joint_speed,
                               list(goal.max_effort), base=self._limits(spec))
            except (RunError, ValueError) as error:
                goal_handle.abort()
                result.error_code, result.error_msg = RunController.Result.INVALID_GOAL, str(error)
                return result
            self._stop.clear()
            plant = RosPlant(self._step_client, spec, self.config.plant_timeout)
            controller = RosController(self._call_client, goal.handle, spec.name, self.config.call_timeout)

            def feedback(tick: Tick) -> None:
                goal_handle.publish_feedback(RunController.Feedback(
                    time=tick.time, calls=tick.calls, state=tick.state.tolist(), output=tick.output.tolist()))

            outcome = ControlLoop(plant, controller).run(run, self._stop, feedback, self.config.feedback_every)
            self.last_result = outcome  # every call's times, for benchmarks in the same process
        finally:
            self._run_lock.release()
        result.error_code = CODES[outcome.outcome]
        result.error_msg = outcome.message
        result.simulated_time, result.calls, result.saturated_calls = \
            outcome.simulated_time, outcome.calls, outcome.saturated_calls
        result.call_p50, result.call_p99 = percentile(outcome.call_seconds, 0.5), percentile(outcome.call_seconds, 0.99)
        result.function_p50 = percentile(outcome.function_seconds, 0.5)
        result.function_p99 = percentile(outcome.function_seconds, 0.99)
        result.final_state = outcome.final_state.tolist()
        if outcome.outcome is Outcome.SUCCESSFUL:
            goal_handle.succeed()
        elif outcome.outcome is Outcome.STOPPED and goal_handle.is_cancel_requested:
            goal_handle.canceled()
        else:
            goal_handle.abort()
        self.get_logger().info(f'{run.controller} on the {spec.name}: {outcome.message}; {outcome.calls} calls, '
                               f'p50 {result.call_p50 * 1000:.2f} ms, p99 {result.call_p99 * 1000:.2f} ms')
        return result


def main(args=None) -> None:
    spin_node(ControllerNode, args)


if __name__ == '__main__':
    main()
