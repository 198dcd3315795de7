"""Lockstep stepping (the ControlStep service's logic) on the controllers scene: a start puts the plant at its defined
start (or says why it cannot) and takes it over, every step advances exactly its duration, and a release or a silent
controller leaves the plant safe."""
from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest

from cap_controllers import plants
from cap_sim_bridge.scenes import controllers as controller_scene
from cap_sim_bridge.lockstep import Lockstep
from cap_sim_bridge.world import World


@pytest.fixture(scope='module')
def world():
    world = World(controller_scene.NAME, seed=4)
    yield world
    world.close()


def test_the_cartpole_is_held_until_a_controller_takes_it_over(world):
    world.reset(4)
    x, _, theta, _ = controller_scene.initial_cartpole_state(4)
    world.run_for(2.0)
    (held_x, held_theta), _ = world.joint_state(plants.CARTPOLE_JOINTS)
    assert held_x == pytest.approx(x, abs=1e-6) and held_theta == pytest.approx(theta, abs=1e-6)
    lockstep = Lockstep(world, 0.0, timeout_s=1.0)
    start, *_ = lockstep.step(plants.CARTPOLE_JOINTS, [plants.CART_ACTUATOR], [], 0.0)
    now, positions, velocities, applied = lockstep.step(plants.CARTPOLE_JOINTS, [plants.CART_ACTUATOR], [2.0], 0.5)
    assert now - start == pytest.approx(0.5)
    assert applied.tolist() == [2.0] and velocities[0] > 0  # the motor pushed the cart towards +x
    assert abs(positions[1]) > abs(theta)  # let go of, the pole falls further
    assert lockstep.release()
    assert world.controls([plants.CART_ACTUATOR]).tolist() == [0.0] and not lockstep.active


def test_the_arm_is_torque_controlled_while_stepped_and_holds_when_released(world):
    world.reset(4)
    lockstep = Lockstep(world, 0.0, timeout_s=1.0)
    lockstep.step(plants.ARM_JOINTS, plants.ARM_ACTUATORS, [], 0.0)
    assert world.arm_torque_mode
    with pytest.raises(ValueError, match='already drives'):
        lockstep.step(plants.CARTPOLE_JOINTS, [plants.CART_ACTUATOR], [1.0], 0.01)
    with pytest.raises(ValueError, match='efforts'):
        lockstep.step(plants.ARM_JOINTS, plants.ARM_ACTUATORS, [0.0, float('nan'), 0, 0, 0, 0], 0.01)
    lockstep.step(plants.ARM_JOINTS, plants.ARM_ACTUATORS, [0.0, 0.0, 0.0, 0.0, 0.0, 0.0], 0.1)
    assert not lockstep.expired()
    time.sleep(0.05)
    lockstep.timeout_s = 0.01
    assert lockstep.expired()
    assert lockstep.release() and not world.arm_torque_mode
    before = world.tcp_pose()[:3, 3]
    world.run_for(1.0)
    assert np.linalg.norm(world.tcp_pose()[:3, 3] - before) < 0.002  # the servos hold it where it was


def test_unknown_names_are_refused(world):
    lockstep = Lockstep(world, 0.0, timeout_s=1.0)
    with pytest.raises(ValueError, match='unknown joint or actuator'):
        lockstep.step(['no_such_joint'], [], [], 0.0)
    assert not lockstep.active


def test_the_scene_names_its_own_joints(world):
    assert world.scene_joint_names() == list(plants.CARTPOLE_JOINTS)


def test_a_start_puts_a_fallen_cartpole_back_at_its_seeded_start_held_until_taken_over(world):
    world.reset(4)
    lockstep = Lockstep(world, 0.0, timeout_s=1.0)
    lockstep.start(plants.CARTPOLE_JOINTS, [plants.CART_ACTUATOR])
    lockstep.step(plants.CARTPOLE_JOINTS, [plants.CART_ACTUATOR], [3.0], 1.0)
    assert lockstep.release()
    world.run_for(2.0)  # the motor idle, the pole falls
    (x, theta), _ = world.joint_state(plants.CARTPOLE_JOINTS)
    assert abs(theta) > 0.5
    before = world.time
    now, positions, velocities, applied = lockstep.start(plants.CARTPOLE_JOINTS, [plants.CART_ACTUATOR])
    start_x, _, start_theta, _ = controller_scene.initial_cartpole_state(4)
    assert positions.tolist() == pytest.approx([start_x, start_theta], abs=1e-12)
    assert velocities.tolist() == [0.0, 0.0] and applied.tolist() == [0.0]
    assert now == before and lockstep.active  # no time passed: the controller sees the start itself
    with pytest.raises(ValueError, match='already drives'):
        lockstep.start(plants.CARTPOLE_JOINTS, [plants.CART_ACTUATOR])
    lockstep.release()


def test_a_start_brings_the_arm_to_rest_on_its_servos_or_says_why_it_cannot(world):
    world.reset(4)
    lockstep = Lockstep(world, 0.0, timeout_s=1.0)
    lockstep.start(plants.ARM_JOINTS, plants.ARM_ACTUATORS)
    lockstep.step(plants.ARM_JOINTS, plants.ARM_ACTUATORS, [20.0, 0.0, 0.0, 0.0, 0.0, 0.0], 0.2)
    lockstep.release()
    assert np.max(np.abs(world.joint_velocities())) > 0.1  # released while it swung
    lockstep.settle_limit_s = 0.0
    with pytest.raises(ValueError, match='did not come to rest on its servos within 0 s'):
        lockstep.start(plants.ARM_JOINTS, plants.ARM_ACTUATORS)
    assert not lockstep.active and not world.arm_torque_mode  # refused: held on its servos, nothing taken over
    lockstep.settle_limit_s = plants.ARM_SETTLE_LIMIT_S
    _, _, velocities, _ = lockstep.start(plants.ARM_JOINTS, plants.ARM_ACTUATORS)
    assert np.max(np.abs(velocities)) < plants.ARM_REST_SPEED and world.arm_torque_mode
    lockstep.release()


def test_a_scene_without_a_defined_start_for_its_joints_refuses_to_start_them(world):
    world.reset(4)
    scene = world.scene
    world.scene = dataclasses.replace(scene, restart_plant=None)
    try:
        lockstep = Lockstep(world, 0.0, timeout_s=1.0)
        with pytest.raises(ValueError, match="the scene 'controllers' cannot put its own joints back"):
            lockstep.start(plants.CARTPOLE_JOINTS, [plants.CART_ACTUATOR])
        assert not lockstep.active
        world.run_for(1.0)
        (x, theta), _ = world.joint_state(plants.CARTPOLE_JOINTS)
        assert theta == pytest.approx(controller_scene.initial_cartpole_state(4)[2], abs=1e-6)  # still held
    finally:
        world.scene = scene
