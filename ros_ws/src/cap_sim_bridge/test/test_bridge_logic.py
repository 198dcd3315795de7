"""The plain logic behind the bridge node: goal checking (control_msgs semantics) and the physics loop's pacing."""
import math

import numpy as np
import pytest
from builtin_interfaces.msg import Duration
from trajectory_msgs.msg import JointTrajectoryPoint

from control_msgs.action import FollowJointTrajectory
from control_msgs.msg import JointTolerance
from cap_sim_bridge import trajectory_goal
from cap_sim_bridge.pacing import LoopPacing, Pacer
from cap_sim_bridge.world import ARM_JOINT_NAMES

HOLD = np.arange(6) * 0.1


def goal(names, points, goal_tolerance=(), path_tolerance=(), goal_time=0.0):
    message = FollowJointTrajectory.Goal()
    message.trajectory.joint_names = list(names)
    for seconds, positions, velocities in points:
        message.trajectory.points.append(JointTrajectoryPoint(
            positions=list(positions), velocities=list(velocities),
            time_from_start=Duration(sec=int(seconds), nanosec=int(round(seconds % 1 * 1e9)))))
    message.goal_tolerance = list(goal_tolerance)
    message.path_tolerance = list(path_tolerance)
    message.goal_time_tolerance = Duration(sec=int(goal_time), nanosec=int(round(goal_time % 1 * 1e9)))
    return message


def test_a_subset_of_joints_in_any_order_is_completed_from_the_held_positions():
    plan = trajectory_goal.plan_from_goal(
        goal(['wrist_3_joint', 'shoulder_pan_joint'], [(0.5, [1.0, 2.0], []), (1.5, [1.5, 2.5], [])]),
        ARM_JOINT_NAMES, HOLD)
    np.testing.assert_allclose(plan.times, [0.5, 1.5])
    np.testing.assert_allclose(plan.positions[0], [2.0, 0.1, 0.2, 0.3, 0.4, 1.0])
    np.testing.assert_allclose(plan.positions[1], [2.5, 0.1, 0.2, 0.3, 0.4, 1.5])
    assert plan.velocities is None
    assert plan.goal_time_tolerance == trajectory_goal.DEFAULT_GOAL_TIME_TOLERANCE
    assert np.all(plan.goal_position_tolerance == trajectory_goal.DEFAULT_GOAL_TOLERANCE)
    assert np.all(np.isinf(plan.path_position_tolerance))


def test_tolerances_zero_means_default_negative_means_unchecked():
    plan = trajectory_goal.plan_from_goal(
        goal(ARM_JOINT_NAMES, [(1.0, HOLD, [0.0] * 6)],
             goal_tolerance=[JointTolerance(name='elbow_joint', position=0.05),
                             JointTolerance(name='wrist_1_joint', position=-1.0),
                             JointTolerance(name='wrist_2_joint', position=0.0, velocity=0.01)],
             path_tolerance=[JointTolerance(name='shoulder_lift_joint', position=0.1)], goal_time=0.25),
        ARM_JOINT_NAMES, HOLD)
    assert plan.goal_position_tolerance[2] == 0.05
    assert math.isinf(plan.goal_position_tolerance[3])
    assert plan.goal_position_tolerance[4] == trajectory_goal.DEFAULT_GOAL_TOLERANCE
    assert plan.goal_velocity_tolerance[4] == 0.01 and math.isinf(plan.goal_velocity_tolerance[0])
    assert plan.path_position_tolerance[1] == 0.1
    assert plan.goal_time_tolerance == 0.25
    assert plan.velocities is not None
    desired = HOLD.copy()
    assert plan.path_violation(desired + [0, 0.05, 0, 0, 0, 0], desired, ARM_JOINT_NAMES) is None
    message = plan.path_violation(desired + [0, 0.2, 0, 0, 0, 0], desired, ARM_JOINT_NAMES)
    assert 'shoulder_lift_joint' in message
    assert plan.goal_reached(HOLD + [0, 0, 0.04, 1.0, 0, 0], np.zeros(6))
    assert not plan.goal_reached(HOLD + [0, 0, 0.06, 0, 0, 0], np.zeros(6))
    assert not plan.goal_reached(HOLD, np.array([0, 0, 0, 0, 0.02, 0]))


