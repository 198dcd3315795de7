"""The arm follows timed joint trajectories accurately, stops when told, and the gripper opens, closes and squeezes."""
import math

import numpy as np
import pytest

from cap_sim_bridge.objects import ObjectSpec
from cap_sim_bridge.trajectory import JointTrajectory
from cap_sim_bridge.world import GRIPPER_MAX_OPENING, HOME_JOINT_POSITIONS, TCP_OFFSET, World

UR5E_DH = [(0.0, 0.1625, math.pi / 2), (-0.425, 0.0, 0.0), (-0.3922, 0.0, 0.0), (0.0, 0.1333, math.pi / 2),
           (0.0, 0.0997, -math.pi / 2), (0.0, 0.0996, 0.0)]


def tcp_forward_kinematics(q):
    """Universal Robots' DH chain followed by the 0.15 m tool offset."""
    pose = np.eye(4)
    for (a, d, alpha), theta in zip(UR5E_DH, q):
        ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
        pose = pose @ np.array([[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st],
                                [0, sa, ca, d], [0, 0, 0, 1]])
    tool = np.eye(4)
    tool[2, 3] = TCP_OFFSET
    return pose @ tool


def reachable_goals(count, seed=0):
    """Joint goals around the home pose whose gripper stays well above the table and away from the robot base."""
    rng = np.random.default_rng(seed)
    goals = []
    while len(goals) < count:
        q = HOME_JOINT_POSITIONS + rng.uniform(-0.6, 0.6, 6)
        pose = tcp_forward_kinematics(q)
        if pose[2, 3] > 0.12 and math.hypot(pose[0, 3], pose[1, 3]) > 0.3:
            goals.append(q)
    return goals


@pytest.fixture(scope='module')
def world():
    return World(objects=['red block', 'blue bowl'])


@pytest.mark.parametrize('with_velocities', [False, True])
def test_trajectories_end_within_2_mm_of_the_goal_pose(world, with_velocities):
    for goal in reachable_goals(6, seed=int(with_velocities)):
        world.reset(0, ['red block', 'blue bowl'])
        start = world.joint_positions()
        middle = (start + goal) / 2
        velocities = [(goal - start) / 2.0, np.zeros(6)] if with_velocities else None
        end_time = world.follow_trajectory([1.0, 2.0], [middle, goal], velocities)
        world.run_for(end_time - world.time + 0.5)
        error = np.linalg.norm(world.tcp_pose()[:3, 3] - tcp_forward_kinematics(goal)[:3, 3])
        assert error < 0.002, (goal, error)
        assert world.trajectory_end_time is None


def test_a_move_does_not_overshoot_its_goal(world):
    world.reset(0, ['red block', 'blue bowl'])
    start = world.joint_positions()
    goal = start + np.array([0.5, -0.3, 0.4, 0.5, -0.5, 0.8])
    world.follow_trajectory([1.5], [goal])
    beyond = np.zeros(6)
    for _ in range(200):
        world.step(5)
        beyond = np.maximum(beyond, (world.joint_positions() - goal) * np.sign(goal - start))
    assert np.all(beyond < 0.002), beyond


def test_hold_stops_the_arm_where_it_is(world):
    world.reset(0, ['red block', 'blue bowl'])
    goal = world.joint_positions() + 0.8
    goal[2] = world.joint_positions()[2] - 0.4
    world.follow_trajectory([2.0], [goal])
    world.run_for(0.8)
    world.hold()
    stopped_at = world.joint_positions()
    world.run_for(1.0)
    assert np.abs(world.joint_positions() - stopped_at).max() < 0.01
    assert np.abs(world.joint_positions() - goal).min() > 0.2
    assert world.trajectory_end_time is None


def test_a_new_trajectory_replaces_the_running_one_without_a_jump(world):
    world.reset(0, ['red block', 'blue bowl'])
    first = world.joint_positions() + 0.6
    world.follow_trajectory([2.0], [first])
    world.run_for(1.0)
    reference_before, _ = world.reference()
    second = world.joint_positions() - 0.3
    world.follow_trajectory([1.0], [second])
    reference_after, _ = world.reference()
    np.testing.assert_allclose(reference_after, reference_before, atol=1e-9)
    world.run_for(1.5)
    assert np.abs(world.joint_positions() - second).max() < 0.002


@pytest.mark.parametrize('times, positions, match', [
    ([1.0, 0.5], [HOME_JOINT_POSITIONS, HOME_JOINT_POSITIONS], 'increase'),
    ([1.0], [HOME_JOINT_POSITIONS[:5]], 'shape'),
    ([1.0], [HOME_JOINT_POSITIONS + [0, 0, 4.0, 0, 0, 0]], 'joint limits'),
    ([-1.0], [HOME_JOINT_POSITIONS], 'from now'),
])
def test_malformed_trajectories_are_refused_and_the_arm_stays(world, times, positions, match):
    world.reset(0, ['red block', 'blue bowl'])
    with pytest.raises(ValueError, match=match):
        world.follow_trajectory(times, positions)
    world.run_for(0.5)
    assert np.abs(world.joint_positions() - HOME_JOINT_POSITIONS).max() < 1e-3


