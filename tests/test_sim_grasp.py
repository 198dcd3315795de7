"""The simulated gripper picks a block up by friction alone, lifts it with the arm and drops it into a bowl.

Arm targets come from the control package's analytic UR5e inverse kinematics; the world only follows the joint
trajectories and the gripper commands, as it would for the pick-and-place controller.
"""
import numpy as np
import pytest

from cap_control.kinematics import HOME_JOINTS, forward_kinematics, inverse_kinematics, top_down_pose
from cap_sim_bridge.objects import ObjectSpec
from cap_tabletop.objects import BOWL_BOTTOM_THICKNESS, BOWL_INNER_RADIUS
from cap_sim_bridge.world import GRIPPER_MAX_OPENING, World

LIFT = 0.10


def move_tcp(world, target, duration, waypoints=10):
    """Straight-line tcp motion (top-down) as a timed joint trajectory; returns the last joint goal."""
    start = world.tcp_pose()[:3, 3]
    # Seed from the arm's configuration once it is over the table, else from the control package's home.
    q = world.joint_positions() if start[1] < -0.3 else HOME_JOINTS
    goals = []
    for s in np.linspace(0.0, 1.0, waypoints + 1)[1:]:
        q = inverse_kinematics(top_down_pose(start + s * (np.asarray(target) - start)), q)
        goals.append(q)
    world.follow_trajectory(np.linspace(0.0, duration, waypoints + 1)[1:], goals)
    world.run_for(duration + 0.3)
    return goals[-1]


@pytest.mark.parametrize('block_xy, bowl_xy', [((0.0, -0.5), (0.15, -0.6)), ((-0.15, -0.35), (0.1, -0.65)),
                                               ((0.18, -0.68), (-0.15, -0.4))])
def test_grasp_lift_and_drop_into_a_bowl(block_xy, bowl_xy):
    world = World(objects=[ObjectSpec('red block', 'block', 'red', block_xy),
                                   ObjectSpec('blue bowl', 'bowl', 'blue', bowl_xy)])
    # Nothing but contacts can carry the block: the only equality constraint couples the two fingers.
    assert world.model.neq == 1
    block = world.object_state('red block')
    bx, by, bz = block.position

    goal = move_tcp(world, [bx, by, 0.15], 2.5)
    np.testing.assert_allclose(world.tcp_pose()[:3, 3], forward_kinematics(goal)[:3, 3], atol=0.002)
    move_tcp(world, [bx, by, bz], 1.5)
    world.command_gripper(0.0, 20.0)
    world.run_for(1.2)
    gripper = world.gripper_state()
    assert gripper.opening == pytest.approx(0.04, abs=0.002), 'the fingers should stop on the 4 cm block'

    move_tcp(world, [bx, by, bz + LIFT], 1.5)
    lifted = world.object_state('red block')
    assert lifted.position[2] - bz == pytest.approx(LIFT, abs=0.005), 'the block rises with the gripper'
    assert np.linalg.norm(np.subtract(lifted.position, world.tcp_pose()[:3, 3])) < 0.005

    bowl = world.object_state('blue bowl')
    move_tcp(world, [bowl.position[0], bowl.position[1], 0.15], 2.5)
    world.command_gripper(GRIPPER_MAX_OPENING, 20.0)
    world.run_for(1.5)
    move_tcp(world, [bowl.position[0], bowl.position[1], 0.3], 1.0)
    world.run_for(2.0)

    dropped = world.object_state('red block')
    bowl = world.object_state('blue bowl')
    assert np.hypot(dropped.position[0] - bowl.position[0], dropped.position[1] - bowl.position[1]) \
        < BOWL_INNER_RADIUS, 'the block lies inside the bowl'
    assert dropped.bbox_min[2] == pytest.approx(BOWL_BOTTOM_THICKNESS, abs=0.002), 'on the bowl bottom'
    assert max(world.object_speeds().values()) < 1e-3, 'and stays there'
    assert np.hypot(bowl.position[0] - bowl_xy[0], bowl.position[1] - bowl_xy[1]) < 0.01, 'the bowl did not move'
