"""What the domains' robot APIs share over ROS: perception's object names and positions, `say`, and the plumbing
of calls and goals from the thread that runs a program.

Called from the worker thread that runs a program while an executor spins the node in another thread; requests are
sent asynchronously and awaited on threading events, never by spinning (a blocking call on a node that an executor
already spins would deadlock). Every failure raises RobotApiError with a message a person understands; a stop
raises StoppedError. Text a program passes on (what it says, object names) is made safe first
(safe_text.wire_text): a string rclpy cannot encode would fail the publish. A domain's binding subclasses
`RosRobotApi`, creates its action clients in `_create_clients` and sends goals with `_run_goal`.
"""
from __future__ import annotations

import reprlib
import threading
import time
from typing import Any, Callable

import numpy as np
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from std_msgs.msg import String

from cap_interfaces.msg import GraphNames
from cap_interfaces.srv import GetObjectNames, GetObjectState
from cap_lmp.errors import RobotApiError, StoppedError
from cap_lmp.safe_text import wire_text
from cap_lmp_ros.domains.object_names import object_name_candidate


MAX_SAY_CHARS = 2000
MAX_NAME_CHARS = 200  # of an object name sent to perception or the controller
_BOUNDED_REPR = reprlib.Repr()  # Python 3.11: limits are attributes, not constructor arguments
_BOUNDED_REPR.maxlevel, _BOUNDED_REPR.maxlist, _BOUNDED_REPR.maxtuple, _BOUNDED_REPR.maxdict = 3, 10, 10, 10
_BOUNDED_REPR.maxstring, _BOUNDED_REPR.maxother = 500, 200


class RosRobotApi:
    """get_obj_names, get_obj_pos and say over ROS, and the plumbing a domain's motions use."""

    where = 'on the table'  # where the objects are, in messages ("there is no ... on the table")

    def __init__(self, node: Node, say_publisher, service_timeout_s: float = 5.0,
                 motion_timeout_s: float = 180.0) -> None:
        self._node = node
        self._say_publisher = say_publisher
        self.service_timeout_s = service_timeout_s
        self.motion_timeout_s = motion_timeout_s
        self._client_node = node
        self._create_clients(node)
        self._ready: set[str] = set()  # services seen running: later calls skip the wait for them
        self.stop_requested = threading.Event()
        self._active_goal = None
        self._goal_lock = threading.Lock()
        self.said: list[str] = []
        self._known_names: set[str] = set()  # names perception has listed: passed on without asking again
        self.api_calls = 0
        self.api_call_seconds: list[float] = []

    # -------------------------------------------------------------------------------------------- binding
    def _create_clients(self, node: Node) -> None:
        """Create the service and action clients on `node` (a subclass adds its actions' clients)."""
        group = ReentrantCallbackGroup()
        self._names = node.create_client(GetObjectNames, GraphNames.PERCEPTION_OBJECT_NAMES_SERVICE,
                                         callback_group=group)
        self._state = node.create_client(GetObjectState, GraphNames.PERCEPTION_OBJECT_STATE_SERVICE,
                                         callback_group=group)

    def _clients(self) -> list[Any]:
        """Every client `_create_clients` made (a subclass adds its own)."""
        return [self._names, self._state]

    def bind_clients(self, node: Node) -> None:
        """Move the service and action clients onto `node` (call before the first program runs).

        A graph that spins a small client node on a fast executor of its own makes each call's round trip
        independent of the executor that runs the long, blocking callbacks of the node given to the constructor.
        """
        old_node, old = self._client_node, self._clients()
        self._create_clients(node)
        self._client_node = node
        self._ready.clear()
        for client in old:
            if hasattr(client, 'srv_name'):
                old_node.destroy_client(client)
            else:  # an action client
                client.destroy()

    def functions(self) -> dict[str, Callable[..., Any]]:
        """The names generated code sees."""
        return {'get_obj_names': self.get_obj_names, 'get_obj_pos': self.get_obj_pos, 'say': self.say}

    def stop(self) -> None:
        """Stop waiting for the robot and cancel the motion in progress (thread-safe)."""
        self.stop_requested.set()
        with self._goal_lock:
            goal = self._active_goal
        if goal is not None:
            goal.cancel_goal_async()

    # -------------------------------------------------------------------------------------------- perception
    def get_obj_names(self) -> list[str]:
        """Names of the objects perception knows, e.g. ['blue block', 'red bowl']."""
        return list(self._call(self._names, GetObjectNames.Request(), 'the perception service').names)

    def _name(self, name: Any) -> str:
        """The scene's name for what the program passed ("the red block", ['red block'] -> 'red block'), or an error
        naming the objects there are."""
        if isinstance(name, str) and len(name) <= MAX_NAME_CHARS and name in self._known_names:
            return name
        candidate = object_name_candidate(name)
        if candidate is None:
            raise RobotApiError(f'an object name must be text like "red block", not {type(name).__name__}'
                                + (f' of {len(name)} items' if isinstance(name, (list, tuple)) else ''))
        names = self.get_obj_names()
        self._known_names = set(names)
        if candidate in self._known_names:
            return candidate
        # Made sendable first (a lone surrogate becomes U+FFFD), then quoted.
        shown = repr(wire_text(name, MAX_NAME_CHARS)) if isinstance(name, str) else \
            wire_text(repr(name), MAX_NAME_CHARS)
        raise RobotApiError(f'there is no {shown} {self.where}; the objects are: {", ".join(names) or "none"}')

    def _object(self, name: Any):
        name = self._name(name)
        response = self._call(self._state, GetObjectState.Request(name=wire_text(name, MAX_NAME_CHARS)),
                              'the perception service')
        if not response.success:
            raise RobotApiError(response.message or f'unknown object {name!r}')
        return response.state

    def object_states(self) -> list[Any]:
        """Every object perception knows, as ObjectState messages (what a twin of the scene is built from)."""
        states = []
        for name in self.get_obj_names():
            response = self._call(self._state, GetObjectState.Request(name=wire_text(name, MAX_NAME_CHARS)),
                                  'the perception service')
            if response.success:
                states.append(response.state)
        return states

    def get_obj_pos(self, name: str) -> np.ndarray:
        """Centre of the object on the table, np.array([x, y]) in metres."""
        state = self._object(name)
        return np.array([state.position.x, state.position.y])

    # -------------------------------------------------------------------------------------------- motion
    def _run_goal(self, client, goal, what: str, refusal: str, timeout_s: float | None = None):
        """Send `goal` to the action `client` and return its result (a stop cancels the motion, and its cancelled
        result is awaited); RobotApiError if the server is missing, refuses the goal or does not answer within
        `timeout_s` (default: motion_timeout_s)."""
        if not client.wait_for_server(timeout_sec=self.service_timeout_s):
            name = self._client_node.resolve_topic_name(client._action_name)  # rclpy keeps it only there
            raise RobotApiError(f'{what} ({name}) is not running')
        started = time.monotonic()
        goal_handle = self._wait(client.send_goal_async(goal), self.service_timeout_s, what)
        if not goal_handle.accepted:
            raise RobotApiError(refusal)
        with self._goal_lock:
            self._active_goal = goal_handle
        try:
            if self.stop_requested.is_set():  # stopped between sending and acceptance
                goal_handle.cancel_goal_async()
            return self._wait(goal_handle.get_result_async(), timeout_s or self.motion_timeout_s, what,
                              cancel=goal_handle.cancel_goal_async).result
        finally:
            with self._goal_lock:
                self._active_goal = None
            self._record(started)

    def say(self, text: Any) -> None:
        """Say something to the user (published on /cap/say)."""
        # A program may pass anything: bound the conversion so a huge structure cannot stall the node.
        if isinstance(text, str):
            message = text
        elif isinstance(text, (bool, float, np.generic)) or (isinstance(text, np.ndarray) and text.size <= 100):
            message = str(text)
        else:  # also int: str() of a 10**5-digit integer is slow (and refused by Python past 4300 digits)
            message = _BOUNDED_REPR.repr(text)
        message = wire_text(message, MAX_SAY_CHARS)
        self.said.append(message)
        self._say_publisher.publish(String(data=message))

    # -------------------------------------------------------------------------------------------- plumbing
    def _call(self, client, request, what: str):
        started = time.monotonic()
        # Discovery is checked until the service is first seen, then only when a call fails (to name the cause).
        if client.srv_name not in self._ready:
            if not client.wait_for_service(timeout_sec=self.service_timeout_s):
                raise RobotApiError(f'{what} ({client.srv_name}) is not running')
            self._ready.add(client.srv_name)
        try:
            return self._wait(client.call_async(request), self.service_timeout_s, what)
        except StoppedError:
            raise
        except RobotApiError:
            if not client.service_is_ready():
                self._ready.discard(client.srv_name)
                raise RobotApiError(f'{what} ({client.srv_name}) is not running') from None
            raise
        finally:
            self._record(started)

    def _record(self, started: float) -> None:
        self.api_calls += 1
        self.api_call_seconds.append(time.monotonic() - started)
        del self.api_call_seconds[:-10000]

    def _wait(self, future, timeout_s: float, what: str, cancel: Callable[[], Any] | None = None):
        return wait_for_future(future, timeout_s, what, self.stop_requested, self.service_timeout_s, cancel)


