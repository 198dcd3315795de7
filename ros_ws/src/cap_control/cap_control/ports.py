"""Ports to the arm, the gripper and perception, and the waits of one run over them (plain Python, no ROS).

The executors of cap_control (`<skill>.executor`: pick-and-place, path following, navigation, mobile
pick-and-place; the controller loop has ports of its own) talk to the robot through these small abstract classes:
the nodes implement them over their action clients, services and /joint_states (cap_control.skill_node), and unit
tests with fakes. `GoalRun` holds what every run does with them: wait for a future while a cancel or a stop may
come (every wait sleeps on one condition that a future completing, an interruption or a timeout wakes), send a
goal, and cancel the goal in flight when interrupted.

A goal counts as running from the moment it is sent, not only once the server accepts it: a cancel or stop while
the acceptance is awaited cancels it too (the port sends the cancel once the server has the goal), so a result that
says the arm stopped is true.
"""
from __future__ import annotations

import abc
import enum
import threading
import time
from concurrent.futures import Future
from dataclasses import dataclass
from typing import Any

from cap_control.pick_place.plan import ObjectInfo
from cap_control.trajectory import JointTrajectory


class ArmResult(enum.Enum):
    SUCCEEDED = 'succeeded'
    TOLERANCE_VIOLATED = 'tolerance violated'  # the arm strayed from the path, or ended short of its goal
    FAILED = 'failed'


@dataclass(frozen=True)
class ArmOutcome:
    result: ArmResult
    message: str = ''  # why, when not SUCCEEDED


@dataclass(frozen=True)
class GripperOutcome:
    width: float  # opening the fingers ended at [m]
    stalled: bool  # they stopped on something before the commanded opening


@dataclass(frozen=True)
class ObjectReport:
    """Perception's answer about one object."""

    success: bool
    message: str = ''
    info: ObjectInfo | None = None  # the object as the planner takes it
    position: tuple[float, float, float] | None = None  # where perception reports it
    visible: bool = False  # False: perception only remembers where it was last seen
    stamp: float = 0.0  # time of the observation answered from [s]; 0: the source has no time stamps


class PendingGoal(abc.ABC):
    """A goal sent to the arm or the gripper."""

    @property
    @abc.abstractmethod
    def accepted(self) -> Future:
        """Completes with True (accepted) or False (refused)."""

    @property
    @abc.abstractmethod
    def result(self) -> Future:
        """Completes with the outcome (ArmOutcome or GripperOutcome) once an accepted goal ends."""

    @abc.abstractmethod
    def cancel(self) -> Future:
        """Ask the server to cancel; completes once it has taken the cancel (it then holds where it is).

        May come before `accepted` completes: the cancel is then sent once the server has the goal (the future
        completes then), and a refused goal completes it at once (it never moved).
        """


class Arm(abc.ABC):
    server_description = 'the arm controller'  # named in "... is not available"
    joints_description = 'the arm joints'

    @abc.abstractmethod
    def server_ready(self) -> Future:
        """Completes once the trajectory server can take goals; cancelled when the executor stops waiting."""

    @abc.abstractmethod
    def joints(self) -> Future:
        """Completes with the arm's joint positions (np.ndarray) once they are known."""

    @abc.abstractmethod
    def opening(self) -> float | None:
        """The finger opening read from the joint state now [m], None if unknown."""

    @abc.abstractmethod
    def state_time(self) -> float | None:
        """Time stamp of the latest joint state [s], None if none came yet."""

    @abc.abstractmethod
    def follow(self, trajectory: JointTrajectory, contact_tolerance: float | None,
               goal_tolerance: float | None = None) -> PendingGoal:
        """Send a timed trajectory; with a contact tolerance [rad], a tracking error above it aborts the motion; a
        goal tolerance [rad] replaces the controller's default for the end of the motion."""


class Gripper(abc.ABC):
    server_description = 'the gripper'

    @abc.abstractmethod
    def server_ready(self) -> Future:
        """Completes once the gripper server can take goals; cancelled when the executor stops waiting."""

    @abc.abstractmethod
    def command(self, position: float, max_effort: float) -> PendingGoal:
        """Move the fingers to `position` [m] with at most `max_effort` [N] (0: the gripper's default)."""


class Perception(abc.ABC):
    service_description = 'the perception service'

    @abc.abstractmethod
    def state_service_ready(self) -> Future:
        """Completes once the object state service can be called; cancelled when the executor stops waiting."""

    @abc.abstractmethod
    def names_available(self) -> bool:
        """Whether the object names service can be called now (it is not waited for)."""

    @abc.abstractmethod
    def object_names(self, visible_only: bool = True) -> Future:
        """Completes with the names of the objects in view now (list[str]); with `visible_only` False, of every
        object perception knows of (also those it remembers out of view)."""

    @abc.abstractmethod
    def object_state(self, name: str) -> Future:
        """Completes with an ObjectReport."""