def test_cubic_segments_pass_through_waypoints_with_their_velocities():
    trajectory = JointTrajectory([0.0, 1.0, 3.0], [[0.0], [1.0], [0.0]], [[0.0], [0.5], [0.0]])
    for t, q, qd in [(0.0, 0.0, 0.0), (1.0, 1.0, 0.5), (3.0, 0.0, 0.0)]:
        position, velocity = trajectory.sample(t - 1e-9 if t > 0 else t)
        assert position[0] == pytest.approx(q, abs=1e-6) and velocity[0] == pytest.approx(qd, abs=1e-6)
    # Velocity is the derivative of position.
    eps = 1e-6
    numeric = (trajectory.sample(1.7 + eps)[0] - trajectory.sample(1.7 - eps)[0]) / (2 * eps)
    assert numeric[0] == pytest.approx(trajectory.sample(1.7)[1][0], rel=1e-5)


def test_gripper_closes_fully_when_empty_and_opens_again(world):
    world.reset(0, ['red block', 'blue bowl'])
    world.command_gripper(0.0, 10.0)
    world.run_for(1.5)
    state = world.gripper_state()
    assert state.opening < 0.001 and state.speed < 1e-3
    world.command_gripper(0.06)
    world.run_for(1.0)
    assert world.gripper_state().opening == pytest.approx(0.06, abs=0.001)
    world.command_gripper(1.0)  # clamped to the widest opening
    world.run_for(1.0)
    assert world.gripper_state().opening == pytest.approx(GRIPPER_MAX_OPENING, abs=0.001)


def test_gripper_stops_on_a_block_and_squeezes_with_the_commanded_force(world):
    # The gripper is lowered around a block by a trajectory from a pre-grasp pose found with a damped
    # least-squares solve on the model itself (independent of the control package).
    world.reset(0, [ObjectSpec('red block', 'block', 'red', (0.0, -0.5)), 'blue bowl'])
    down = solve_top_down(world, np.array([0.0, -0.5, 0.02]))
    above = solve_top_down(world, np.array([0.0, -0.5, 0.15]))
    world.follow_trajectory([2.0, 3.5], [above, down])
    world.run_for(4.0)
    world.command_gripper(0.0, 15.0)
    world.run_for(1.5)
    state = world.gripper_state()
    assert state.opening == pytest.approx(0.04, abs=0.002)
    assert state.force == pytest.approx(15.0, rel=0.02)
    assert state.speed < 1e-3


def solve_top_down(world, target, iterations=300):
    """Joint angles putting the tcp at target pointing down, fingers closing along world y (DLS on the model)."""
    import mujoco
    model = world.model
    data = mujoco.MjData(model)
    joints = [model.joint(n) for n in ('shoulder_pan_joint', 'shoulder_lift_joint', 'elbow_joint',
                                       'wrist_1_joint', 'wrist_2_joint', 'wrist_3_joint')]
    qpos_adr = [j.qposadr[0] for j in joints]
    dof_adr = [j.dofadr[0] for j in joints]
    site = model.site('tcp').id
    wanted = np.diag([1.0, -1.0, -1.0])
    q = np.array([math.pi / 2, -math.pi / 2, math.pi / 2, -math.pi / 2, -math.pi / 2, 0.0])
    for _ in range(iterations):
        data.qpos[qpos_adr] = q
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        error = np.zeros(6)
        error[:3] = target - data.site_xpos[site]
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, (wanted @ data.site_xmat[site].reshape(3, 3).T).flatten())
        mujoco.mju_quat2Vel(error[3:], quat, 1.0)
        jac_pos, jac_rot = np.zeros((3, model.nv)), np.zeros((3, model.nv))
        mujoco.mj_jacSite(model, data, jac_pos, jac_rot, site)
        jacobian = np.vstack([jac_pos, jac_rot])[:, dof_adr]
        step = jacobian.T @ np.linalg.solve(jacobian @ jacobian.T + 1e-3 * np.eye(6), error)
        q = q + step * min(1.0, 0.1 / max(np.linalg.norm(step), 1e-12))
    assert np.linalg.norm(error) < 1e-6
    return q


def test_a_chunk_of_samples_is_what_sampling_each_time_gives():
    times = np.array([0.0, 0.4, 1.0, 1.3])
    positions = np.array([[0.0, 1.0], [0.5, 0.8], [0.2, 0.9], [0.2, 1.2]])
    trajectory = JointTrajectory(times, positions)
    ts = np.linspace(-0.1, 1.5, 97)  # before, inside (at waypoints too) and after
    many_p, many_v, many_a = trajectory.sample_many(ts)
    for t, p, v, a in zip(ts, many_p, many_v, many_a):
        one_p, one_v = trajectory.sample(t)
        np.testing.assert_allclose(p, one_p, atol=1e-12)
        np.testing.assert_allclose(v, one_v, atol=1e-12)
        np.testing.assert_allclose(a, trajectory.sample_acceleration(t), atol=1e-9)