def wait_for_future(future, timeout_s: float, what: str, stop_requested: threading.Event, cancel_timeout_s: float,
                    cancel: Callable[[], Any] | None = None):
    """The result of a future that the node's executor completes in another thread, waited for on an event (never by
    spinning); RobotApiError when it fails or does not come within `timeout_s`. When `stop_requested` is set, a
    future with no `cancel` is dropped (StoppedError); with one, the goal is cancelled and its result still awaited
    for `cancel_timeout_s`, so that the motion reports where it stopped."""
    done = threading.Event()
    future.add_done_callback(lambda _: done.set())
    deadline = time.monotonic() + timeout_s
    cancelled = False
    # done() too: a future already done when the callback is added hands the callback to its executor as a task,
    # which an idle events executor may not run for a long time.
    while not done.wait(0.01) and not future.done():
        if stop_requested.is_set() and not cancelled:
            if cancel is None:
                future.cancel()
                raise StoppedError(f'stopped while waiting for {what}')
            cancel()
            cancelled = True
            deadline = time.monotonic() + cancel_timeout_s
        if time.monotonic() > deadline:
            if cancel is not None:
                cancel()
            if cancelled:  # the wait after the cancel is the one that ran out
                raise RobotApiError(f'{what} did not answer within {cancel_timeout_s:g} s of the cancel')
            raise RobotApiError(f'{what} did not answer within {timeout_s:.0f} s')
    if future.exception() is not None:
        raise RobotApiError(f'{what} failed: {future.exception()}')
    return future.result()

__all__ = ['MAX_NAME_CHARS', 'MAX_SAY_CHARS', 'RosRobotApi', 'wait_for_future']
