"""The objects that stand on the whiteboard for drawings to refer to: blocks of the palette's colours and fruit.

A block is named "<colour> block" as on the table top; a fruit by its kind alone ("apple"). Fruit shapes are
simple solids of about the real fruit's size, flattened underneath so that they rest without rolling.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cap_whiteboard import board


@dataclass(frozen=True)
class FruitKind:
    """One kind of fruit: its colour (a palette name), shape ('ellipsoid' or 'capsule') and size [m].

    size: ellipsoid semi-axes (x, y, z); capsule (radius, half-length of the cylinder part along x, 0)."""

    name: str
    color_name: str
    shape: str
    size: tuple[float, float, float]
    mass: float  # [kg]

    @property
    def resting_height(self) -> float:
        """Height of its centre above the surface it rests on [m]."""
        return self.size[2] if self.shape == 'ellipsoid' else self.size[0]


FRUIT: dict[str, FruitKind] = {kind.name: kind for kind in (
    FruitKind('apple', 'red', 'ellipsoid', (0.035, 0.035, 0.03), 0.15),
    FruitKind('lemon', 'yellow', 'ellipsoid', (0.035, 0.025, 0.024), 0.1),
    FruitKind('orange', 'orange', 'ellipsoid', (0.037, 0.037, 0.034), 0.18),
    FruitKind('lime', 'green', 'ellipsoid', (0.027, 0.027, 0.025), 0.07),
    FruitKind('banana', 'yellow', 'capsule', (0.017, 0.06, 0.0), 0.12),
)}

BLOCK_COLOURS: tuple[str, ...] = ('blue', 'red', 'green', 'orange', 'yellow', 'purple', 'pink', 'cyan', 'brown',
                                  'gray')

# Where objects stand at reset: well inside the board, far enough apart for a shape drawn around each.
SPAWN_X_RANGE: tuple[float, float] = (board.X_RANGE[0] + 0.07, board.X_RANGE[1] - 0.07)
SPAWN_Y_RANGE: tuple[float, float] = (board.Y_RANGE[0] + 0.07, board.Y_RANGE[1] - 0.07)
SPAWN_MIN_SEPARATION = 0.13


def footprint_radius(name: str) -> float:
    """Radius of the smallest circle around the object's footprint [m] (a block is a 4 cm cube)."""
    kind = FRUIT.get(name)
    if kind is None:
        return 0.02 * math.sqrt(2.0)
    return kind.size[0] if kind.shape == 'ellipsoid' else kind.size[0] + kind.size[1]


def default_objects(seed: int) -> list[tuple[str, str, str]]:
    """(name, category, colour) of the seed's default episode: two blocks of distinct colours and two fruit."""
    rng = np.random.default_rng([seed, 11])
    blocks = [(f'{colour} block', 'block', str(colour)) for colour in rng.choice(BLOCK_COLOURS, 2, replace=False)]
    fruit = [(FRUIT[name].name, FRUIT[name].name, FRUIT[name].color_name)
             for name in rng.choice(sorted(FRUIT), 2, replace=False)]
    return blocks + fruit


__all__ = ['BLOCK_COLOURS', 'FRUIT', 'FruitKind', 'SPAWN_MIN_SEPARATION', 'SPAWN_X_RANGE', 'SPAWN_Y_RANGE',
           'default_objects', 'footprint_radius']