@pytest.mark.parametrize('message, code, words', [
    (goal([], [(1.0, [], [])]), trajectory_goal.INVALID_JOINTS, 'no joints'),
    (goal(['elbow_joint', 'finger'], [(1.0, [0, 0], [])]), trajectory_goal.INVALID_JOINTS, 'finger'),
    (goal(['elbow_joint', 'elbow_joint'], [(1.0, [0, 0], [])]), trajectory_goal.INVALID_JOINTS, 'repeat'),
    (goal(['elbow_joint'], []), trajectory_goal.INVALID_GOAL, 'no points'),
    (goal(['elbow_joint'], [(1.0, [0], []), (1.0, [1], [])]), trajectory_goal.INVALID_GOAL, 'increase'),
    (goal(['elbow_joint'], [(1.0, [0, 1], [])]), trajectory_goal.INVALID_GOAL, 'positions'),
    (goal(['elbow_joint'], [(1.0, [0], [0.0]), (2.0, [1], [])]), trajectory_goal.INVALID_GOAL, 'velocities'),
    (goal(['elbow_joint'], [(1.0, [0], [])], goal_tolerance=[JointTolerance(name='x', position=1.0)]),
     trajectory_goal.INVALID_JOINTS, "'x'"),
])
def test_malformed_goals_are_refused_with_the_control_msgs_code_and_a_reason(message, code, words):
    with pytest.raises(trajectory_goal.GoalError, match=words) as raised:
        trajectory_goal.plan_from_goal(message, ARM_JOINT_NAMES, HOLD)
    assert raised.value.code == code


class FakeWallClock:
    """A wall clock the test advances by hand (time itself is the input here, not a system under test)."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_pacer_keeps_simulated_time_at_the_requested_rate():
    wall = FakeWallClock()
    pacer = Pacer(2.0, clock=wall)
    assert pacer.delay(0.0) == 0.0
    assert pacer.delay(1.0) == pytest.approx(0.5)  # 1 simulated second = 0.5 s of wall time at 2x
    wall.now += 0.5
    assert pacer.delay(1.0) == pytest.approx(0.0)
    assert pacer.delay(1.2) == pytest.approx(0.1)


def test_pacer_does_not_race_to_catch_up_after_a_stall_and_never_waits_when_unpaced():
    wall = FakeWallClock()
    pacer = Pacer(1.0, max_lag=0.2, clock=wall)
    pacer.delay(0.0)
    wall.now += 5.0  # a long stall
    assert pacer.delay(0.01) == 0.0
    assert pacer.delay(0.11) == pytest.approx(0.1)  # paced again from the new anchor
    assert Pacer(0.0, clock=wall).delay(123.0) == 0.0


def test_a_restarted_pacer_does_not_wait_for_a_jump_in_simulated_time():
    wall = FakeWallClock()
    pacer = Pacer(1.0, clock=wall)
    pacer.delay(0.0)
    pacer.restart()
    assert pacer.delay(0.5) == 0.0  # e.g. half a second of settling simulated at once on a reset
    assert pacer.delay(0.6) == pytest.approx(0.1)


def test_as_fast_as_possible_the_loop_slows_to_its_idle_speed_only_while_idle():
    wall = FakeWallClock()
    pacing = LoopPacing(0.0, idle_speed=10.0, clock=wall)
    assert pacing.slows_when_idle
    assert pacing.delay(5.0, idle=False) == 0.0  # busy: as fast as possible
    assert pacing.delay(6.0, idle=True) == 0.0  # idle from here: paced from this point on
    assert pacing.delay(7.0, idle=True) == pytest.approx(0.1)  # 1 simulated second = 0.1 s of wall at 10x
    assert pacing.delay(60.0, idle=False) == 0.0  # a goal: full speed again at once
    wall.now += 0.01
    assert pacing.delay(61.0, idle=True) == 0.0  # a new idle spell does not pay for the busy one
    assert pacing.delay(61.5, idle=True) == pytest.approx(0.05)


def test_in_real_time_or_without_an_idle_speed_idleness_does_not_change_the_pace():
    wall = FakeWallClock()
    real_time = LoopPacing(1.0, idle_speed=10.0, clock=wall)
    assert not real_time.slows_when_idle
    real_time.delay(0.0, idle=True)
    assert real_time.delay(0.5, idle=True) == pytest.approx(0.5)
    assert real_time.delay(0.5, idle=False) == pytest.approx(0.5)
    unpaced = LoopPacing(0.0, idle_speed=0.0, clock=wall)
    assert not unpaced.slows_when_idle
    assert unpaced.delay(100.0, idle=True) == 0.0
