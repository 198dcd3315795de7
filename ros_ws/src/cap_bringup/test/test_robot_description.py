"""The URDF written from the simulator's model moves like the model: its joints are the model's, and its chain
from the world to the flange is the UR5e's DH chain (cap_control.kinematics) at any joint angles."""
from __future__ import annotations

import math
import xml.etree.ElementTree as ElementTree

import mujoco
import numpy as np
import pytest
from cap_mobile.robot import BASE_JOINT_NAMES

from cap_control.kinematics import forward_kinematics
from cap_sim_bridge.scenes import build_model
from cap_sim_bridge.urdf import robot_urdf, rpy_of_quaternion
from cap_sim_bridge.world import ARM_JOINT_NAMES, GRIPPER_JOINT_NAMES


@pytest.fixture(scope='module')
def urdf() -> ElementTree.Element:
    return ElementTree.fromstring(robot_urdf(build_model([])))


def _rotation(roll: float, pitch: float, yaw: float) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = (f(a) for a in (roll, pitch, yaw) for f in (math.cos, math.sin))
    return (np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]]) @ np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
            @ np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]]))


def _axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    x, y, z = axis / np.linalg.norm(axis)
    k = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def _link_pose(urdf: ElementTree.Element, link: str, positions: dict[str, float]) -> np.ndarray:
    """The world pose of `link` by the URDF's joints, as robot_state_publisher computes it."""
    by_child = {joint.find('child').get('link'): joint for joint in urdf.findall('joint')}
    chain = []
    while link in by_child:
        chain.append(by_child[link])
        link = by_child[link].find('parent').get('link')
    pose = np.eye(4)
    for joint in reversed(chain):
        origin = joint.find('origin')
        step = np.eye(4)
        step[:3, :3] = _rotation(*map(float, origin.get('rpy').split()))
        step[:3, 3] = [float(v) for v in origin.get('xyz').split()]
        motion = np.eye(4)
        value = positions.get(joint.get('name'), 0.0)
        if joint.get('type') in ('revolute', 'continuous'):
            motion[:3, :3] = _axis_angle(np.array([float(v) for v in joint.find('axis').get('xyz').split()]), value)
        elif joint.get('type') == 'prismatic':
            motion[:3, 3] = value * np.array([float(v) for v in joint.find('axis').get('xyz').split()])
        pose = pose @ step @ motion
    return pose


def test_the_urdf_names_the_joints_the_simulator_publishes(urdf):
    moving = [joint.get('name') for joint in urdf.findall('joint') if joint.get('type') != 'fixed']
    assert moving == list(ARM_JOINT_NAMES + GRIPPER_JOINT_NAMES)
    assert urdf.find("link[@name='world']") is not None
    assert all(link.find('visual') is not None for link in urdf.findall('link') if link.get('name').endswith('_link'))


@pytest.mark.parametrize('seed', range(5))
def test_the_urdf_chain_is_the_dh_chain_of_the_ur5e(urdf, seed):
    q = np.random.default_rng(seed).uniform(-math.pi, math.pi, 6)
    flange = _link_pose(urdf, 'flange', dict(zip(ARM_JOINT_NAMES, q)))
    assert np.allclose(flange, forward_kinematics(q, tool_offset=0.0), atol=1e-5)


@pytest.mark.parametrize('seed', range(3))
def test_the_mobile_manipulators_urdf_moves_its_flange_where_the_simulator_does(seed):
    """The kitchen's base joints (x, y and a yaw about the base's centre, off the arm's root frame) as a chain."""
    model = build_model([], 'mobile')
    urdf = ElementTree.fromstring(robot_urdf(model))
    rng = np.random.default_rng(seed)
    positions = dict(zip(BASE_JOINT_NAMES, [*rng.uniform(-2, 2, 2), rng.uniform(-math.pi, math.pi)]))
    positions.update(zip(ARM_JOINT_NAMES, rng.uniform(-math.pi, math.pi, 6)))
    data = mujoco.MjData(model)
    for name, value in positions.items():
        data.qpos[model.jnt_qposadr[model.joint(name).id]] = value
    mujoco.mj_kinematics(model, data)
    expected = np.eye(4)
    expected[:3, :3], expected[:3, 3] = data.body('flange').xmat.reshape(3, 3), data.body('flange').xpos
    assert np.allclose(_link_pose(urdf, 'flange', positions), expected, atol=1e-4)  # URDF's 6 digits
    moving = [joint.get('name') for joint in urdf.findall('joint') if joint.get('type') != 'fixed']
    assert moving[:3] == list(BASE_JOINT_NAMES)


def test_rpy_of_a_quaternion():
    half = math.sqrt(0.5)
    assert np.allclose(rpy_of_quaternion([half, half, 0, 0]), [math.pi / 2, 0, 0])
    assert np.allclose(rpy_of_quaternion([half, 0, 0, half]), [0, 0, math.pi / 2])
