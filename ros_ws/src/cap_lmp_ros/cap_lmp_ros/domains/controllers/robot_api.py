"""The reactive-controller domain's robot functions, bound to the graph: controller_node's RunController action and
GetPlantState service, /cap/say, and the CallController service through which controller_node calls the program's
controller function.

`start_controller(function, plant, rate, duration, time_budget)` receives the program's function as a handle
(cap_lmp.isolated_engine.CallableHandle: the function stays in the sandbox process), sends the RunController goal
and waits for its result; meanwhile controller_node asks this node's CallController service once per tick, which
calls the function through the engine's `invoke` (in the sandbox process, under the sandbox's rules, with the tick's
time budget). Only the function of the run in progress can be called. Requests are sent asynchronously and awaited
on events, never by spinning (the program's thread waits while an executor spins the node in another).
"""
from __future__ import annotations

import math
import threading
import time
from typing import Any, Callable

import numpy as np
from cap_ros_common.actions import ActionClient
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from std_msgs.msg import String

from cap_controllers import plants
from cap_interfaces.action import RunController
from cap_interfaces.msg import GraphNames
from cap_interfaces.srv import CallController, GetPlantState
from cap_lmp.errors import RobotApiError, StoppedError
from cap_lmp.isolated_engine import CallableHandle, InvokeError
from cap_lmp.safe_text import wire_text

MAX_SAY_CHARS = 2000
SAFE = {'cartpole': "the cart's motor was switched off", 'arm': 'the arm holds where it stopped'}


