"""Our UR5e forward kinematics agrees with MuJoCo's on the simulator's own arm model (site "tcp")."""
import mujoco
import numpy as np
import pytest
from cap_sim_bridge.scenes import MODELS_DIR
from cap_tabletop.workspace import TABLE_X_RANGE, TABLE_Y_RANGE

from cap_control.kinematics import JOINT_LOWER, JOINT_NAMES, JOINT_UPPER, forward_kinematics, inverse_kinematics, \
    top_down_pose

SCENE = MODELS_DIR / 'tabletop.xml'


@pytest.fixture(scope='module')
def sim():
    model = mujoco.MjModel.from_xml_path(str(SCENE))
    data = mujoco.MjData(model)
    addresses = [model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)] for name in JOINT_NAMES]
    tcp = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, 'tcp')
    assert tcp >= 0, 'the arm model has no site "tcp"'
    return model, data, addresses, tcp


def mujoco_tcp_pose(sim, q: np.ndarray) -> np.ndarray:
    model, data, addresses, tcp = sim
    data.qpos[addresses] = q
    mujoco.mj_kinematics(model, data)
    pose = np.eye(4)
    pose[:3, :3] = data.site_xmat[tcp].reshape(3, 3)
    pose[:3, 3] = data.site_xpos[tcp]
    return pose


def test_forward_kinematics_matches_mujoco_over_random_joint_vectors(sim):
    rng = np.random.default_rng(2024)
    for _ in range(500):
        q = rng.uniform(JOINT_LOWER, JOINT_UPPER)
        np.testing.assert_allclose(forward_kinematics(q), mujoco_tcp_pose(sim, q), atol=1e-6)


def test_ik_solutions_put_the_simulated_tcp_on_the_table_targets(sim):
    rng = np.random.default_rng(7)
    for _ in range(100):
        target = top_down_pose((rng.uniform(*TABLE_X_RANGE), rng.uniform(*TABLE_Y_RANGE), rng.uniform(0.02, 0.3)),
                               rng.uniform(-np.pi, np.pi))
        np.testing.assert_allclose(mujoco_tcp_pose(sim, inverse_kinematics(target)), target, atol=1e-6)
