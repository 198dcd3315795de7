"""Rendered images agree with the published intrinsics and camera poses: a block shows where they project it."""
import numpy as np
import pytest

from cap_sim_bridge.objects import ObjectSpec
from cap_tabletop.palette import PALETTE as COLORS
from cap_sim_bridge.world import World
from cap_tabletop.cameras import CAMERA_NAMES

BLOCKS = [ObjectSpec('red block', 'block', 'red', (-0.15, -0.35)),
          ObjectSpec('blue block', 'block', 'blue', (0.15, -0.65)),
          ObjectSpec('green block', 'block', 'green', (0.0, -0.5)),
          ObjectSpec('yellow bowl', 'bowl', 'yellow', (0.15, -0.35))]


def nearest_palette_colour(rgb):
    """The palette colour whose chromaticity (colour with brightness divided out) is closest to the pixel's."""
    pixel = np.asarray(rgb, dtype=float)
    pixel = pixel / max(pixel.sum(), 1.0)
    return min(COLORS, key=lambda name: np.linalg.norm(np.array(COLORS[name]) / sum(COLORS[name]) - pixel))


@pytest.fixture(scope='module')
def world():
    world = World(objects=BLOCKS)
    yield world
    world.close()


@pytest.mark.parametrize('camera', CAMERA_NAMES)
@pytest.mark.parametrize('width, height', [(640, 480), (320, 240)])
def test_block_tops_appear_where_intrinsics_and_pose_project_them(world, camera, width, height):
    rgb, depth = world.render(camera, width, height)
    assert rgb.shape == (height, width, 3) and rgb.dtype == np.uint8
    assert depth.shape == (height, width) and depth.dtype == np.float32
    intrinsics = world.camera_intrinsics(camera, width, height)
    optical_from_world = np.linalg.inv(world.camera_pose(camera))
    for block in (s for s in world.object_states() if s.category == 'block'):
        top_centre = np.array([block.position[0], block.position[1], block.bbox_max[2], 1.0])
        in_optical = (optical_from_world @ top_centre)[:3]
        assert in_optical[2] > 0, 'the block must be in front of the camera'
        u, v = intrinsics.project(in_optical)
        column, row = int(round(u)), int(round(v))
        assert 0 <= column < width and 0 <= row < height
        assert nearest_palette_colour(rgb[row, column]) == block.color_name, (camera, block.name, rgb[row, column])
        # Depth is the distance along the optical axis, in metres.
        assert depth[row, column] == pytest.approx(in_optical[2], abs=0.004), (camera, block.name)


def test_optical_frames_look_at_the_table_with_image_down_as_plus_y(world):
    top = world.camera_pose('top')
    np.testing.assert_allclose(top[:3, 2], [0, 0, -1], atol=1e-6)  # looks down
    np.testing.assert_allclose(top[:3, 0], [1, 0, 0], atol=1e-6)  # image right = table right
    np.testing.assert_allclose(top[:3, 1], [0, -1, 0], atol=1e-6)  # image down = toward the table's bottom
    front = world.camera_pose('front')
    assert front[1, 3] < -0.8 and front[2, 3] > 0.3  # beyond the table's far edge, above it
    towards_table_centre = np.array([0.0, -0.5, 0.0]) - front[:3, 3]
    towards_table_centre /= np.linalg.norm(towards_table_centre)
    assert front[:3, 2] @ towards_table_centre > 0.99  # looks at (just above) the table centre
    np.testing.assert_allclose(front[:3, 0], [1, 0, 0], atol=1e-6)  # image right = table right
    intrinsics = world.camera_intrinsics('front', 640, 480)
    assert intrinsics.cx == pytest.approx(319.5) and intrinsics.cy == pytest.approx(239.5)
    assert intrinsics.fx == intrinsics.fy


def test_whole_table_is_in_view_of_both_cameras(world):
    corners = [(x, y, 0.0, 1.0) for x in (-0.3, 0.3) for y in (-0.8, -0.2)]
    for camera in CAMERA_NAMES:
        intrinsics = world.camera_intrinsics(camera, 640, 480)
        optical_from_world = np.linalg.inv(world.camera_pose(camera))
        for corner in corners:
            u, v = intrinsics.project((optical_from_world @ np.array(corner))[:3])
            assert 0 <= u < 640 and 0 <= v < 480, (camera, corner)