class RosControllersApi:
    """start_controller, read_plant_state and say over ROS; the CallController service for controller_node."""

    def __init__(self, node: Node, say_publisher, service_timeout_s: float = 5.0,
                 motion_timeout_s: float = 180.0) -> None:
        self._node = node
        self._say_publisher = say_publisher
        self.service_timeout_s = service_timeout_s
        self.motion_timeout_s = motion_timeout_s
        self.stop_requested = threading.Event()
        self._engine: Any = None
        self._running: tuple[int, str] | None = None  # (handle id, plant) of the controller run in progress
        self._goal = None
        self._lock = threading.Lock()
        self._client_node = node
        self._create_clients(node)

    # -------------------------------------------------------------------------------------------- binding
    def _create_clients(self, node: Node) -> None:
        group = ReentrantCallbackGroup()
        self._run = ActionClient(node, RunController, GraphNames.RUN_CONTROLLER_ACTION, callback_group=group)
        self._state = node.create_client(GetPlantState, GraphNames.PLANT_STATE_SERVICE, callback_group=group)
        self._service = node.create_service(CallController, GraphNames.CONTROLLER_CALL_SERVICE, self._on_call,
                                            callback_group=group)

    def bind_clients(self, node: Node) -> None:
        """Move the clients and the CallController service onto `node` (before the first program): the per-tick
        calls then run on the graph's fast executor."""
        old_node, old = self._client_node, (self._run, self._state, self._service)
        self._create_clients(node)
        self._client_node = node
        old[0].destroy()
        old_node.destroy_client(old[1])
        old_node.destroy_service(old[2])

    def bind_engine(self, engine: Any) -> None:
        """The engine whose program passes the controller functions (lmp_node calls this once it has one)."""
        self._engine = engine

    def functions(self) -> dict[str, Callable[..., Any]]:
        return {'start_controller': self.start_controller, 'read_plant_state': self.read_plant_state,
                'say': self.say}

    def stop(self) -> None:
        """Stop waiting and cancel the controller run in progress (thread-safe)."""
        self.stop_requested.set()
        with self._lock:
            goal = self._goal
        if goal is not None:
            goal.cancel_goal_async()

    # -------------------------------------------------------------------------------------------- robot functions
    def say(self, text: Any) -> None:
        """Say something to the user (published on /cap/say)."""
        message = wire_text(text if isinstance(text, str) else repr(text)[:MAX_SAY_CHARS], MAX_SAY_CHARS)
        self._say_publisher.publish(String(data=message))

    def read_plant_state(self, plant: str) -> np.ndarray:
        """The plant's state vector now (cap_controllers.plants layout), from controller_node."""
        if not isinstance(plant, str) or plant not in plants.PLANTS:
            raise RobotApiError(f'unknown plant {plant!r}; the plants are: {", ".join(sorted(plants.PLANTS))}')
        if not self._state.wait_for_service(timeout_sec=self.service_timeout_s):
            raise RobotApiError(f'the controller node ({self._state.srv_name}) is not running')
        response = self._wait(self._state.call_async(GetPlantState.Request(plant=plant)), self.service_timeout_s,
                              'the controller node')
        if not response.success:
            raise RobotApiError(response.message)
        return np.asarray(response.state, dtype=float)

    def start_controller(self, function: Any, plant: str, rate: float, duration: float,
                         time_budget: float) -> dict[str, float]:
        """Run the program's `function` as the plant's controller; a summary of the run, or RobotApiError saying
        why it was stopped (and that the plant was made safe)."""
        if not isinstance(function, CallableHandle) or self._engine is None or not hasattr(self._engine, 'invoke'):
            raise RobotApiError('controllers run only with the session in its sandbox process (lmp_node parameter '
                                'sandbox_process: true)')
        numbers = (rate, duration, time_budget)
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in numbers):
            raise RobotApiError('rate, duration and time_budget must be numbers')
        goal = RunController.Goal(controller=f'{function.name}()', handle=function.id, plant=str(plant),
                                  rate=float(rate), duration=float(duration), time_budget=float(time_budget))
        if not self._run.wait_for_server(timeout_sec=self.service_timeout_s):
            raise RobotApiError(f'the controller node ({self._run._action_name}) is not running')
        with self._lock:
            self._running = (function.id, goal.plant)
        try:
            handle = self._wait(self._run.send_goal_async(goal), self.service_timeout_s, 'the controller node')
            if not handle.accepted:
                raise RobotApiError('the controller node refused to run the controller')
            with self._lock:
                self._goal = handle
            if self.stop_requested.is_set():
                handle.cancel_goal_async()
            # Simulated time may run slower than the wall clock (real time, a loaded machine): room for both.
            wrapped = self._wait(handle.get_result_async(), self.motion_timeout_s + 2.0 * duration,
                                 'the controller run', cancel=handle.cancel_goal_async)
        finally:
            with self._lock:
                self._running, self._goal = None, None
        result = wrapped.result
        where = f'; {SAFE.get(goal.plant, "the plant was made safe")}'
        if result.error_code == RunController.Result.STOPPED or self.stop_requested.is_set():
            raise StoppedError(f'{function.name}() was stopped: {result.error_msg}{where}')
        if result.error_code != RunController.Result.SUCCESSFUL:
            raise RobotApiError(f'{result.error_msg}{where}')
        return {'simulated_time': result.simulated_time, 'calls': int(result.calls),
                'saturated_calls': int(result.saturated_calls), 'call_p50_ms': result.call_p50 * 1000,
                'call_p99_ms': result.call_p99 * 1000}

    # -------------------------------------------------------------------------------------------- per tick
    def _on_call(self, request: CallController.Request, response: CallController.Response):
        """controller_node's call of the running program's controller function, one tick."""
        with self._lock:
            running = self._running
        if running is None or running != (request.handle, request.plant):
            response.success, response.error_type = False, 'NotRunning'
            response.error = 'no program is running a controller with that handle'
            return response
        budget = request.time_budget if request.time_budget > 0 else plants.default_budget(plants.DEFAULT_RATE)
        try:
            # Wait a little past the budget for the answer: the budget is the function's CPU time, the rest is the
            # channel's (controller_node bounds the whole round trip itself).
            value, seconds = self._engine.invoke(CallableHandle(request.handle, ''), [list(request.state)],
                                                 budget_s=budget, timeout_s=budget + 0.2)
        except InvokeError as error:
            response.success, response.error_type, response.error = False, error.kind, str(error)
            return response
        try:
            response.output = [float(v) for v in value]
        except (TypeError, ValueError):
            response.success, response.error_type = False, 'TypeError'
            response.error = f'the controller returned {type(value).__name__}, not numbers'
            return response
        response.success, response.seconds = True, seconds
        return response

    # -------------------------------------------------------------------------------------------- plumbing
    def _wait(self, future, timeout_s: float, what: str, cancel: Callable[[], Any] | None = None):
        """Wait for a future that the node's executor completes in another thread; honour stop requests."""
        done = threading.Event()
        future.add_done_callback(lambda _: done.set())
        deadline = time.monotonic() + timeout_s
        cancelled = False
        while not done.wait(0.01) and not future.done():  # done() too: see cap_control.controller.node._wait
            if self.stop_requested.is_set() and not cancelled:
                if cancel is None:
                    future.cancel()
                    raise StoppedError(f'stopped while waiting for {what}')
                cancel()  # keep waiting for the cancelled result: the run reports where it stopped
                cancelled = True
                deadline = time.monotonic() + self.service_timeout_s
            if time.monotonic() > deadline:
                if cancel is not None:
                    cancel()
                raise RobotApiError(f'{what} did not answer within {timeout_s:.0f} s')
        if future.exception() is not None:
            raise RobotApiError(f'{what} failed: {future.exception()}')
        return future.result()
