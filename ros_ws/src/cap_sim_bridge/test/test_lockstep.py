"""Lockstep stepping (the ControlStep service's logic) on the controllers scene: the first step takes the plant over,
every step advances exactly its duration, and a release or a silent controller leaves the plant safe."""
from __future__ import annotations

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
