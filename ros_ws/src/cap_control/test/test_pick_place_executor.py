"""The pick-and-place executor over fakes of its ports: results, messages and the motions that reach the arm."""
from __future__ import annotations

import dataclasses
import math
import threading
from concurrent.futures import Future

import numpy as np
import pytest

from cap_control.kinematics import HOME_JOINTS, forward_kinematics
from cap_control.pick_place.plan import ObjectInfo, PickPlaceConfig, PickPlaceErrorCode, StageName
from cap_control.pick_place.executor import ExecutionConfig, PickPlaceExecutor, PickPlaceRequest
from cap_control.ports import (
    Arm, ArmOutcome, ArmResult, Ending, Gripper, GripperOutcome, Interruption, ObjectReport, PendingGoal, Perception,
)

BLOCK = (0.04, 0.04, 0.04)
# Short waits: a fake that never answers should end the run soon.
TIMEOUTS = ExecutionConfig(service_timeout=0.05, server_timeout=0.05, motion_timeout_margin=5.0,
                           gripper_timeout=5.0, view_timeout=0.05)


def done(value=None) -> Future:
    future: Future = Future()
    future.set_result(value)
    return future


class FakeGoal(PendingGoal):
    def __init__(self, outcome=None):
        self._accepted, self._result = done(True), Future()
        self.cancelled = threading.Event()
        if outcome is not None:
            self._result.set_result(outcome)

    @property
    def accepted(self) -> Future:
        return self._accepted

    @property
    def result(self) -> Future:
        return self._result

    def cancel(self) -> Future:
        self.cancelled.set()
        return done()


class SlowlyAcceptedGoal(FakeGoal):
    """A goal whose acceptance comes only when `answer(accepted)` is called. A cancel asked for before that is
    taken once the goal is accepted (its future completes then), and at once if the goal is refused, as the
    PendingGoal contract says."""

    def __init__(self):
        super().__init__()
        self._accepted = Future()
        self.cancel_asked = threading.Event()

    def answer(self, accepted: bool) -> None:
        self._accepted.set_result(accepted)

    def cancel(self) -> Future:
        self.cancel_asked.set()
        taken: Future = Future()

        def on_answer(accepted: Future) -> None:
            if accepted.result():
                self.cancelled.set()
            taken.set_result(None)

        self._accepted.add_done_callback(on_answer)
        return taken


