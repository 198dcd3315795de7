import math

import numpy as np

from cap_tabletop import cameras, objects, palette, workspace


def test_named_positions_lie_on_the_table_and_match_normalised_coordinates():
    named = {**workspace.CORNERS, **workspace.SIDES, 'middle': workspace.MIDDLE}
    for name, (x, y) in named.items():
        assert workspace.on_table(x, y), name
    assert np.allclose(workspace.NORMALISED_ORIGIN, workspace.CORNERS['bottom left corner'])
    assert np.allclose(workspace.NORMALISED_ORIGIN + workspace.NORMALISED_SPAN, workspace.CORNERS['top right corner'])
    assert workspace.MIDDLE == (0.0, -0.5)  # the table's centre
    assert not workspace.on_table(0.0, -0.21, margin=0.03)


def test_spawn_region_is_inside_the_table():
    for x in workspace.SPAWN_X_RANGE:
        for y in workspace.SPAWN_Y_RANGE:
            assert workspace.on_table(x, y, margin=objects.BOWL_RIM_RADIUS)


def test_palette_has_ten_distinct_colours_and_rgba_is_normalised():
    assert len(palette.PALETTE) == 10 and len(set(palette.PALETTE.values())) == 10
    assert palette.COLOR_NAMES == tuple(palette.PALETTE)
    assert palette.rgba('red') == (1.0, 87 / 255, 89 / 255, 1.0)


def test_object_sizes():
    assert objects.CATEGORIES == ('block', 'bowl')
    assert objects.object_name('red', 'block') == 'red block'
    assert objects.resting_height('block') == objects.BLOCK_SIZE / 2
    assert objects.BOWL_INNER_RADIUS < objects.BOWL_RIM_RADIUS
    assert 0.12 < 2 * objects.BOWL_RIM_RADIUS < 0.14  # about 13 cm across the rim


def _rotate(q, v):
    w, x, y, z = q
    u = np.array([x, y, z])
    v = np.asarray(v, dtype=float)
    return v + 2 * np.cross(u, np.cross(u, v) + w * v)


def test_cameras_look_at_the_table():
    assert set(cameras.CAMERA_NAMES) == {'front', 'top'} and cameras.DEFAULT_CAMERA in cameras.CAMERAS
    for camera in cameras.CAMERAS.values():
        assert math.isclose(np.linalg.norm(camera.orientation), 1.0, abs_tol=1e-4)
        forward = _rotate(camera.orientation, [0.0, 0.0, -1.0])
        # The view axis reaches the table top's plane over the table.
        t = (workspace.TABLE_Z - camera.position[2]) / forward[2]
        hit = np.asarray(camera.position) + t * forward
        assert t > 0 and workspace.on_table(hit[0], hit[1]), (camera.name, hit)
    assert cameras.TOP.position == (0.0, -0.5, 0.85)


def test_optical_orientation_of_the_top_camera_looks_down_with_image_down_towards_the_bottom():
    assert np.allclose(cameras.optical_orientation_xyzw(cameras.TOP), (1.0, 0.0, 0.0, 0.0))
    x, y, z, w = cameras.optical_orientation_xyzw(cameras.FRONT)
    optical = (w, x, y, z)
    forward = _rotate(optical, [0.0, 0.0, 1.0])
    assert np.allclose(forward, _rotate(cameras.FRONT.orientation, [0.0, 0.0, -1.0]))
    assert np.allclose(_rotate(optical, [0.0, 1.0, 0.0]), -_rotate(cameras.FRONT.orientation, [0.0, 1.0, 0.0]))


def test_place_names_in_the_words_people_use_mean_the_tables_named_positions():
    assert workspace.named_place('middle') == workspace.named_place('the centre of the table') == workspace.MIDDLE
    assert workspace.named_place('the upper-left corner') == workspace.CORNERS['top left corner']
    assert workspace.named_place('left top corner') == workspace.named_place('top left') == \
        workspace.CORNERS['top left corner']
    assert workspace.named_place('the right edge of the table') == workspace.SIDES['right side']
    for name in (*workspace.CORNERS, *workspace.SIDES):
        assert workspace.named_place(name) == {**workspace.CORNERS, **workspace.SIDES}[name]
    for not_a_place in ('left', 'red block', 'top', 'middle block', 'left right corner', 'top top corner', '', 7):
        assert workspace.named_place(not_a_place) is None, not_a_place
