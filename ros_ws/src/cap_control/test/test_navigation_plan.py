"""Planning on the kitchen's occupancy grid and following the path with the base's limits (no ROS, no simulator)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from cap_mobile.layout import BASE_RADIUS, FURNITURE, ROOM_X_RANGE, ROOM_Y_RANGE, START_POSE, location

from cap_control.navigation.plan import (
    FollowerLimits, NavigateErrorCode, NavigationError, OccupancyGrid, PathFollower, follow_on_ideal_base,
    path_length, plan_path, wrap_angle,
)

MARGIN = 0.05  # planned clearance beyond the base's radius: pure pursuit cuts corners by less than this


@pytest.fixture(scope='module')
def kitchen():
    raw = OccupancyGrid.from_boxes([piece.footprint for piece in FURNITURE], ROOM_X_RANGE, ROOM_Y_RANGE)
    return raw, raw.inflated(BASE_RADIUS + MARGIN)


@pytest.mark.parametrize('name', [piece.name for piece in FURNITURE])
def test_every_location_is_reached_by_a_free_path_not_much_longer_than_the_straight_line(kitchen, name):
    _, grid = kitchen
    goal = location(name).approach()
    path = plan_path(grid, START_POSE, goal)
    assert np.allclose(path[0], START_POSE[:2]) and np.allclose(path[-1], goal[:2])
    assert all(grid.segment_is_free(a, b) for a, b in zip(path[:-1], path[1:]))
    straight = math.dist(START_POSE[:2], goal[:2])
    assert straight - 1e-9 <= path_length(path) <= 1.5 * straight + 0.5


def test_a_goal_inside_furniture_or_too_close_to_it_is_unreachable(kitchen):
    _, grid = kitchen
    table = location('table')
    for goal in (table.centre, (table.centre[0], table.footprint[1] - 0.1)):  # in the table; 10 cm from its edge
        with pytest.raises(NavigationError) as error:
            plan_path(grid, START_POSE, goal)
        assert error.value.code == NavigateErrorCode.UNREACHABLE
        assert 'inside an obstacle' in str(error.value)


def test_a_free_spot_walled_in_is_unreachable():
    walls = [(1.0, 1.0, 3.0, 1.1), (1.0, 2.9, 3.0, 3.0), (1.0, 1.0, 1.1, 3.0), (2.9, 1.0, 3.0, 3.0)]
    grid = OccupancyGrid.from_boxes(walls, (-1.0, 4.0), (-1.0, 4.0)).inflated(0.3)
    with pytest.raises(NavigationError, match='no free path') as error:
        plan_path(grid, (0.0, 0.0), (2.0, 2.0))
    assert error.value.code == NavigateErrorCode.UNREACHABLE


@pytest.mark.parametrize('name', ['countertop', 'desk', 'barstool', 'blue bin'])
def test_the_follower_ends_within_5_cm_and_0_05_rad_without_touching_anything_and_within_the_limits(kitchen, name):
    raw, grid = kitchen
    goal = location(name).approach()
    limits = FollowerLimits()
    dt = 0.01
    poses, commands = follow_on_ideal_base(PathFollower(plan_path(grid, START_POSE, goal), goal[2], limits),
                                           START_POSE, dt)
    assert commands[-1].done
    assert math.dist(poses[-1][:2], goal[:2]) <= limits.position_tolerance
    assert abs(wrap_angle(poses[-1][2] - goal[2])) <= limits.yaw_tolerance
    touching = raw.inflated(BASE_RADIUS)
    assert not any(touching.occupied[touching.cell(p[:2])] for p in poses)
    speeds = np.array([c.speed for c in commands])
    rates = np.array([c.yaw_rate for c in commands])
    assert np.all(np.abs(speeds) <= limits.max_speed + 1e-9)
    assert np.all(np.abs(rates) <= limits.max_yaw_rate + 1e-9)
    assert np.all(np.abs(np.diff(speeds)) <= limits.max_acceleration * dt + 1e-9)
    assert np.all(np.abs(np.diff(rates)) <= limits.max_yaw_acceleration * dt + 1e-9)


def test_remaining_distance_counts_down_along_the_path():
    path = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    follower = PathFollower(path, 0.0)
    assert follower.remaining_distance((0.0, 0.0)) == pytest.approx(2.0)
    assert follower.remaining_distance((0.5, 0.1)) == pytest.approx(1.5)
