"""The kitchen's facts hold together: furniture in the room and apart, every location standable and named."""
import itertools
import math

import pytest

from cap_mobile.layout import (
    BASE_RADIUS, BIN_NAMES, FURNITURE, ROOM_X_RANGE, ROOM_Y_RANGE, START_POSE, UnknownLocationError, location,
)


def _gap(box, x, y):
    """Distance from the point to the box (x_min, y_min, x_max, y_max); 0 inside."""
    dx = max(box[0] - x, 0.0, x - box[2])
    dy = max(box[1] - y, 0.0, y - box[3])
    return math.hypot(dx, dy)


def test_furniture_stands_in_the_room_without_overlapping():
    for piece in FURNITURE:
        x_min, y_min, x_max, y_max = piece.footprint
        assert ROOM_X_RANGE[0] <= x_min and x_max <= ROOM_X_RANGE[1], piece.name
        assert ROOM_Y_RANGE[0] <= y_min and y_max <= ROOM_Y_RANGE[1], piece.name
    for a, b in itertools.combinations(FURNITURE, 2):
        (ax0, ay0, ax1, ay1), (bx0, by0, bx1, by1) = a.footprint, b.footprint
        assert ax1 <= bx0 or bx1 <= ax0 or ay1 <= by0 or by1 <= ay0, (a.name, b.name)


@pytest.mark.parametrize('piece', FURNITURE, ids=lambda piece: piece.name)
def test_the_base_fits_at_every_approach_pose_and_faces_the_furniture(piece):
    x, y, yaw = piece.approach()
    for other in FURNITURE:
        assert _gap(other.footprint, x, y) > BASE_RADIUS, (piece.name, other.name)
    assert ROOM_X_RANGE[0] + BASE_RADIUS < x < ROOM_X_RANGE[1] - BASE_RADIUS
    assert ROOM_Y_RANGE[0] + BASE_RADIUS < y < ROOM_Y_RANGE[1] - BASE_RADIUS
    facing = math.atan2(piece.centre[1] - y, piece.centre[0] - x)
    assert abs(math.remainder(facing - yaw, 2 * math.pi)) < 1e-9


def test_the_start_is_clear_of_everything():
    assert all(_gap(piece.footprint, *START_POSE[:2]) > BASE_RADIUS for piece in FURNITURE)


def test_locations_are_found_as_people_write_them_and_unknown_ones_are_named():
    assert location('The Table').name == 'table'
    assert location('office_chair').name == 'office chair'
    assert set(BIN_NAMES) == {'green bin', 'blue bin', 'grey bin'}
    with pytest.raises(UnknownLocationError, match="no location called 'sofa'.*countertop"):
        location('sofa')
