"""The table-top world's scenes: spawn rules, settling, determinism, ground truth and the model's kinematics."""
import itertools
import math

import mujoco
import numpy as np
import pytest

from cap_sim_bridge import objects as scene
from cap_sim_bridge.objects import ObjectSpec
from cap_tabletop import palette, workspace
from cap_sim_bridge.world import ARM_JOINT_NAMES, TCP_OFFSET, World

# Settled objects may drift a little from their sampled spot while contacts come to rest.
DRIFT = 0.003
# MuJoCo contacts are soft: a resting object sinks by a fraction of a millimetre; more than this is overlap.
MAX_PENETRATION = 0.001

# Universal Robots' published UR5e DH parameters (a, d, alpha).
UR5E_DH = [(0.0, 0.1625, math.pi / 2), (-0.425, 0.0, 0.0), (-0.3922, 0.0, 0.0), (0.0, 0.1333, math.pi / 2),
           (0.0, 0.0997, -math.pi / 2), (0.0, 0.0996, 0.0)]


def dh_forward_kinematics(q):
    pose = np.eye(4)
    for (a, d, alpha), theta in zip(UR5E_DH, q):
        ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
        pose = pose @ np.array([[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st],
                                [0, sa, ca, d], [0, 0, 0, 1]])
    return pose


@pytest.fixture(scope='module')
def world():
    return World()


def test_200_seeds_spawn_by_the_rules_and_settle_on_the_table(world):
    for seed in range(200):
        states = world.reset(seed)
        expected = scene.default_objects(seed)
        assert [s.name for s in states] == [e.name for e in expected]
        blocks = [s for s in states if s.category == 'block']
        bowls = [s for s in states if s.category == 'bowl']
        assert 3 <= len(blocks) <= 4 and 3 <= len(bowls) <= 4, seed
        for state in states:
            x, y, _ = state.position
            assert workspace.SPAWN_X_RANGE[0] - DRIFT <= x <= workspace.SPAWN_X_RANGE[1] + DRIFT, (seed, state)
            assert workspace.SPAWN_Y_RANGE[0] - DRIFT <= y <= workspace.SPAWN_Y_RANGE[1] + DRIFT, (seed, state)
            # On the table: inside its bounds, resting on its surface, upright.
            (x_min, x_max), (y_min, y_max) = workspace.TABLE_X_RANGE, workspace.TABLE_Y_RANGE
            assert state.bbox_min[0] >= x_min and state.bbox_max[0] <= x_max, (seed, state)
            assert state.bbox_min[1] >= y_min and state.bbox_max[1] <= y_max, (seed, state)
            assert abs(state.bbox_min[2]) < MAX_PENETRATION, (seed, state)
            assert state.orientation_xyzw[3] > 0.9999, (seed, state)
        for a, b in itertools.combinations(states, 2):
            assert math.dist(a.position[:2], b.position[:2]) >= workspace.SPAWN_MIN_SEPARATION - 2 * DRIFT, (seed, a, b)
        depth, geom_a, geom_b = world.deepest_object_penetration()
        assert depth < MAX_PENETRATION, (seed, geom_a, geom_b, depth)
        assert max(world.object_speeds().values()) < 1e-3, seed


def test_the_same_seed_gives_the_same_scene_and_another_seed_another(world):
    first = world.reset(7)
    world.run_for(0.3)
    again = world.reset(7)
    assert again == first
    assert world.reset(8) != first


def test_given_objects_and_positions_are_placed_and_names_become_specs(world):
    states = world.reset(1, [ObjectSpec('red block', 'block', 'red', (0.1, -0.4)), 'blue bowl', 'gray block'])
    assert [s.name for s in states] == ['red block', 'blue bowl', 'gray block']
    red = states[0]
    assert red.position[0] == pytest.approx(0.1, abs=DRIFT) and red.position[1] == pytest.approx(-0.4, abs=DRIFT)
    assert red.rgba == pytest.approx((1.0, 87 / 255, 89 / 255, 1.0))
    # A block is a 4 cm cube resting on the table; a bowl is about 13 cm across.
    assert np.subtract(red.bbox_max, red.bbox_min) == pytest.approx([0.04, 0.04, 0.04], abs=1e-3)
    assert red.position[2] == pytest.approx(0.02, abs=1e-3)
    bowl = states[1]
    assert 0.12 <= bowl.bbox_max[0] - bowl.bbox_min[0] <= 0.15


@pytest.mark.parametrize('bad', [['violet block'], ['red cup'], ['red block', 'red block']])
def test_unknown_colours_categories_and_duplicates_are_refused_with_the_reason(world, bad):
    with pytest.raises(ValueError, match='unknown colour|unknown category|unique'):
        world.reset(0, bad)


def test_impossible_layouts_are_refused():
    specs = [ObjectSpec.from_name(f'{c} block') for c in palette.PALETTE]
    with pytest.raises(ValueError, match='no layout'):
        scene.sample_spawn_positions(specs, 0, max_restarts=5)


def test_arm_kinematics_equal_the_published_dh_chain_and_tcp_is_15_cm_along_flange_z(world):
    rng = np.random.default_rng(0)
    model, data = world.model, world.data
    assert [model.joint(n).name for n in ARM_JOINT_NAMES] == list(ARM_JOINT_NAMES)
    for _ in range(20):
        q = rng.uniform(-math.pi, math.pi, 6)
        data.qpos[[model.joint(n).qposadr[0] for n in ARM_JOINT_NAMES]] = q
        mujoco.mj_kinematics(model, data)
        expected = dh_forward_kinematics(q)
        np.testing.assert_allclose(world.flange_pose(), expected, atol=1e-9)
        tool = expected @ np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, TCP_OFFSET], [0, 0, 0, 1]])
        np.testing.assert_allclose(world.tcp_pose(), tool, atol=1e-9)
    world.reset(0)


def test_arm_masses_and_limits_are_the_published_ones(world):
    model = world.model
    masses = [model.body(n).mass[0] for n in ('shoulder_link', 'upper_arm_link', 'forearm_link', 'wrist_1_link',
                                              'wrist_2_link', 'wrist_3_link')]
    assert masses == pytest.approx([3.761, 8.058, 2.846, 1.37, 1.3, 0.365])
    limits = [model.joint(n).range for n in ARM_JOINT_NAMES]
    assert [hi for _, hi in limits] == pytest.approx([2 * math.pi, 2 * math.pi, math.pi] + [2 * math.pi] * 3,
                                                      abs=1e-5)
