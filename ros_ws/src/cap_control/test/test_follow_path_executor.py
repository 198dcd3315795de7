"""The path executor over fake ports: what it sends, and how it ends on a lost contact, a stop, a refused path."""
import threading
import time
from concurrent.futures import Future

import numpy as np

from cap_control.follow_path.executor import MAX_GOAL_SAMPLES, PathExecutor, PathRequest, PathTimeouts, ToolSpring
from cap_control.follow_path.plan import PathErrorCode
from cap_control.ports import Arm, ArmOutcome, ArmResult, Ending, Interruption, PendingGoal

READY = np.array([0.8413, -2.2842, 1.7017, -0.9883, -1.5708, -0.7295])
LINE = [np.array([[-0.1, -0.5], [0.1, -0.5]])]


def done(value=None) -> Future:
    future: Future = Future()
    future.set_result(value)
    return future


class Goal(PendingGoal):
    def __init__(self, duration: float, arm: 'FakeArm'):
        self._result: Future = Future()
        self.cancelled = False
        # The motion "runs" for a moment of wall time; simulated time advances with it.
        self._timer = threading.Timer(0.05, self._finish)
        self._timer.start()
        self.arm, self.duration = arm, duration

    def _finish(self):
        self.arm.now += self.duration
        if not self._result.done():
            self._result.set_result(ArmOutcome(ArmResult.SUCCEEDED))

    @property
    def accepted(self) -> Future:
        return done(True)

    @property
    def result(self) -> Future:
        return self._result

    def cancel(self) -> Future:
        self.cancelled = True
        self._timer.cancel()
        if not self._result.done():
            self._result.set_result(ArmOutcome(ArmResult.FAILED, 'cancelled'))
        return done()


class FakeArm(Arm, ToolSpring):
    """An arm whose motions end after 50 ms, and a spring compressed as the test says (advancing time)."""

    def __init__(self, compression: float = 0.003):
        self.goals: list[tuple[Goal, float | None]] = []
        self.trajectories = []
        self.compressed = compression
        self.now = 0.0

    def server_ready(self) -> Future:
        return done()

    def joints(self) -> Future:
        return done(READY.copy())

    def opening(self):
        return 0.016

    def state_time(self):
        self.now += 0.01
        return self.now

    def follow(self, trajectory, contact_tolerance, goal_tolerance=None) -> PendingGoal:
        goal = Goal(trajectory.duration, self)
        self.goals.append((goal, goal_tolerance))
        self.trajectories.append(trajectory)
        return goal

    def compression(self, tool):
        return self.compressed


def test_a_line_is_travelled_to_drawn_lifted_and_parked_with_feedback():
    arm = FakeArm()
    progress = []
    outcome = PathExecutor(arm, arm).run(PathRequest(LINE, 'marker'), Interruption(), progress.append)
    assert outcome.ending == Ending.SUCCEEDED, outcome.message
    assert outcome.points_done == 2 and outcome.fraction == 1.0
    assert [g[1] is not None for g in arm.goals] == [False, True, True, False, False]  # pressing: descend, follow
    stages = [p.stage for p in progress]
    assert stages[:5] == ['travel', 'descend', 'follow', 'follow', 'follow'] or 'follow' in stages
    assert stages[-1] == 'done' and progress[-1].progress == 1.0


def test_a_tool_that_lifts_off_fails_the_stroke_and_halts_the_arm():
    arm = FakeArm(compression=0.003)
    executor = PathExecutor(arm, arm, timeouts=PathTimeouts(landing_time=0.05))

    def lift_off():  # once the stroke has started, the spring relaxes
        while len(arm.goals) < 3:
            threading.Event().wait(0.001)
        arm.compressed = 0.0
    threading.Thread(target=lift_off, daemon=True).start()
    outcome = executor.run(PathRequest(LINE, 'marker'), Interruption())
    assert outcome.ending == Ending.FAILED and outcome.code == PathErrorCode.CONTACT_LOST
    assert 'lifted off the board' in outcome.message
    assert arm.goals[2][0].cancelled or len(arm.goals) == 3


def test_a_tool_that_never_lands_is_reported():
    arm = FakeArm(compression=0.0)
    outcome = PathExecutor(arm, arm, timeouts=PathTimeouts(landing_time=0.05)).run(
        PathRequest(LINE, 'eraser'), Interruption())
    assert outcome.code == PathErrorCode.CONTACT_LOST and 'did not land' in outcome.message
    assert len(arm.goals) == 2  # travel, descend: nothing followed


def test_a_path_off_the_board_sends_nothing():
    arm = FakeArm()
    outcome = PathExecutor(arm, arm).run(PathRequest([np.array([[0.0, -0.5], [0.5, -0.5]])], 'marker'),
                                         Interruption())
    assert outcome.code == PathErrorCode.OUTSIDE_WORKSPACE and arm.goals == []


def test_a_stop_cancels_the_motion_in_progress():
    arm = FakeArm()
    interruption = Interruption()

    def stop_in_stroke():
        while len(arm.goals) < 3:
            threading.Event().wait(0.001)
        interruption.stop()
    threading.Thread(target=stop_in_stroke, daemon=True).start()
    outcome = PathExecutor(arm, arm, stop_source='cap/stop').run(PathRequest(LINE, 'marker'), interruption)
    assert outcome.ending == Ending.STOPPED and outcome.code == PathErrorCode.CANCELLED
    assert 'stopped by cap/stop' in outcome.message
    assert len(arm.goals) <= 4


def _scribble(count: int) -> list[np.ndarray]:
    """`count` points all over the board: thousands of corners, hours of drawing."""
    rng = np.random.default_rng(0)
    return [np.column_stack([rng.uniform(-0.23, 0.23, count), rng.uniform(-0.68, -0.32, count)])]


def test_a_stop_while_planning_ends_the_run_at_once_with_nothing_sent():
    arm = FakeArm()
    interruption = Interruption()
    threading.Timer(0.05, interruption.stop).start()
    started = time.monotonic()
    outcome = PathExecutor(arm, arm, stop_source='cap/stop').run(PathRequest(_scribble(5000), 'marker'), interruption)
    assert outcome.ending == Ending.STOPPED and outcome.code == PathErrorCode.CANCELLED
    assert time.monotonic() - started < 0.5
    assert arm.goals == []



def test_a_long_stroke_goes_to_the_arm_a_part_at_a_time_each_from_rest_to_rest():
    arm = FakeArm()
    zigzag = [np.array([[-0.2 + 0.4 * (i % 2), -0.6 + 0.002 * i] for i in range(60)])]
    outcome = PathExecutor(arm, arm).run(PathRequest(zigzag, 'marker'), Interruption())
    assert outcome.ending == Ending.SUCCEEDED, outcome.message
    follows = arm.trajectories[2:-2]  # after the travel and the landing; before the lift and the park
    assert len(follows) > 1 and max(len(t) for t in follows) <= MAX_GOAL_SAMPLES
    assert all(not np.any(t.velocities[[0, -1]]) for t in follows)
    assert sum(t.duration for t in follows) > 60 * 0.4 / 0.1  # the whole stroke: 59 strokes of 40 cm at 0.1 m/s
