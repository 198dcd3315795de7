"""Ink on the whiteboard: laid where the marker's tip touches the board in the physics, wiped where the eraser does,
with paths planned by cap_control.follow_path.plan and run in the MuJoCo world."""
import numpy as np
import pytest

from cap_control.follow_path.plan import plan_path
from cap_sim_bridge.world import World
from cap_whiteboard import board


def _follow(world, plan):
    for step in plan.steps:
        if len(step.trajectory) > 1:
            world.follow_trajectory(step.trajectory.times[1:], step.trajectory.positions[1:],
                                    step.trajectory.velocities[1:])
            world.run_for(step.trajectory.duration + 0.05)


@pytest.fixture(scope='module')
def world():
    return World('whiteboard', seed=0, objects=['red block'])


def test_the_ink_is_where_the_tip_touched_the_board_not_where_it_was_sent(world):
    world.reset(0, ['red block'])
    line = np.array([[-0.15, -0.6], [0.1, -0.6]])
    # Without touching: the same path held 9 cm above the board leaves no ink.
    _follow(world, plan_path(world.joint_positions(), [line], 'none'))
    assert world.ink_canvas.image().sum() == 0
    _follow(world, plan_path(world.joint_positions(), [line], 'marker'))
    ink = world.ink_canvas.image()
    rows, cols = np.nonzero(ink)
    y = board.Y_RANGE[1] - (rows + 0.5) * board.INK_RESOLUTION
    assert np.all(np.abs(y + 0.6) <= 0.0025)
    assert cols.min() * 0.001 - 0.25 == pytest.approx(-0.15, abs=0.003)
    assert (cols.max() + 1) * 0.001 - 0.25 == pytest.approx(0.1, abs=0.003)
    # The camera sees it: the board's texture shows the ink.
    top = world.render('top', 320, 240, with_depth=False)[0].astype(int)
    assert (top.sum(axis=2) < 300).sum() > 30
    # The eraser wipes it off, and a reset leaves a clean board.
    _follow(world, plan_path(world.joint_positions(), [line], 'eraser'))
    assert world.ink_canvas.image().sum() == 0
    _follow(world, plan_path(world.joint_positions(), [line], 'marker'))
    world.reset(0, ['red block'])
    assert world.ink_canvas.image().sum() == 0
