"""The links' poses computed from the URDF and joint positions (what /tf carries) are where the simulator has its
bodies: every link, any joint angles, the fixed arm and the mobile manipulator (whose base_link pose in odom is its
base joints' values)."""
from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cap_sim_bridge.robot_state import RobotState, urdf_joints
from cap_sim_bridge.scenes import build_model
from cap_sim_bridge.urdf import BASE_LINK, WORLD_LINK, base_joint_names, robot_urdf
from cap_sim_bridge.world import ARM_JOINT_NAMES, GRIPPER_JOINT_NAMES


def _body_pose(data: mujoco.MjData, name: str) -> np.ndarray:
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = data.body(name).xmat.reshape(3, 3), data.body(name).xpos
    return pose


@pytest.mark.parametrize('scene', ['tabletop', 'mobile'])
@pytest.mark.parametrize('seed', range(3))
def test_every_link_is_where_the_simulator_has_its_body(scene, seed):
    model = build_model([], scene)
    state = RobotState(robot_urdf(model))
    rng = np.random.default_rng(seed)
    positions = dict(zip(ARM_JOINT_NAMES, rng.uniform(-math.pi, math.pi, 6)))
    positions.update(zip(GRIPPER_JOINT_NAMES, rng.uniform(0.0, 0.04, 2)))
    base = base_joint_names(model)
    base_pose = [*rng.uniform(-2, 2, 2), rng.uniform(-math.pi, math.pi)] if base else []
    data = mujoco.MjData(model)
    for name, value in [*positions.items(), *zip(base, base_pose)]:
        data.qpos[model.jnt_qposadr[model.joint(name).id]] = value
    mujoco.mj_kinematics(model, data)
    if base:  # odom -> base_link, as the simulator sends it (odom and map are the world here)
        root = np.eye(4)
        root[:3, :3] = Rotation.from_euler('z', base_pose[2]).as_matrix()
        root[:3, 3] = [base_pose[0], base_pose[1], 0.0]
        poses = {link: root @ pose for link, pose in state.link_poses(positions, BASE_LINK).items()}
    else:
        poses = state.link_poses(positions, WORLD_LINK)
    links = [link for link in poses if link not in (WORLD_LINK, BASE_LINK)]
    assert {'base', 'shoulder_link', 'wrist_3_link', 'flange', 'left_finger'} <= set(links)
    for link in links:
        error = np.linalg.norm(poses[link][:3, 3] - _body_pose(data, link)[:3, 3])
        assert error < 1e-4, f'{link} is {error * 1000:.3f} mm off'  # URDF's six digits
        assert np.allclose(poses[link][:3, :3], _body_pose(data, link)[:3, :3], atol=1e-4)


def test_fixed_joints_go_to_tf_static_and_moving_ones_to_tf():
    state = RobotState(robot_urdf(build_model([])))
    fixed = state.fixed_transforms()
    assert (WORLD_LINK, 'base') in {(t.parent, t.child) for t in fixed}
    moving = state.moving_transforms(['shoulder_pan_joint', 'not_in_the_urdf'], [0.5, 1.0], stamp=2.0)
    assert [(t.parent, t.child, t.stamp) for t in moving] == [('base', 'shoulder_link', 2.0)]
    assert state.moving_joint_names == list(ARM_JOINT_NAMES + GRIPPER_JOINT_NAMES)


def test_a_joint_type_that_is_not_modelled_is_refused():
    with pytest.raises(ValueError, match="type 'floating' is not modelled"):
        urdf_joints('<robot name="r"><link name="a"/><link name="b"/><joint name="j" type="floating">'
                    '<parent link="a"/><child link="b"/></joint></robot>')
