"""The navigation map as nav_msgs/OccupancyGrid: what the navigation node sends is the map mobile_pick_place uses."""
from __future__ import annotations

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from cap_mobile import layout

from cap_control import ros_conversions as conv
from cap_control.navigation.executor import NavigationConfig


def test_the_kitchen_map_comes_back_cell_for_cell_and_answers_the_same():
    grid = NavigationConfig().grid()
    msg = conv.occupancy_grid_msg(grid, 'world', Time(sec=3))
    assert (msg.info.width, msg.info.height) == grid.occupied.shape[::-1] and msg.header.frame_id == 'world'
    assert set(msg.data) == {conv.OCCUPIED, conv.FREE}
    back = conv.occupancy_grid(msg)
    assert np.array_equal(back.occupied, grid.occupied)
    assert back.origin == grid.origin and back.resolution == grid.resolution
    points = np.random.default_rng(0).uniform((layout.ROOM_X_RANGE[0], layout.ROOM_Y_RANGE[0]),
                                              (layout.ROOM_X_RANGE[1], layout.ROOM_Y_RANGE[1]), (2000, 2))
    assert [back.is_free(p) for p in points] == [grid.is_free(p) for p in points]


def test_a_malformed_map_is_refused_and_unknown_cells_are_occupied():
    msg = conv.occupancy_grid_msg(NavigationConfig().grid(), 'world', Time())
    msg.data = msg.data[:-1]
    with pytest.raises(ValueError, match='needs as many values'):
        conv.occupancy_grid(msg)
    small = conv.occupancy_grid_msg(NavigationConfig().grid(), 'world', Time())
    small.info.width, small.info.height, small.data = 2, 1, [-1, 0]
    assert conv.occupancy_grid(small).occupied.tolist() == [[True, False]]