class FakeWorld(Arm, Gripper, Perception):
    """Arm, gripper and perception of a table with objects: a closed gripper over a block holds it, and opening
    it sets the block down under the tool. `contact_at_place` makes the place descent stop on contact half way;
    `hang_in` names a stage whose motion never ends, `slow_accept_in` one whose goal waits for its acceptance;
    `drop_to` is where a released block ends instead."""

    def __init__(self, objects: list[ObjectInfo], stages: list[StageName]):
        self.objects = {o.name: o for o in objects}
        self.stages = stages  # the feedback so far
        self.q = np.array(HOME_JOINTS, dtype=float)
        self.opening_now = 0.085
        self.held: str | None = None
        self.trajectories: list[tuple[StageName, object, float | None]] = []
        self.gripper_commands: list[tuple[float, float]] = []
        self.goals: list[FakeGoal] = []
        self.contact_at_place = False
        self.hang_in: StageName | None = None
        self.slow_accept_in: StageName | None = None
        self.moving = threading.Event()
        self.drop_to: tuple[float, float, float] | None = None
        self.missing_object = False  # nothing between the fingers when they close
        self.misses_left = 0  # grasps that close on nothing before one finds the object
        self.perception_answers = True
        self.hidden_from = None  # joint positions from which the camera sees placed objects again; None: always seen

    # arm
    def server_ready(self) -> Future:
        return done()

    def joints(self) -> Future:
        return done(self.q.copy())

    def opening(self) -> float | None:
        return self.opening_now

    def state_time(self) -> float | None:
        return 0.0

    def follow(self, trajectory, contact_tolerance) -> PendingGoal:
        stage = self.stages[-1]
        self.trajectories.append((stage, trajectory, contact_tolerance))
        if stage in (self.hang_in, self.slow_accept_in):
            goal = FakeGoal() if stage == self.hang_in else SlowlyAcceptedGoal()
            self.goals.append(goal)
            self.moving.set()
            return goal
        if contact_tolerance is not None and self.contact_at_place:
            self.q = trajectory.positions[len(trajectory) // 2].copy()
            return FakeGoal(ArmOutcome(ArmResult.TOLERANCE_VIOLATED, 'path tolerance violated'))
        self.q = trajectory.end.copy()
        return FakeGoal(ArmOutcome(ArmResult.SUCCEEDED))

    # gripper
    def command(self, position: float, max_effort: float) -> PendingGoal:
        self.gripper_commands.append((position, max_effort))
        tcp = forward_kinematics(self.q)[:3, 3]
        if max_effort > 0:  # closing on an object (a grasp is the only command with a grip force)
            under = [o for o in self.objects.values() if o.category == 'block'
                     and math.dist(o.position[:2], tcp[:2]) < 0.01] if not self.missing_object else []
            if self.misses_left > 0:  # this grasp closes on nothing (the object was not where it was seen)
                self.misses_left -= 1
                under = []
            if under:
                self.held = under[0].name
                self.opening_now = under[0].size[1]
                return FakeGoal(GripperOutcome(self.opening_now, True))
            self.opening_now = position
            return FakeGoal(GripperOutcome(position, False))
        if self.held is not None:
            held = self.objects[self.held]
            where = self.drop_to or (float(tcp[0]), float(tcp[1]), 0.03)
            self.objects[self.held] = ObjectInfo(held.name, where, held.size, held.category, held.yaw)
            self.held = None
        self.opening_now = position
        return FakeGoal(GripperOutcome(position, False))

    # perception
    def state_service_ready(self) -> Future:
        return done()

    def names_available(self) -> bool:
        return True

    def object_names(self, visible_only: bool = True) -> Future:
        return done(list(self.objects)) if self.perception_answers else Future()

    def object_state(self, name: str) -> Future:
        if not self.perception_answers:
            return Future()
        obj = self.objects.get(name)
        if obj is None:
            return done(ObjectReport(False, f'no object named {name!r}'))
        if self.hidden_from is not None:  # a camera with time stamps, and an arm that may hang over the object
            retreating = bool(self.stages) and self.stages[-1] == StageName.RETREAT
            visible = bool(np.allclose(self.q, self.hidden_from, atol=1e-3)) or not retreating
            return done(ObjectReport(True, '', obj, obj.position, visible, stamp=1.0))
        return done(ObjectReport(True, '', obj, obj.position, True))

    def stage_motions(self) -> list[StageName]:
        return [stage for stage, _, _ in self.trajectories]


@pytest.fixture
def table():
    stages: list[StageName] = []
    world = FakeWorld([ObjectInfo('red block', (0.1, -0.5, 0.02), BLOCK),
                       ObjectInfo('blue bowl', (-0.1, -0.6, 0.03), (0.14, 0.14, 0.06), 'bowl')], stages)
    executor = PickPlaceExecutor(world, world, world, PickPlaceConfig(), TIMEOUTS, stop_source='/cap/stop')
    return world, executor, stages


def run(executor, stages, request, interruption=None):
    interruption = interruption or Interruption()
    return executor.run(request, interruption, lambda stage, progress: stages.append(stage))


def start_run(executor, stages, interruption):
    """Move the red block to the blue bowl on a thread of its own; the outcome lands in the returned list."""
    outcomes = []
    runner = threading.Thread(target=lambda: outcomes.append(
        run(executor, stages, PickPlaceRequest('red block', 'blue bowl'), interruption)))
    runner.start()
    return runner, outcomes


def test_a_block_goes_into_the_bowl_through_every_stage(table):
    world, executor, stages = table
    outcome = run(executor, stages, PickPlaceRequest('red block', 'blue bowl'))
    assert (outcome.ending, outcome.code, outcome.message) == (Ending.SUCCEEDED, PickPlaceErrorCode.NONE, '')
    assert list(dict.fromkeys(stages)) == list(StageName)
    assert math.dist(outcome.final_position[:2], (-0.1, -0.6)) < 0.01
    assert set(world.stage_motions()) == {StageName.APPROACH, StageName.DESCEND, StageName.LIFT, StageName.MOVE,
                                          StageName.PLACE, StageName.RETREAT}
    # Only the place descent stops on contact, with the configured tolerance; the gripper closes with the grip
    # force and releases wider than the block.
    assert [(stage, tolerance) for stage, _, tolerance in world.trajectories if tolerance is not None] == \
        [(StageName.PLACE, PickPlaceConfig().contact_tolerance)]
    # The fingers start fully open: the approach needs no gripper motion, the first command is the grasp.
    assert world.gripper_commands[0] == pytest.approx((BLOCK[1] - PickPlaceConfig().grasp_squeeze,
                                                       PickPlaceConfig().grip_force))
    assert BLOCK[1] < world.gripper_commands[1][0] <= PickPlaceConfig().gripper_open_width
    assert len(world.gripper_commands) == 2


def test_fingers_too_close_together_open_on_the_approach(table):
    world, executor, stages = table
    world.opening_now = 0.02
    outcome = run(executor, stages, PickPlaceRequest('red block', 'blue bowl'))
    assert outcome.code == PickPlaceErrorCode.NONE, outcome.message
    approach_opening, grasp = world.gripper_commands[:2]
    assert approach_opening[0] == PickPlaceConfig().gripper_open_width
    assert grasp == pytest.approx((BLOCK[1] - PickPlaceConfig().grasp_squeeze, PickPlaceConfig().grip_force))


def test_a_grasp_that_closes_on_nothing_fails_before_lifting(table):
    world, executor, stages = table
    world.missing_object = True
    outcome = run(executor, stages, PickPlaceRequest('red block', 'blue bowl'))
    assert (outcome.ending, outcome.code) == (Ending.FAILED, PickPlaceErrorCode.GRASP_MISSED)
    assert 'grasp missed' in outcome.message
    assert stages[-1] == StageName.VERIFY
    # A second grasp after the first missed: the fingers open, the arm lifts back (during the failed verify) and,
    # already above the object, comes down again; after the second miss nothing moves on.
    assert world.stage_motions() == [StageName.APPROACH, StageName.DESCEND, StageName.VERIFY, StageName.DESCEND], \
        'nothing moves after the last miss'
    grasp = BLOCK[1] - PickPlaceConfig().grasp_squeeze
    assert [position for position, _ in world.gripper_commands] == pytest.approx(
        [grasp, PickPlaceConfig().gripper_open_width, grasp])


def test_a_missed_grasp_is_tried_once_more_and_the_pick_finishes(table):
    world, executor, stages = table
    world.misses_left = 1
    outcome = run(executor, stages, PickPlaceRequest('red block', 'blue bowl'))
    assert (outcome.ending, outcome.code) == (Ending.SUCCEEDED, PickPlaceErrorCode.NONE), outcome.message
    assert math.dist(outcome.final_position[:2], (-0.1, -0.6)) < 0.01
    assert stages.count(StageName.VERIFY) == 2 and stages[-1] == StageName.RETREAT


@pytest.mark.parametrize('how', ['stop', 'cancel'])
def test_a_stop_or_cancel_mid_motion_cancels_the_arm_goal_and_moves_nothing_more(table, how):
    world, executor, stages = table
    world.hang_in = StageName.MOVE
    interruption = Interruption()
    runner, outcomes = start_run(executor, stages, interruption)
    assert world.moving.wait(30.0)
    interruption.stop() if how == 'stop' else interruption.cancel()
    runner.join(30.0)
    (outcome,) = outcomes
    assert outcome.code == PickPlaceErrorCode.CANCELLED
    if how == 'stop':
        assert (outcome.ending, outcome.message) == (Ending.STOPPED,
                                                     'stopped by /cap/stop: the arm stopped where it was')
    else:
        assert (outcome.ending, outcome.message) == (Ending.CANCELLED, 'cancelled: the arm stopped where it was')
    assert world.goals[-1].cancelled.is_set(), 'the running trajectory was cancelled'
    assert world.stage_motions()[-1] == StageName.MOVE and stages[-1] == StageName.MOVE
    assert world.held == 'red block'


@pytest.mark.parametrize('how', ['stop', 'cancel'])
def test_a_stop_or_cancel_while_the_arm_goal_awaits_acceptance_cancels_it_once_accepted(table, how):
    world, _, stages = table
    world.slow_accept_in = StageName.MOVE
    # Long waits: the run waits for the cancel to be taken until this test lets the goal be accepted.
    executor = PickPlaceExecutor(world, world, world, PickPlaceConfig(),
                                 ExecutionConfig(service_timeout=60.0, server_timeout=60.0), stop_source='/cap/stop')
    interruption = Interruption()
    runner, outcomes = start_run(executor, stages, interruption)
    assert world.moving.wait(30.0)
    goal = world.goals[-1]
    interruption.stop() if how == 'stop' else interruption.cancel()
    assert goal.cancel_asked.wait(30.0), 'the goal not yet accepted was cancelled'
    assert runner.is_alive() and not outcomes, 'the run waits until the controller has taken the cancel'
    goal.answer(True)
    runner.join(30.0)
    (outcome,) = outcomes
    assert goal.cancelled.is_set(), 'the cancel reached the goal once it was accepted'
    assert outcome.code == PickPlaceErrorCode.CANCELLED and outcome.halt_confirmed
    assert (outcome.ending, outcome.message) == (
        (Ending.STOPPED, 'stopped by /cap/stop: the arm stopped where it was') if how == 'stop' else
        (Ending.CANCELLED, 'cancelled: the arm stopped where it was'))
    assert world.stage_motions()[-1] == StageName.MOVE and stages[-1] == StageName.MOVE


def test_a_stop_while_the_acceptance_never_comes_says_the_cancel_was_not_confirmed(table):
    world, executor, stages = table
    world.slow_accept_in = StageName.MOVE
    interruption = Interruption()
    runner, outcomes = start_run(executor, stages, interruption)
    assert world.moving.wait(30.0)
    interruption.stop()
    runner.join(30.0)
    (outcome,) = outcomes
    assert world.goals[-1].cancel_asked.is_set()
    assert (outcome.ending, outcome.code, outcome.halt_confirmed) == (Ending.STOPPED, PickPlaceErrorCode.CANCELLED,
                                                                      False)
    assert outcome.message == ('stopped by /cap/stop, but the controller did not confirm the cancel of its goal '
                               'within 0 s')


def test_an_acceptance_that_times_out_still_cancels_the_goal(table):
    world, executor, stages = table
    world.slow_accept_in = StageName.APPROACH
    outcome = run(executor, stages, PickPlaceRequest('red block', 'blue bowl'))
    assert (outcome.ending, outcome.code) == (Ending.FAILED, PickPlaceErrorCode.TIMEOUT)
    assert outcome.message == 'no answer from the arm controller within 0 s'
    assert world.goals[-1].cancel_asked.is_set(), 'a late acceptance would not start the motion unwatched'


def test_contact_on_the_place_descent_ends_it_and_the_retreat_starts_where_the_arm_stopped(table):
    world, executor, stages = table
    world.contact_at_place = True
    outcome = run(executor, stages, PickPlaceRequest('red block', 'blue bowl'))
    assert outcome.code == PickPlaceErrorCode.NONE, outcome.message
    place = [t for stage, t, _ in world.trajectories if stage == StageName.PLACE][-1]  # the touch-down
    retreat = [t for stage, t, _ in world.trajectories if stage == StageName.RETREAT][0]
    np.testing.assert_allclose(retreat.start, place.positions[len(place) // 2])


def test_a_tracking_error_outside_the_place_descent_fails_the_motion(table):
    world, executor, stages = table
    world.contact_at_place = True
    world.follow = lambda trajectory, tolerance: (world.trajectories.append((world.stages[-1], trajectory, tolerance))
                                                  or FakeGoal(ArmOutcome(ArmResult.TOLERANCE_VIOLATED, 'strayed')))
    outcome = run(executor, stages, PickPlaceRequest('red block', 'blue bowl'))
    assert (outcome.code, outcome.message) == (PickPlaceErrorCode.UNKNOWN,
                                               'the arm did not complete its motion (approach): strayed')
    assert world.stage_motions() == [StageName.APPROACH]


def test_a_block_that_ends_off_the_table_is_reported_dropped(table):
    world, executor, stages = table
    world.drop_to = (-0.1, -0.9, -0.3)
    outcome = run(executor, stages, PickPlaceRequest('red block', 'blue bowl'))
    assert (outcome.ending, outcome.code) == (Ending.FAILED, PickPlaceErrorCode.OBJECT_DROPPED)
    assert 'the red block fell off the table' in outcome.message
    assert stages[-1] == StageName.RETREAT


def test_a_block_that_slips_while_lifting_is_reported_dropped(table):
    world, executor, stages = table
    # The fingers close on nothing once the arm has risen (the grasp itself was verified).
    world.opening = lambda: 0.0 if world.stages[-1] == StageName.LIFT else world.opening_now
    outcome = run(executor, stages, PickPlaceRequest('red block', 'blue bowl'))
    assert (outcome.code, stages[-1]) == (PickPlaceErrorCode.OBJECT_DROPPED, StageName.LIFT)
    assert 'slipped out of the gripper' in outcome.message


def test_perception_that_does_not_answer_times_out_before_anything_moves(table):
    world, executor, stages = table
    world.perception_answers = False
    outcome = run(executor, stages, PickPlaceRequest('red block', 'blue bowl'))
    assert (outcome.code, outcome.message) == (PickPlaceErrorCode.TIMEOUT, 'no answer from perception within 0 s')
    assert not world.trajectories and not world.gripper_commands and not stages


@pytest.mark.parametrize('request_, code, words', [
    (PickPlaceRequest('red block', '', (0.0, -1.0)), PickPlaceErrorCode.OUTSIDE_WORKSPACE, 'outside the workspace'),
    (PickPlaceRequest('purple block', 'blue bowl'), PickPlaceErrorCode.OBJECT_NOT_FOUND, "'purple block'"),
    (PickPlaceRequest('red block', 'pink bowl'), PickPlaceErrorCode.TARGET_NOT_FOUND, "'pink bowl'"),
])
def test_refused_requests_move_nothing(table, request_, code, words):
    world, executor, stages = table
    outcome = run(executor, stages, request_)
    assert (outcome.ending, outcome.code) == (Ending.FAILED, code)
    assert words in outcome.message
    assert not world.trajectories and not world.gripper_commands and not stages


def test_a_placed_object_still_hidden_after_the_retreat_is_looked_at_again_from_out_of_the_view(table):
    world, _, stages = table
    rest = (0.8413, -2.2842, 1.7017, -0.9883, -1.5708, -0.7295)
    config = dataclasses.replace(PickPlaceConfig(), clear_view_from=(0.0, -0.5, 0.85), look_again_joints=rest)
    executor = PickPlaceExecutor(world, world, world, config, TIMEOUTS, stop_source='/cap/stop')
    world.hidden_from = rest
    outcome = run(executor, stages, PickPlaceRequest('red block', 'blue bowl'))
    assert outcome.ending == Ending.SUCCEEDED, outcome.message
    assert world.stage_motions()[-1] == StageName.RETREAT
    assert np.allclose(world.q, rest, atol=1e-3)  # it went to look again, and saw the block there
    assert math.dist(world.objects['red block'].position[:2], (-0.1, -0.6)) < 0.01


def test_a_placed_object_in_view_after_the_retreat_costs_no_extra_move(table):
    world, _, stages = table
    rest = (0.8413, -2.2842, 1.7017, -0.9883, -1.5708, -0.7295)
    config = dataclasses.replace(PickPlaceConfig(), clear_view_from=(0.0, -0.5, 0.85), look_again_joints=rest)
    executor = PickPlaceExecutor(world, world, world, config, TIMEOUTS, stop_source='/cap/stop')
    outcome = run(executor, stages, PickPlaceRequest('red block', 'blue bowl'))
    assert outcome.ending == Ending.SUCCEEDED, outcome.message
    assert not np.allclose(world.q, rest, atol=1e-3)
