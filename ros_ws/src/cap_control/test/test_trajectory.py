"""Trajectory timing: the arm moves within the UR5e's limits, ends exactly where asked, and lines stay straight."""
import math

import numpy as np
import pytest

from cap_control.kinematics import HOME_JOINTS, IKError, forward_kinematics, inverse_kinematics, top_down_pose
from cap_control.trajectory import (
    UR5E_LIMITS, CartesianLimits, JointLimits, TrajectoryError, cartesian_line, time_joint_path,
    trajectory_tcp_positions,
)

TOLERANCE = 1e-6


def table_joints(x: float, y: float, z: float, yaw: float = 0.0, seed=HOME_JOINTS) -> np.ndarray:
    return inverse_kinematics(top_down_pose((x, y, z), yaw), q_seed=seed)


def assert_within_limits(trajectory, limits: JointLimits, check_jerk: bool = True) -> None:
    assert np.all(np.diff(trajectory.times) > 0), 'time must increase strictly'
    assert np.all(np.abs(trajectory.velocities) <= limits.velocity * (1 + TOLERANCE))
    assert np.all(np.abs(trajectory.accelerations) <= limits.acceleration * (1 + TOLERANCE))
    if check_jerk:
        jerk = np.diff(trajectory.accelerations, axis=0) / np.diff(trajectory.times)[:, None]
        assert np.all(np.abs(jerk) <= limits.jerk * (1 + 1e-3))
    assert np.all(trajectory.positions >= limits.lower) and np.all(trajectory.positions <= limits.upper)


def test_joint_path_respects_limits_and_hits_every_waypoint_exactly():
    waypoints = [HOME_JOINTS, table_joints(0.25, -0.75, 0.2, 1.0), table_joints(-0.25, -0.3, 0.1, -2.0),
                 HOME_JOINTS + np.array([2.0, 0.3, -0.3, 0.5, 0.2, -3.0])]
    trajectory = time_joint_path(waypoints, period=0.01)
    assert_within_limits(trajectory, UR5E_LIMITS)
    np.testing.assert_array_equal(trajectory.start, waypoints[0])
    np.testing.assert_array_equal(trajectory.end, waypoints[-1])
    for waypoint in waypoints:
        assert np.min(np.max(np.abs(trajectory.positions - waypoint), axis=1)) == 0.0
    np.testing.assert_allclose(trajectory.velocities[[0, -1]], 0.0, atol=1e-9)
    # The fastest joint of the long last segment reaches its speed limit (180 or 360 deg/s).
    assert np.max(np.abs(trajectory.velocities) / UR5E_LIMITS.velocity) == pytest.approx(1.0, rel=1e-6)


def test_positions_follow_the_reported_velocities():
    trajectory = time_joint_path([HOME_JOINTS, table_joints(0.2, -0.6, 0.05)], period=0.002)
    integrated = trajectory.start + np.concatenate(
        [np.zeros((1, 6)), np.cumsum(0.5 * (trajectory.velocities[1:] + trajectory.velocities[:-1])
                                     * np.diff(trajectory.times)[:, None], axis=0)])
    np.testing.assert_allclose(integrated, trajectory.positions, atol=1e-4)


def test_slower_limits_give_a_slower_trajectory_within_them():
    path = [HOME_JOINTS, table_joints(-0.2, -0.7, 0.1, 0.5)]
    slow_limits = UR5E_LIMITS.scaled(velocity_scale=0.3, acceleration_scale=0.5)
    fast, slow = time_joint_path(path), time_joint_path(path, slow_limits)
    assert slow.duration > fast.duration
    assert_within_limits(slow, slow_limits)


def test_last_sample_lands_on_the_duration_whatever_the_period():
    trajectory = time_joint_path([HOME_JOINTS, HOME_JOINTS + 0.3], period=0.0371)
    steps = np.diff(trajectory.times)
    assert np.all(steps <= 0.0371 * 1.5 + 1e-12)
    np.testing.assert_array_equal(trajectory.end, HOME_JOINTS + 0.3)


def test_a_path_that_stays_put_is_a_single_sample():
    trajectory = time_joint_path([HOME_JOINTS, HOME_JOINTS])
    assert len(trajectory) == 1 and trajectory.duration == 0.0


def test_waypoints_outside_the_joint_limits_are_refused():
    beyond_elbow = HOME_JOINTS.copy()
    beyond_elbow[2] = 3.5
    with pytest.raises(TrajectoryError, match='outside the joint limits'):
        time_joint_path([HOME_JOINTS, beyond_elbow])


def test_vertical_descent_is_straight_top_down_and_exact_at_both_ends():
    start = table_joints(0.25, -0.75, 0.25, 0.7)
    goal = top_down_pose((0.25, -0.75, 0.02), 0.7)
    line = cartesian_line(start, goal, cartesian_limits=CartesianLimits(speed=0.2))
    tcp = trajectory_tcp_positions(line)
    np.testing.assert_allclose(tcp[:, :2], [[0.25, -0.75]] * len(tcp), atol=1e-6)
    assert np.all(np.diff(tcp[:, 2]) <= 1e-12), 'the descent never goes back up'
    np.testing.assert_array_equal(line.start, start)
    np.testing.assert_allclose(forward_kinematics(line.end), goal, atol=1e-9)
    for q in line.positions:
        np.testing.assert_allclose(forward_kinematics(q)[:3, 2], [0, 0, -1], atol=1e-6)
    speeds = np.linalg.norm(np.diff(tcp, axis=0), axis=1) / np.diff(line.times)
    assert np.max(speeds) <= 0.2 * (1 + 1e-3)
    assert_within_limits(line, UR5E_LIMITS, check_jerk=False)
    assert np.max(np.abs(np.diff(line.positions, axis=0))) < 0.05, 'no configuration flip along the line'


def test_line_with_a_turn_interpolates_orientation():
    start = table_joints(-0.2, -0.4, 0.15, 0.0)
    goal = top_down_pose((0.1, -0.6, 0.1), 1.2)
    line = cartesian_line(start, goal)
    yaws = [math.atan2(forward_kinematics(q)[1, 0], forward_kinematics(q)[0, 0]) for q in line.positions]
    assert yaws[0] == pytest.approx(0.0, abs=1e-9) and yaws[-1] == pytest.approx(1.2, abs=1e-9)
    assert np.all(np.diff(yaws) >= -1e-9)
    assert_within_limits(line, UR5E_LIMITS, check_jerk=False)


def test_line_near_the_shoulder_singularity_slows_down_to_the_joint_limits():
    # Passing 0.14 m from the base axis (the singular distance is 0.133 m) makes the shoulder pan whirl.
    start = table_joints(0.3, -0.14, 0.3, 0.0)
    line = cartesian_line(start, top_down_pose((-0.3, -0.14, 0.3), 0.0), max_joint_step=0.5)
    assert_within_limits(line, UR5E_LIMITS, check_jerk=False)
    np.testing.assert_allclose(trajectory_tcp_positions(line)[:, 1:], [[-0.14, 0.3]] * len(line), atol=1e-6)


def test_line_through_the_base_axis_is_refused():
    start = table_joints(0.3, -0.05, 0.3, 0.0)
    with pytest.raises((IKError, TrajectoryError)):
        cartesian_line(start, top_down_pose((-0.3, -0.05, 0.3), 0.0))


def test_line_to_where_the_arm_already_is_is_a_single_sample():
    start = table_joints(0.0, -0.5, 0.1)
    assert len(cartesian_line(start, forward_kinematics(start))) == 1
