"""What a twin watches for (cap_sim_bridge/twin_watch.py), on MuJoCo worlds: a scene at rest is no harm; an object
pushed, knocked over or off its surface is; the arm driven into the table is; and a twin starts where the robot is
(the arm's joints, a block standing on another, an object turned)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from cap_sim_bridge.objects import ObjectSpec
from cap_sim_bridge.twin_watch import TwinWatch
from cap_sim_bridge.world import World

SCENE = [ObjectSpec.from_name('red block', (0.0, -0.5)), ObjectSpec.from_name('blue block', (0.12, -0.45)),
         ObjectSpec.from_name('green bowl', (-0.12, -0.6))]


def _watch_for(world: World, seconds: float) -> TwinWatch:
    watch = TwinWatch(world)
    watch.start()
    _run(world, watch, seconds)
    return watch


def _run(world: World, watch: TwinWatch, seconds: float) -> None:
    for _ in range(int(seconds / (10 * world.timestep))):
        with world.lock:
            world.step(10)
            watch.update()


@pytest.fixture(scope='module')
def world() -> World:
    built = World('tabletop', 0, SCENE)
    yield built
    built.close()


def _velocity(world: World, name: str, linear=(0.0, 0.0, 0.0), angular=(0.0, 0.0, 0.0)) -> None:
    model = world.model
    adr = model.jnt_dofadr[model.body_jntadr[world._object_body_ids[name]]]
    world.data.qvel[adr:adr + 3] = linear
    world.data.qvel[adr + 3:adr + 6] = angular


def test_a_scene_at_rest_is_no_harm(world):
    world.reset(0, SCENE)
    watch = _watch_for(world, 1.0)
    watch.finish()
    assert watch.findings() == []


def test_an_object_nothing_held_that_moves_was_pushed(world):
    world.reset(0, SCENE)
    watch = TwinWatch(world)
    watch.start()
    _velocity(world, 'green bowl', linear=(0.8, 0.0, 0.0))
    _run(world, watch, 1.0)
    assert len(watch.findings()) == 1, watch.findings()
    assert watch.findings()[0].startswith('the green bowl was pushed ')
    assert watch.findings()[0].endswith(' cm (the gripper never held it)')


def test_an_object_left_on_an_edge_topples_and_that_is_harm(world):
    # A twin built as a block stands half over another's edge: the moment it starts, the top one tips off.
    world.reset(0, [ObjectSpec.from_name('red block', (0.0, -0.5)),
                    ObjectSpec('blue block', 'block', 'blue', (0.032, -0.5), height=0.061)], settle_time=0.0)
    watch = TwinWatch(world)
    watch.start()
    _run(world, watch, 1.5)
    watch.finish()
    assert any(text.startswith('the blue block ') and text.endswith('(the gripper never held it)')
               and ('fell' in text or 'knocked over' in text or 'leaning' in text) for text in watch.findings()), \
        watch.findings()


def test_an_object_that_falls_off_the_table_fell(world):
    world.reset(0, [ObjectSpec.from_name('red block', (0.27, -0.5))])
    watch = TwinWatch(world)
    watch.start()
    _velocity(world, 'red block', linear=(1.0, 0.0, 0.0))
    _run(world, watch, 1.5)
    assert watch.findings() == ['the red block fell off where it stood (the gripper never held it)']


def test_the_arm_driven_into_the_table_hit_it(world):
    world.reset(0, SCENE)
    watch = TwinWatch(world)
    watch.start()
    start = world.joint_positions()
    down = start + np.array([0.0, 1.5, 0.0, 0.0, 0.0, 0.0])  # the shoulder swung down: the hand meets the table
    world.follow_trajectory([0.0, 2.0], [start, down])
    _run(world, watch, 2.5)
    assert any(' hit the table at (' in text for text in watch.findings()), watch.findings()


def test_a_twin_starts_where_the_robot_is(world):
    joints = world.joint_positions() + np.array([0.3, -0.1, 0.1, 0.0, 0.0, 0.2])
    states = world.reset(0, [ObjectSpec.from_name('red block', (0.0, -0.5)),
                             ObjectSpec('blue block', 'block', 'blue', (0.0, -0.5), height=0.06, yaw=0.4)],
                         arm_joints=joints)
    by_name = {state.name: state for state in states}
    assert by_name['blue block'].position[2] == pytest.approx(0.06, abs=0.003)  # standing on the red block
    x, y, z, w = by_name['blue block'].orientation_xyzw
    assert 2 * math.atan2(z, w) == pytest.approx(0.4, abs=0.02)
    assert np.allclose(world.joint_positions(), joints, atol=0.01)
    with pytest.raises(ValueError, match='outside their limits'):
        world.reset(0, SCENE, arm_joints=[10.0] * 6)


def test_objects_a_twin_is_given_into_each_other_become_ghosts(world):
    # Perception reported the yellow block twice (once as a gray one) and a gray bowl around a line of blocks.
    line = [ObjectSpec.from_name(f'{colour} block', (x, -0.7)) for colour, x in (('red', -0.04), ('blue', 0.0),
                                                                                    ('green', 0.04))]
    states = world.reset(0, [ObjectSpec.from_name('yellow block', (0.2, -0.5)),
                             ObjectSpec('gray block', 'block', 'gray', (0.205, -0.5), height=0.02), *line,
                             ObjectSpec.from_name('gray bowl', (0.0, -0.7)),
                             ObjectSpec.from_name('purple bowl', (-0.15, -0.45)),
                             ObjectSpec.from_name('pink block', (-0.15, -0.45))],  # a block in a bowl: no ghost
                         ghost_overlaps=True)
    ghosts = {spec.name for spec in world.objects if not spec.solid}
    assert ghosts == {'gray block', 'gray bowl'}
    watch = _watch_for(world, 1.0)
    watch.finish()
    assert watch.findings() == []  # nothing was thrown apart
    before = {state.name: state.position for state in states}
    after = {state.name: state.position for state in world.object_states()}
    assert all(np.linalg.norm(np.subtract(after[name], before[name])) < 0.005 for name in before)
