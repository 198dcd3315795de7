"""NavigationExecutor over a fake base port: goals by name and pose, refusals, recovery after a block, cancel."""
from __future__ import annotations

import math
import threading
from concurrent.futures import Future

import numpy as np
import pytest
from cap_mobile import layout

from cap_control.navigation.plan import NavigateErrorCode
from cap_control.navigation.executor import Base, NavigateRequest, NavigationConfig, NavigationExecutor
from cap_control.ports import ArmOutcome, ArmResult, Ending, Interruption, PendingGoal


def done(value=None) -> Future:
    future: Future = Future()
    future.set_result(value)
    return future


class Drive(PendingGoal):
    """A trajectory the fake base ends at once: at its last point, or blocked where it began."""

    def __init__(self, base: 'FakeBase', positions: np.ndarray, blocked: bool, hang: bool):
        self._accepted, self._result = done(True), Future()
        self.cancelled = False
        if hang:  # runs until cancelled
            return
        if blocked:
            self._result.set_result(ArmOutcome(ArmResult.TOLERANCE_VIOLATED, 'path tolerance exceeded'))
        else:
            base.position = positions[-1].copy()
            self._result.set_result(ArmOutcome(ArmResult.SUCCEEDED))

    @property
    def accepted(self) -> Future:
        return self._accepted

    @property
    def result(self) -> Future:
        return self._result

    def cancel(self) -> Future:
        self.cancelled = True
        if not self._result.done():
            self._result.set_result(ArmOutcome(ArmResult.FAILED, 'cancelled'))
        return done()


class FakeBase(Base):
    def __init__(self, blocked: int = 0, hang: bool = False):
        self.position = np.array(layout.START_POSE, dtype=float)
        self.blocked, self.hang = blocked, hang
        self.drives: list[tuple[np.ndarray, np.ndarray, Drive]] = []
        self.sent = threading.Event()

    def server_ready(self) -> Future:
        return done()

    def pose(self) -> Future:
        return done(self.position.copy())

    def latest_pose(self) -> np.ndarray | None:
        return self.position.copy()

    def follow(self, times, positions, velocities, path_tolerance) -> PendingGoal:
        drive = Drive(self, positions, blocked=len(self.drives) < self.blocked, hang=self.hang)
        self.drives.append((positions, velocities, drive))
        self.sent.set()
        return drive


def test_a_named_location_is_driven_to_its_approach_pose_in_one_continuous_trajectory():
    base = FakeBase()
    outcome = NavigationExecutor(base).run(NavigateRequest(location_name='The Desk'), Interruption())
    assert outcome.ending == Ending.SUCCEEDED, outcome.message
    assert outcome.code == NavigateErrorCode.NONE
    positions, velocities, _ = base.drives[0]
    goal = layout.location('desk').approach()
    assert positions[-1][:2] == pytest.approx(goal[:2], abs=0.05)
    assert math.cos(positions[-1][2] - goal[2]) > math.cos(0.05)
    steps = np.abs(np.diff(positions, axis=0)).max(axis=0)
    assert steps[2] < 0.2, 'the yaw never jumps (no wrap at pi)'
    assert np.linalg.norm(velocities[:, :2], axis=1).max() <= layout.BASE_MAX_SPEED + 1e-9
    assert np.abs(velocities[-1]).max() == 0.0


def test_unknown_locations_and_goals_in_furniture_are_refused_before_anything_moves():
    base = FakeBase()
    executor = NavigationExecutor(base)
    outcome = executor.run(NavigateRequest(location_name='the garage'), Interruption())
    assert outcome.code == NavigateErrorCode.UNKNOWN_LOCATION and 'countertop' in outcome.message
    outcome = executor.run(NavigateRequest(pose=(*layout.location('table').centre, 0.0)), Interruption())
    assert outcome.code == NavigateErrorCode.UNREACHABLE
    outcome = executor.run(NavigateRequest(pose=(math.nan, 0.0, 0.0)), Interruption())
    assert outcome.code == NavigateErrorCode.UNREACHABLE
    assert base.drives == []


def test_a_blocked_base_plans_again_around_the_spot_and_counts_the_recovery():
    base = FakeBase(blocked=1)
    progress = []
    outcome = NavigationExecutor(base).run(NavigateRequest(pose=(2.5, -1.0, 0.0)), Interruption(), progress.append)
    assert outcome.ending == Ending.SUCCEEDED, outcome.message
    assert outcome.recoveries == 1 and len(base.drives) == 2
    first, second = base.drives[0][0], base.drives[1][0]
    # The second plan keeps away from the spot ahead of where the base was blocked (its start, facing +x).
    radius = NavigationConfig().blocked_radius
    ahead = np.array([layout.BASE_RADIUS + radius, 0.0])
    assert np.linalg.norm(first[:, :2] - ahead, axis=1).min() < radius, 'the first plan went through the spot'
    assert np.linalg.norm(second[:, :2] - ahead, axis=1).min() > radius


def test_a_base_blocked_every_time_gives_up_as_unreachable():
    base = FakeBase(blocked=100)
    outcome = NavigationExecutor(base, NavigationConfig(max_recoveries=2)).run(
        NavigateRequest(location_name='countertop'), Interruption())
    assert outcome.code == NavigateErrorCode.UNREACHABLE and 'blocked 3 times' in outcome.message
    assert len(base.drives) == 3


@pytest.mark.parametrize('how', ['cancel', 'stop'])
def test_a_cancel_or_a_stop_cancels_the_drive(how):
    base = FakeBase(hang=True)
    interruption = Interruption()
    outcomes = []
    runner = threading.Thread(target=lambda: outcomes.append(NavigationExecutor(
        base, NavigationConfig(feedback_period=0.01)).run(NavigateRequest(location_name='table'), interruption)))
    runner.start()
    assert base.sent.wait(5.0)
    getattr(interruption, how)()
    runner.join(5.0)
    outcome = outcomes[0]
    assert outcome.code == NavigateErrorCode.CANCELLED
    assert outcome.ending == (Ending.CANCELLED if how == 'cancel' else Ending.STOPPED)
    assert base.drives[0][2].cancelled and outcome.halt_confirmed