class Ending(enum.Enum):
    SUCCEEDED = 'succeeded'
    FAILED = 'failed'
    CANCELLED = 'cancelled'  # by a cancel request
    STOPPED = 'stopped'  # by a stop request


def interruption_message(ending: Ending, stop_source: str, halt_confirmed: bool, timeout: float,
                         part: str = 'the arm') -> str:
    """The message of a run ended by a cancel (`ending` CANCELLED) or by a stop from `stop_source`; `part` is what
    moved ("the arm", "the base")."""
    how = 'cancelled' if ending == Ending.CANCELLED else f'stopped by {stop_source}'
    if halt_confirmed:
        return f'{how}: {part} stopped where it was'
    return f'{how}, but the controller did not confirm the cancel of its goal within {timeout:.0f} s'


class Interruption:
    """Cancel and stop requests for one run, and the condition every wait of the run sleeps on."""

    def __init__(self) -> None:
        self.condition = threading.Condition()
        self.reason: Ending | None = None

    def cancel(self) -> None:
        self._set(Ending.CANCELLED)

    def stop(self) -> None:
        self._set(Ending.STOPPED)

    def _set(self, reason: Ending) -> None:
        with self.condition:
            if self.reason is None:
                self.reason = reason
            self.condition.notify_all()

    def notify(self, *_: Any) -> None:
        """Wake the waits (a future's done callback)."""
        with self.condition:
            self.condition.notify_all()


class Interrupted(Exception):
    """A run was cancelled or stopped (Interruption.reason says which)."""


class Failed(Exception):
    """A run failed with an executor's error code (an int enum) and a message a person understands."""

    def __init__(self, code: Any, message: str):
        super().__init__(message)
        self.code = code
        self.message = message


@dataclass(frozen=True)
class WaitTimeouts:
    """The waits of a run [s]: an answer (or a goal's acceptance), a server's appearance."""

    service_timeout: float
    server_timeout: float


class GoalRun:
    """The waits of one run over ports: answers, servers, pauses, goals; cancels and stops end them.

    `timeout_code` is the executor's error code for a wait that timed out, `refused_code` for a refused goal.
    """

    def __init__(self, interruption: 'Interruption', timeouts: WaitTimeouts, timeout_code: Any, refused_code: Any):
        self.interruption = interruption
        self.wait_timeouts = timeouts
        self.timeout_code, self.refused_code = timeout_code, refused_code
        self.active: PendingGoal | None = None  # the goal running now (cancelled on interrupt)

    def check_interrupted(self) -> None:
        if self.interruption.reason is not None:
            raise Interrupted()

    def wait(self, future: Future, timeout: float, failure: str) -> Any:
        """The future's result; raises Interrupted on cancel/stop and Failed(timeout_code, failure) after
        `timeout`."""
        condition = self.interruption.condition
        future.add_done_callback(self.interruption.notify)
        deadline = time.monotonic() + timeout
        with condition:
            while not future.done():
                self.check_interrupted()
                left = deadline - time.monotonic()
                if left <= 0:
                    raise Failed(self.timeout_code, failure)
                condition.wait(left)
        return future.result()

    def answer(self, future: Future, timeout: float, what: str) -> Any:
        return self.wait(future, timeout, f'no answer from {what} within {timeout:.0f} s')

    def available(self, future: Future, what: str) -> None:
        try:
            self.wait(future, self.wait_timeouts.server_timeout, f'{what} is not available')
        finally:
            future.cancel()  # no-op once done; otherwise tells the port to stop looking

    def pause(self, seconds: float) -> None:
        """Wait `seconds`, or less if interrupted (then raise)."""
        with self.interruption.condition:
            self.check_interrupted()
            self.interruption.condition.wait(seconds)
        self.check_interrupted()

    def send(self, goal: 'PendingGoal', what: str, refusal: str) -> None:
        """Count `goal` as running, then wait for its acceptance; Failed(refused_code, refusal) if refused."""
        # Active before the acceptance comes: an interruption or timeout while waiting for it cancels the goal too.
        self.active = goal
        if not self.answer(goal.accepted, self.wait_timeouts.service_timeout, what):
            self.active = None
            raise Failed(self.refused_code, refusal)

    def cancel_active_goal(self) -> bool:
        """Cancel the goal sent last, accepted or not yet; True once the server has taken the cancel (or none ran).

        The controller holds the arm (or the fingers) where they are; answer only once it has taken the cancel.
        """
        goal, self.active = self.active, None
        if goal is None:
            return True
        done = threading.Event()
        goal.cancel().add_done_callback(lambda _: done.set())
        return done.wait(self.wait_timeouts.service_timeout)


__all__ = ['Arm', 'ArmOutcome', 'ArmResult', 'Ending', 'Failed', 'GoalRun', 'Gripper', 'GripperOutcome',
           'Interrupted', 'Interruption', 'ObjectReport', 'PendingGoal', 'Perception', 'WaitTimeouts',
           'interruption_message']
