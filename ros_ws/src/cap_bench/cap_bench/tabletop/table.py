"""The table-top facts the benchmark uses, from cap_tabletop (world frame, metres; "top" is +y, "left" is -x)."""
from __future__ import annotations

from cap_tabletop.objects import BLOCK_SIZE
from cap_tabletop.workspace import (CORNERS, MIDDLE, SIDES as _SIDES, SPAWN_MIN_SEPARATION, SPAWN_X_RANGE,
                                    SPAWN_Y_RANGE, TABLE_X_RANGE, TABLE_Y_RANGE)

__all__ = ['BLOCK_SIZE', 'CORNERS', 'DIRECTIONS', 'NAMED_POSITIONS', 'SIDES', 'SPAWN_MIN_DISTANCE', 'SPAWN_X',
           'SPAWN_Y', 'TABLE_X', 'TABLE_Y']

# Named positions on the table surface (z = 0): the ones the robot API of generated code knows ("middle" among
# the sides, as the benchmark's instructions name it).
SIDES: dict[str, tuple[float, float]] = {**_SIDES, 'middle': MIDDLE}
NAMED_POSITIONS = {**CORNERS, **SIDES}

# Unit vectors of the four directions in the table plane.
DIRECTIONS: dict[str, tuple[float, float]] = {
    'top': (0.0, 1.0), 'bottom': (0.0, -1.0), 'left': (-1.0, 0.0), 'right': (1.0, 0.0)}

# Short names the benchmark modules use for the table-top bounds and spawn rules.
SPAWN_X, SPAWN_Y, SPAWN_MIN_DISTANCE = SPAWN_X_RANGE, SPAWN_Y_RANGE, SPAWN_MIN_SEPARATION
TABLE_X, TABLE_Y = TABLE_X_RANGE, TABLE_Y_RANGE
