"""The things in the kitchen the robot can see and grasp (world frame, metres, kilograms).

Drinks (cans, a bottle), snacks (a bag of chips, bars) and fruit, each a kind named alone ("coke can") with its
colour from the shared palette, its shape and size (common product sizes: a 330 ml can is 66 mm across and 122 mm
tall, a 500 ml bottle about 65 mm across and 210 mm tall) and its group, which is what "the snacks" or "the drinks"
means. The fruit are the whiteboard's kinds, named here only (their sizes are cap_whiteboard's; the simulator
builds them). At the start of an episode objects stand on the furniture tops of SURFACES, SPAWN_MARGIN inside
their edges and SPAWN_SEPARATION apart.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Sequence

import numpy as np

from cap_mobile import layout

GROUP_DRINK, GROUP_SNACK, GROUP_FRUIT = 'drink', 'snack', 'fruit'


@dataclasses.dataclass(frozen=True)
class KitchenKind:
    """shape 'cylinder' (size: radius, half-height, 0) or 'box' (size: half-extents x, y, z), standing upright."""

    name: str
    color_name: str
    shape: str
    size: tuple[float, float, float]
    mass: float  # [kg]
    group: str

    @property
    def resting_height(self) -> float:
        """Height of the body's centre above the surface it stands on."""
        return self.size[1] if self.shape == 'cylinder' else self.size[2]


KINDS: dict[str, KitchenKind] = {kind.name: kind for kind in (
    KitchenKind('coke can', 'red', 'cylinder', (0.033, 0.061, 0.0), 0.35, GROUP_DRINK),
    KitchenKind('sprite can', 'green', 'cylinder', (0.033, 0.061, 0.0), 0.35, GROUP_DRINK),
    KitchenKind('water bottle', 'cyan', 'cylinder', (0.0325, 0.105, 0.0), 0.5, GROUP_DRINK),
    KitchenKind('chips bag', 'yellow', 'box', (0.07, 0.03, 0.02), 0.06, GROUP_SNACK),
    KitchenKind('energy bar', 'brown', 'box', (0.065, 0.02, 0.012), 0.05, GROUP_SNACK),
    KitchenKind('granola bar', 'purple', 'box', (0.06, 0.018, 0.012), 0.04, GROUP_SNACK),
)}
FRUIT_NAMES: tuple[str, ...] = ('apple', 'banana', 'orange')
OBJECT_NAMES: tuple[str, ...] = tuple(KINDS) + FRUIT_NAMES
GROUPS: dict[str, str] = {**{name: kind.group for name, kind in KINDS.items()},
                          **{name: GROUP_FRUIT for name in FRUIT_NAMES}}
# What a user calls the bin each group is put away in (the bins themselves are named by colour: layout.BIN_NAMES).
BIN_LABEL_FOR_GROUP: dict[str, str] = {GROUP_FRUIT: 'compost bin', GROUP_DRINK: 'recycle bin',
                                       GROUP_SNACK: 'landfill bin'}

SURFACES: tuple[str, ...] = ('table', 'countertop', 'desk')  # where objects stand at the start
SPAWN_MARGIN = 0.1  # [m] inside a surface's edges
SPAWN_DEPTH = 0.3  # [m] from the edge of a surface's approach side: within the arm's reach from there
SPAWN_SEPARATION = 0.15  # [m] between object centres


def surface_height(x: float, y: float) -> float:
    """The top of the furniture whose footprint holds (x, y) (a bin's bottom for a bin), 0 for the floor."""
    for piece in layout.FURNITURE:
        x_min, y_min, x_max, y_max = piece.footprint
        if x_min <= x <= x_max and y_min <= y <= y_max:
            return 0.01 if piece.kind == 'bin' else piece.top
    return 0.0


def surface_of(x: float, y: float) -> str | None:
    """The name of the furniture under (x, y), None for the floor."""
    for piece in layout.FURNITURE:
        x_min, y_min, x_max, y_max = piece.footprint
        if x_min <= x <= x_max and y_min <= y <= y_max:
            return piece.name
    return None


def spawn_region(piece: layout.Furniture) -> tuple[float, float, float, float]:
    """(x_min, y_min, x_max, y_max) where objects start on `piece`: SPAWN_MARGIN inside its edges, within SPAWN_DEPTH
    of its approach side's edge."""
    x_min, y_min, x_max, y_max = piece.footprint
    x_min, y_min, x_max, y_max = x_min + SPAWN_MARGIN, y_min + SPAWN_MARGIN, x_max - SPAWN_MARGIN, y_max - SPAWN_MARGIN
    nx, ny = layout.SIDES[piece.approach_side]
    if nx > 0:
        x_min = max(x_min, piece.footprint[2] - SPAWN_DEPTH)
    elif nx < 0:
        x_max = min(x_max, piece.footprint[0] + SPAWN_DEPTH)
    elif ny > 0:
        y_min = max(y_min, piece.footprint[3] - SPAWN_DEPTH)
    else:
        y_max = min(y_max, piece.footprint[1] + SPAWN_DEPTH)
    return x_min, y_min, x_max, y_max


def default_objects(seed: int) -> list[str]:
    """The seed's episode: two to three snacks, two drinks and two fruit, distinct kinds."""
    rng = np.random.default_rng([seed, 31])
    snacks = [n for n, g in GROUPS.items() if g == GROUP_SNACK]
    drinks = [n for n, g in GROUPS.items() if g == GROUP_DRINK]
    return [str(n) for n in rng.choice(snacks, int(rng.integers(2, 4)), replace=False)] + \
        [str(n) for n in rng.choice(drinks, 2, replace=False)] + \
        [str(n) for n in rng.choice(FRUIT_NAMES, 2, replace=False)]


def spawn_positions(count: int, seed: int, given: Sequence[tuple[float, float] | None] = (),
                    surfaces: Sequence[str] = SURFACES) -> list[tuple[float, float, float]]:
    """(x, y, surface height) for `count` objects: the given (x, y) kept (on whatever is under them), the others
    drawn on a surface chosen by the seed, SPAWN_SEPARATION apart. ValueError when no layout is found."""
    rng = np.random.default_rng([seed, 32])
    given = list(given) + [None] * (count - len(given))
    for _ in range(200):
        placed: list[tuple[float, float, float]] = []
        for xy in given[:count]:
            if xy is not None:
                placed.append((float(xy[0]), float(xy[1]), surface_height(*xy)))
                continue
            for _ in range(100):
                piece = layout.location(str(rng.choice(list(surfaces))))
                x_min, y_min, x_max, y_max = spawn_region(piece)
                x = float(rng.uniform(x_min, x_max))
                y = float(rng.uniform(y_min, y_max))
                if all(math.dist((x, y), other[:2]) >= SPAWN_SEPARATION for other in placed):
                    placed.append((x, y, piece.top))
                    break
            else:
                break
        if len(placed) == count:
            return placed
    raise ValueError(f'no layout of {count} objects {SPAWN_SEPARATION} m apart fits on {", ".join(surfaces)}')


__all__ = ['FRUIT_NAMES', 'GROUPS', 'GROUP_DRINK', 'GROUP_FRUIT', 'GROUP_SNACK', 'KINDS', 'KitchenKind',
           'OBJECT_NAMES', 'SPAWN_MARGIN', 'SPAWN_SEPARATION', 'SURFACES', 'default_objects', 'spawn_positions',
           'spawn_region', 'surface_height', 'surface_of']
