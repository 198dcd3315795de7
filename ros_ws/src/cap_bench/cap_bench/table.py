"""Facts of the table-top scene the benchmark is defined on (world frame, metres; "top" is +y, "left" is -x)."""
from __future__ import annotations

from cap_lmp_ros.domains.tabletop import lmps as tabletop

# Named positions on the table surface (z = 0): the ones the robot API of generated code knows.
CORNERS: dict[str, tuple[float, float]] = dict(tabletop.CORNERS)
SIDES: dict[str, tuple[float, float]] = {**tabletop.SIDES, 'middle': tabletop.MIDDLE}
NAMED_POSITIONS = {**CORNERS, **SIDES}

# Unit vectors of the four directions in the table plane.
DIRECTIONS: dict[str, tuple[float, float]] = {
    'top': (0.0, 1.0), 'bottom': (0.0, -1.0), 'left': (-1.0, 0.0), 'right': (1.0, 0.0)}

# Where objects spawn, and how far apart.
SPAWN_X = (-0.2, 0.2)
SPAWN_Y = (-0.7, -0.3)
SPAWN_MIN_DISTANCE = 0.15
TABLE_X = (-0.3, 0.3)
TABLE_Y = (-0.8, -0.2)

BLOCK_SIZE = 0.04
