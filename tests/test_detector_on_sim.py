"""The RGB-D colour detector finds every block and bowl of rendered MuJoCo scenes, where they are."""
import numpy as np
import pytest

from cap_perception.rgbd_detector import CameraView, detect
from cap_sim_bridge.world import TabletopWorld


@pytest.fixture(scope='module')
def world():
    world = TabletopWorld(seed=0)
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

