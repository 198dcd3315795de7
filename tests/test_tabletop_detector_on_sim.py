"""The RGB-D colour detector finds every block and bowl of rendered MuJoCo scenes, where they are."""
import numpy as np
import pytest

from cap_perception.detectors.tabletop import detect
from cap_perception.rgbd import CameraView
from cap_sim_bridge.world import World


@pytest.fixture(scope='module')
def world():
    world = World(seed=0)
    yield world
    world.close()


def _view(world, camera='top'):
    rgb, depth = world.render(camera, 640, 480)
    return CameraView(rgb, depth, world.camera_intrinsics(camera, 640, 480).matrix, world.camera_pose(camera))


def test_twenty_random_scenes_no_missed_or_phantom_objects_and_centimetre_accuracy(world):
    errors = []
    for seed in range(100, 120):
        truth = {state.name: state for state in world.reset(seed)}
        found = {obj.name: obj for obj in detect(_view(world))}
        assert set(found) == set(truth), f'seed {seed}: missed {set(truth) - set(found)}, ' \
                                         f'phantom {set(found) - set(truth)}'
        for name, obj in found.items():
            assert obj.category == truth[name].category
            errors.append(np.linalg.norm(np.subtract(obj.position[:2], truth[name].position[:2])))
    print(f'detector over 20 scenes: {len(errors)} objects, position error median {np.median(errors) * 1000:.2f} mm, '
          f'max {max(errors) * 1000:.2f} mm')
    assert np.median(errors) <= 0.01
    assert max(errors) <= 0.02



@pytest.mark.parametrize('spot', [(0.0, -0.75), (0.05, -0.7), (0.0, -0.65), (-0.2, -0.6), (0.2, -0.3), (0.0, -0.4),
                                  (-0.25, -0.25), (0.0, -0.25)])
def test_after_placing_the_clear_view_move_leaves_the_placed_block_in_the_top_cameras_sight(world, spot):
    # With perception from the top camera, pick-and-place ends each place by moving the tool out of the camera's
    # line of sight; on the far half of the table's centre line a short move left the block behind the forearm.
    from cap_control.kinematics import HOME_JOINTS
    from cap_control.pick_place.plan import ObjectInfo, PickPlaceConfig, StageName, plan_pick_place
    from cap_sim_bridge.objects import ObjectSpec

    camera = tuple(world.camera_pose('top')[:3, 3])
    world.reset(0, [ObjectSpec('red block', 'block', 'red', spot)])
    carried = ObjectInfo('blue block', (0.2, -0.45, 0.02), (0.04, 0.04, 0.04))
    plan = plan_pick_place(carried, spot, HOME_JOINTS, PickPlaceConfig(clear_view_from=camera))
    stages = {stage.name: stage for stage in plan.stages}
    # The arm really moves there: above the spot (as when it has just placed there), then the clear-view move.
    for step in [*stages[StageName.MOVE].steps, stages[StageName.RETREAT].steps[-1]]:
        trajectory = plan.trajectory_for(step, world.joint_positions())
        end = world.follow_trajectory(trajectory.times, trajectory.positions, trajectory.velocities)
        world.run_for(end - world.time + 0.3)
    seen = {obj.name: obj for obj in detect(_view(world))}
    assert 'red block' in seen, f'the block at {spot} is hidden from the top camera'
    assert np.linalg.norm(np.subtract(seen['red block'].position[:2], spot)) < 0.02
