"""Planning a tool's path over the whiteboard: checks before anything moves, timing, reach, tool orientation."""
import math
import time

import numpy as np
import pytest

from cap_control.kinematics import forward_kinematics
from cap_control.follow_path.plan import (
    PathConfig, PathError, PathErrorCode, StepKind, Surface, plan_path, resample, rest_parts, split_at_corners,
    tool_tip_positions,
)
from cap_control.trajectory import UR5E_LIMITS, concatenate
from cap_whiteboard import board, tool

READY = np.array([0.8413, -2.2842, 1.7017, -0.9883, -1.5708, -0.7295])
SQUARE = np.array([[-0.1, -0.45], [0.0, -0.45], [0.0, -0.55], [-0.1, -0.55], [-0.1, -0.45]])


def test_resampling_keeps_every_vertex_and_corners_cut_the_stroke():
    dense = resample(SQUARE, 0.002)
    assert np.max(np.linalg.norm(np.diff(dense, axis=0), axis=1)) <= 0.002 + 1e-12
    for vertex in SQUARE:
        assert np.min(np.linalg.norm(dense - vertex, axis=1)) < 1e-12
    assert len(split_at_corners(dense, math.radians(25))) == 4
    circle = np.array([[math.cos(a), math.sin(a)] for a in np.linspace(0, 2 * math.pi, 73)]) * 0.05
    assert len(split_at_corners(circle, math.radians(25))) == 1


@pytest.mark.parametrize('path, code, words', [
    ([np.array([[0.0, -0.5], [0.3, -0.5]])], PathErrorCode.OUTSIDE_WORKSPACE, '(0.300, -0.500)'),
    ([np.array([[0.0, -0.5], [np.nan, -0.5]])], PathErrorCode.INVALID_PATH, 'not a finite number'),
    ([], PathErrorCode.INVALID_PATH, 'no points'),
])
def test_bad_paths_are_refused_before_anything_is_planned(path, code, words):
    with pytest.raises(PathError) as refused:
        plan_path(READY, path, 'marker')
    assert refused.value.code == code and words in refused.value.message


def test_a_surface_out_of_reach_reports_the_fraction_that_could_be_followed():
    far = PathConfig(surface=Surface(x_min=-0.3, x_max=0.3, y_min=-1.2, y_max=-0.3))
    line = np.array([[0.0, -0.5], [0.0, -1.1]])
    with pytest.raises(PathError) as refused:
        plan_path(READY, [line], 'marker', config=far)
    assert refused.value.code == PathErrorCode.IK_FAILED
    assert 0.2 < refused.value.fraction < 0.9


@pytest.mark.parametrize('name', ['marker', 'eraser'])
def test_the_tool_tip_follows_the_stroke_pressed_into_the_board_within_the_joint_limits(name):
    plan = plan_path(READY, [SQUARE], name)
    kinds = [step.kind for step in plan.steps]
    assert kinds == [StepKind.TRAVEL, StepKind.DESCEND, StepKind.FOLLOW, StepKind.LIFT, StepKind.PARK]
    follow = plan.steps[2]
    tips = tool_tip_positions(follow.trajectory, name)
    assert np.allclose(tips[:, 2], board.SURFACE_Z - tool.press_depth(name), atol=1e-6)
    along = resample(SQUARE, 0.0005)
    distances = [np.min(np.linalg.norm(along - tip[:2], axis=1)) for tip in tips]
    assert max(distances) < 0.001
    velocities = np.abs(follow.trajectory.velocities)
    assert np.all(velocities <= UR5E_LIMITS.velocity + 1e-9)
    # Tool speed at most the default along the stroke; the tool points straight down the whole way.
    speeds = np.linalg.norm(np.diff(tips[:, :2], axis=0), axis=1) / np.diff(follow.trajectory.times)
    assert speeds.max() <= PathConfig().speed * 1.05
    for q in follow.trajectory.positions[::25]:
        axis = (forward_kinematics(q, 0.0) @ tool.flange_to_tool(name))[:3, 2]
        assert axis[2] < -0.9999
    # Joint steps stay small (no IK branch flip), and the arm parks at the end.
    assert np.max(np.abs(np.diff(follow.trajectory.positions, axis=0))) < 0.05
    assert np.allclose(plan.steps[-1].trajectory.end, PathConfig().park_joints)


def test_sharp_corners_stop_the_tool_and_a_moving_tool_never_touches_down_off_the_stroke():
    plan = plan_path(READY, [SQUARE, SQUARE + [0.12, 0.0]], 'marker')
    assert [s.kind for s in plan.steps].count(StepKind.FOLLOW) == 2
    follow = plan.steps[2].trajectory
    tips = tool_tip_positions(follow, 'marker')
    for corner in SQUARE[1:-1]:
        index = int(np.argmin(np.linalg.norm(tips[:, :2] - corner, axis=1)))
        assert np.max(np.abs(follow.velocities[index])) < 1e-6
    # Between strokes the tool travels at travel height.
    travel = tool_tip_positions(plan.steps[4].trajectory, 'marker')
    assert np.all(travel[:, 2] >= board.SURFACE_Z + PathConfig().travel_height - 1e-6)


def test_the_largest_stroke_plans_in_well_under_two_seconds():
    rng = np.random.default_rng(0)  # 5,000 points all over the board: thousands of corners, hours of drawing
    scribble = np.column_stack([rng.uniform(-0.23, 0.23, 5000), rng.uniform(-0.68, -0.32, 5000)])
    started = time.process_time()
    plan = plan_path(READY, [scribble], 'marker')
    assert time.process_time() - started < 2.0
    assert plan.points_total == 5000 and plan.duration > 3600


def test_planning_looks_for_an_interruption_between_passes():
    calls = []

    def check_interrupted():
        calls.append(len(calls))
        if len(calls) == 3:
            raise InterruptedError

    rng = np.random.default_rng(1)
    scribble = np.column_stack([rng.uniform(-0.23, 0.23, 2000), rng.uniform(-0.68, -0.32, 2000)])
    with pytest.raises(InterruptedError):
        plan_path(READY, [scribble], 'marker', check_interrupted=check_interrupted)
    assert len(calls) == 3


def test_a_long_stroke_is_cut_where_it_stops_into_parts_that_make_it_up():
    zigzag = np.array([[-0.2 + 0.4 * (i % 2), -0.6 + 0.002 * i] for i in range(60)])
    follow = plan_path(READY, [zigzag], 'marker').steps[2].trajectory
    parts = rest_parts(follow, 400)
    assert len(parts) > 1 and max(len(part) for part in parts) <= 400
    for part in parts:
        assert part.times[0] == 0.0 and not np.any(part.velocities[[0, -1]])
    joined = concatenate(parts)
    assert np.array_equal(joined.positions, follow.positions) and np.allclose(joined.times, follow.times)
    assert rest_parts(follow, len(follow)) == [follow]
