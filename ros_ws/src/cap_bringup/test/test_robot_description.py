"""The URDF written from the simulator's model moves like the model: its joints are the model's, and its chain
from the world to the flange is the UR5e's DH chain (cap_control.kinematics) at any joint angles."""
from __future__ import annotations

import math
import xml.etree.ElementTree as ElementTree

import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from cap_mobile.robot import BASE_JOINT_NAMES

from cap_control.kinematics import forward_kinematics
from cap_sim_bridge.scenes import build_model
from cap_sim_bridge.robot_state import RobotState
from cap_sim_bridge.urdf import BASE_LINK, WORLD_LINK, robot_urdf, rpy_of_quaternion
from cap_sim_bridge.world import ARM_JOINT_NAMES, GRIPPER_JOINT_NAMES


@pytest.fixture(scope='module')
def urdf() -> ElementTree.Element:
    return ElementTree.fromstring(robot_urdf(build_model([])))


def _link_pose(urdf: ElementTree.Element, link: str, positions: dict[str, float], root: str = WORLD_LINK) -> np.ndarray:
    """The pose of `link` in `root` by the URDF's joints, as robot_state_publisher computes it."""
    return RobotState(ElementTree.tostring(urdf, encoding='unicode')).link_poses(positions, root)[link]


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
    """The URDF hangs from base_link (the base's centre on the floor); base_link's pose in the world is the base
    joints' values (x, y and a yaw about the base's centre), which the simulator sends as odom -> base_link."""
    model = build_model([], 'mobile')
    urdf = ElementTree.fromstring(robot_urdf(model))
    rng = np.random.default_rng(seed)
    base = [*rng.uniform(-2, 2, 2), rng.uniform(-math.pi, math.pi)]
    positions = dict(zip(ARM_JOINT_NAMES, rng.uniform(-math.pi, math.pi, 6)))
    data = mujoco.MjData(model)
    for name, value in [*positions.items(), *zip(BASE_JOINT_NAMES, base)]:
        data.qpos[model.jnt_qposadr[model.joint(name).id]] = value
    mujoco.mj_kinematics(model, data)
    expected = np.eye(4)
    expected[:3, :3], expected[:3, 3] = data.body('flange').xmat.reshape(3, 3), data.body('flange').xpos
    base_link = np.eye(4)
    base_link[:3, :3] = Rotation.from_euler('z', base[2]).as_matrix()
    base_link[:3, 3] = [base[0], base[1], 0.0]
    flange = base_link @ _link_pose(urdf, 'flange', positions, BASE_LINK)
    assert np.allclose(flange, expected, atol=1e-4)  # URDF's six digits
    assert urdf.find('link').get('name') == BASE_LINK
    assert not {joint.get('name') for joint in urdf.findall('joint')} & set(BASE_JOINT_NAMES)


def test_rpy_of_a_quaternion():
    half = math.sqrt(0.5)
    assert np.allclose(rpy_of_quaternion([half, half, 0, 0]), [math.pi / 2, 0, 0])
    assert np.allclose(rpy_of_quaternion([half, 0, 0, half]), [0, 0, math.pi / 2])
