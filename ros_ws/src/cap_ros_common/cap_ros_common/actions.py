"""What every action server and client of the graph shares."""
from __future__ import annotations

import threading

from rclpy.action import ActionClient as _RclpyActionClient

# How long a server keeps a finished goal's result [s of the server's clock] for a client that asks for it late.
# Every goal kept is listed in each status message the server publishes, and every client of the action takes and
# deserializes those lists in Python. At rclpy's default (900 s) the simulator's trajectory and gripper servers
# (on the wall clock) kept thousands of goals in a long benchmark run, and each job slowed from 9x to 3x real time
# over its first 250 episodes. The graph's clients ask for the result as soon as a goal is accepted (the result
# then waits for them, however long the goal runs); 10 s still serves a client that asks a little late.
RESULT_TIMEOUT_S = 10


class ActionClient(_RclpyActionClient):
    """rclpy's ActionClient without its lost-answer race.

    rclpy 7.1 sends a goal (result, cancel) request first and only then records the future that waits for its
    answer. A server in the same process answers within microseconds; when another executor thread takes that answer
    in between, rclpy drops it ("Ignoring unexpected goal response. There may be more than one action server") and
    the goal's acceptance never arrives: a pick-and-place in a loaded test run ended with "no answer from the arm
    controller within 5 s". Here sending and recording happen under one lock, and taking answers waits for it.
    """

    def __init__(self, *args, **kwargs) -> None:
        self._request_lock = threading.Lock()
        super().__init__(*args, **kwargs)

    def send_goal_async(self, *args, **kwargs):
        with self._request_lock:
            return super().send_goal_async(*args, **kwargs)

    def _get_result_async(self, *args, **kwargs):
        with self._request_lock:
            return super()._get_result_async(*args, **kwargs)

    def _cancel_goal_async(self, *args, **kwargs):
        with self._request_lock:
            return super()._cancel_goal_async(*args, **kwargs)

    def take_data(self):
        with self._request_lock:
            return super().take_data()


__all__ = ['ActionClient', 'RESULT_TIMEOUT_S']
