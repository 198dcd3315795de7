"""UR5e kinematics: the arm reaches every top-down pose over the table, exactly, and says clearly when it cannot."""
import math

import numpy as np
import pytest

from cap_tabletop.objects import BLOCK_SIZE
from cap_tabletop.workspace import CORNERS, MIDDLE, SIDES, TABLE_X_RANGE, TABLE_Y_RANGE

from cap_control.kinematics import (
    ARM_REACH, HOME_JOINTS, JOINT_LOWER, JOINT_UPPER, IKError, forward_kinematics, inverse_kinematics,
    inverse_kinematics_all, inverse_kinematics_path, is_reachable_top_down, pose_error, top_down_pose,
    top_down_reach_margin,
)

TABLE_X = TABLE_X_RANGE
TABLE_Y = TABLE_Y_RANGE
BLOCK_CENTRE_HEIGHT = BLOCK_SIZE / 2
NAMED_POSITIONS = {**CORNERS, **SIDES, 'middle': MIDDLE}


def random_table_poses(count: int, seed: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [top_down_pose((rng.uniform(*TABLE_X), rng.uniform(*TABLE_Y), rng.uniform(0.02, 0.3)),
                          rng.uniform(-math.pi, math.pi)) for _ in range(count)]


def test_ik_round_trip_over_the_table_is_within_1mm_and_half_a_degree():
    worst_position, worst_angle = 0.0, 0.0
    for pose in random_table_poses(1000, seed=5):
        q = inverse_kinematics(pose)
        assert np.all(q >= JOINT_LOWER) and np.all(q <= JOINT_UPPER)
        position_error, angle_error = pose_error(pose, forward_kinematics(q))
        worst_position, worst_angle = max(worst_position, position_error), max(worst_angle, angle_error)
    assert worst_position < 1e-3
    assert math.degrees(worst_angle) < 0.5


def test_tcp_points_down_and_sits_tool_offset_below_the_flange():
    pose = forward_kinematics(HOME_JOINTS)
    flange = forward_kinematics(HOME_JOINTS, tool_offset=0.0)
    np.testing.assert_allclose(pose[:3, 2], [0.0, 0.0, -1.0], atol=1e-9)
    np.testing.assert_allclose(flange[:3, 3] - pose[:3, 3], [0.0, 0.0, 0.15], atol=1e-9)
    assert pose[1, 3] < -0.3, 'the ready pose must be over the table (negative y)'


def test_all_eight_branches_reach_the_pose():
    pose = top_down_pose((0.1, -0.5, 0.1), 0.4)
    solutions = inverse_kinematics_all(pose)
    assert len(solutions) == 8
    distinct = {tuple(np.round(q, 6)) for q in solutions}
    assert len(distinct) == 8
    for q in solutions:
        position_error, angle_error = pose_error(pose, forward_kinematics(q))
        assert position_error < 1e-9 and angle_error < 1e-6


def test_the_solution_nearest_the_seed_is_returned():
    rng = np.random.default_rng(11)
    for _ in range(200):
        q = rng.uniform(JOINT_LOWER, JOINT_UPPER)
        if abs(math.sin(q[4])) < 0.05:  # at the wrist singularity joints 4 and 6 trade off freely
            continue
        solved = inverse_kinematics(forward_kinematics(q), q_seed=q)
        np.testing.assert_allclose(solved, q, atol=1e-6)


def test_top_down_pose_has_the_requested_yaw():
    pose = top_down_pose((0.0, -0.5, 0.1), math.radians(30))
    np.testing.assert_allclose(pose[:3, 2], [0, 0, -1], atol=1e-12)
    assert math.degrees(math.atan2(pose[1, 0], pose[0, 0])) == pytest.approx(30)
    np.testing.assert_allclose(pose[:3, :3] @ pose[:3, :3].T, np.eye(3), atol=1e-12)


@pytest.mark.parametrize('xyz, reason', [
    ((0.0, -1.2, 0.1), 'out of reach'),
    ((0.6, -0.7, 0.02), 'out of reach'),
    ((0.0, 0.0, 0.3), 'too close to the base axis'),
])
def test_unreachable_poses_raise_a_readable_ik_error(xyz, reason):
    with pytest.raises(IKError, match=reason):
        inverse_kinematics(top_down_pose(xyz))
    assert not is_reachable_top_down(xyz)


def test_far_pose_in_any_orientation_is_unreachable():
    pose = np.eye(4)
    pose[:3, 3] = (0.9, -0.9, 0.5)
    with pytest.raises(IKError):
        inverse_kinematics(pose)


@pytest.mark.parametrize('name', sorted(NAMED_POSITIONS))
def test_every_named_position_is_reachable_top_down_at_block_height(name):
    x, y = NAMED_POSITIONS[name]
    assert is_reachable_top_down((x, y, BLOCK_CENTRE_HEIGHT))
    assert top_down_reach_margin((x, y, BLOCK_CENTRE_HEIGHT)) > 0.05


def test_the_whole_table_top_is_reachable_top_down_at_block_height():
    margins = []
    for x in np.linspace(*TABLE_X, 25):
        for y in np.linspace(*TABLE_Y, 25):
            for yaw in (0.0, 1.0, 2.5):
                assert is_reachable_top_down((x, y, BLOCK_CENTRE_HEIGHT), yaw), (x, y, yaw)
            margins.append(top_down_reach_margin((x, y, BLOCK_CENTRE_HEIGHT)))
    # The far corners (0.854 m from the base) are the tightest spots; they still leave over 6 cm of stretch.
    assert min(margins) > 0.06


def test_reach_margin_matches_where_ik_starts_failing():
    direction = np.array([0.3, -0.8]) / np.linalg.norm([0.3, -0.8])
    for height in (0.02, 0.3):
        radii = np.arange(0.5, 1.2, 0.0005)
        reachable = [is_reachable_top_down((*(r * direction), height)) for r in radii]
        edge = radii[np.argmin(reachable)]  # first radius that fails
        assert top_down_reach_margin((*((edge - 0.001) * direction), height)) > 0
        assert top_down_reach_margin((*((edge + 0.001) * direction), height)) < 0
    assert ARM_REACH == pytest.approx(0.8172)


@pytest.mark.parametrize('kind', ['line over the table', 'joint sweep through the wrist singularity', 'out of reach'])
def test_a_path_is_solved_as_pose_by_pose_ik_seeded_with_the_last_solution(kind):
    rng = np.random.default_rng(len(kind))
    steps = np.linspace(0.0, 1.0, 400)[:, None]
    if kind == 'line over the table':
        poses = [top_down_pose((-0.3 + 0.6 * s, -0.4 - 0.2 * s, 0.1), 0.7) for s in steps[:, 0]]
    elif kind == 'joint sweep through the wrist singularity':
        start = rng.uniform(JOINT_LOWER, JOINT_UPPER) * 0.5
        end = start.copy()
        start[4], end[4] = -0.4, 0.4
        poses = [forward_kinematics(q) for q in start + steps * (end - start)]
    else:
        poses = [top_down_pose((0.0, -0.5 - 0.8 * s, 0.1)) for s in steps[:, 0]]
    seed = rng.uniform(JOINT_LOWER, JOINT_UPPER)
    expected, previous = [], seed
    for pose in poses:
        try:
            previous = inverse_kinematics(pose, previous)
        except IKError:
            break
        expected.append(previous)
    solutions, error = inverse_kinematics_path(np.array(poses), seed)
    assert len(solutions) == len(expected) and (error is None) == (len(expected) == len(poses))
    np.testing.assert_allclose(solutions, np.array(expected).reshape(-1, 6), atol=1e-12)
