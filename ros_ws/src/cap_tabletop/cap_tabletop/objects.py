"""The kinds of objects on the table and their sizes [m]. An object is named "<colour> <category>" ("red block")."""
from __future__ import annotations

import math

CATEGORY_BLOCK = 'block'
CATEGORY_BOWL = 'bowl'
CATEGORIES: tuple[str, ...] = (CATEGORY_BLOCK, CATEGORY_BOWL)

BLOCK_SIZE = 0.04  # edge of the cube

# Bowl: a flat disc bottom and a ring of outward-tilted wall slabs; about 13 cm across the rim, 4 cm deep.
BOWL_BOTTOM_RADIUS = 0.05
BOWL_BOTTOM_THICKNESS = 0.006
BOWL_WALL_HEIGHT = 0.034
BOWL_WALL_TILT = math.radians(25.0)  # outward from vertical
BOWL_WALL_THICKNESS = 0.004
BOWL_WALL_SEGMENTS = 12
BOWL_HEIGHT = BOWL_BOTTOM_THICKNESS + BOWL_WALL_HEIGHT
BOWL_RIM_RADIUS = BOWL_BOTTOM_RADIUS + BOWL_WALL_HEIGHT * math.tan(BOWL_WALL_TILT) + BOWL_WALL_THICKNESS
# Inside a bowl: horizontal distance from its centre at which a block still rests on the bottom.
BOWL_INNER_RADIUS = BOWL_BOTTOM_RADIUS


def object_name(color_name: str, category: str) -> str:
    """'red', 'block' -> 'red block'."""
    return f'{color_name} {category}'


def resting_height(category: str) -> float:
    """z above the table top of the object's origin when it rests there: cube centre, bowl bottom."""
    return BLOCK_SIZE / 2 if category == CATEGORY_BLOCK else 0.0
