"""Facts of the table-top scene the benchmark is defined on (world frame, metres; "top" is +y, "left" is -x)."""
from __future__ import annotations

COLORS = ('blue', 'red', 'green', 'orange', 'yellow', 'purple', 'pink', 'cyan', 'brown', 'gray')

# Named positions on the table surface (z = 0).
CORNERS: dict[str, tuple[float, float]] = {
    'top left corner': (-0.25, -0.25),
    'top right corner': (0.25, -0.25),
    'bottom left corner': (-0.25, -0.75),
    'bottom right corner': (0.25, -0.75),
}
SIDES: dict[str, tuple[float, float]] = {
    'top side': (0.0, -0.25),
    'left side': (-0.25, -0.5),
    'right side': (0.25, -0.5),
    'bottom side': (0.0, -0.75),
    'middle': (0.0, -0.5),
}
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
