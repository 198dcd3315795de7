"""The kitchen-office the mobile manipulator works in (world frame, metres, radians; z up, the floor is z = 0).

A room of ROOM_X_RANGE x ROOM_Y_RANGE with furniture on the floor. Each piece of furniture is a box (its footprint
and height; round pieces such as the barstool are boxes around their footprint for planning) and a named location:
`get_loc_pos(name)` gives its centre, and a robot sent there stands at its `approach` pose, facing it from the open
side. Sizes are common furniture figures: kitchen counters 0.91 m high and 0.61 m deep, tables and desks 0.75 m
high, bar stools 0.76 m to the seat.
"""
from __future__ import annotations

import dataclasses
import math

ROOM_X_RANGE: tuple[float, float] = (-4.0, 4.0)
ROOM_Y_RANGE: tuple[float, float] = (-3.0, 3.0)
WALL_THICKNESS = 0.1  # [m], outside the room's ranges

# The mobile base: a round footprint (the arm stays within it while driving), its speed limits, and the gap it keeps
# from furniture when it stands at a location.
BASE_RADIUS = 0.28
BASE_MAX_SPEED = 0.5  # [m/s]
BASE_MAX_ACCELERATION = 0.5  # [m/s^2]
BASE_MAX_YAW_RATE = 1.2  # [rad/s]
BASE_MAX_YAW_ACCELERATION = 2.0  # [rad/s^2]
APPROACH_GAP = 0.12  # [m] between the base's edge and the furniture at a location's approach pose
# Closer when the arm works on the furniture: the arm's base is then 0.24 m from the edge.
MANIPULATION_GAP = 0.06  # [m] (more than NAVIGATION_MARGIN: the spot stays free for the base)
NAVIGATION_MARGIN = 0.05  # [m] clearance a planned path keeps beyond the base's radius (less than APPROACH_GAP)

# The side of a piece of furniture the robot approaches from (outward normal of that side, in the world frame).
SIDES: dict[str, tuple[float, float]] = {'+x': (1.0, 0.0), '-x': (-1.0, 0.0), '+y': (0.0, 1.0), '-y': (0.0, -1.0)}


@dataclasses.dataclass(frozen=True)
class Furniture:
    name: str
    centre: tuple[float, float]  # [m] of the footprint
    size: tuple[float, float, float]  # footprint x, y and height [m]
    approach_side: str  # key of SIDES: where the robot stands to reach it
    round: bool = False  # a round piece (drawn as a cylinder of diameter size[0]); planned as its box
    kind: str = 'furniture'  # or 'bin' (something objects are put away in) or 'seat'

    @property
    def top(self) -> float:
        return self.size[2]

    @property
    def footprint(self) -> tuple[float, float, float, float]:
        """(x_min, y_min, x_max, y_max)."""
        (x, y), (sx, sy) = self.centre, self.size[:2]
        return (x - sx / 2, y - sy / 2, x + sx / 2, y + sy / 2)

    def approach(self, base_radius: float = BASE_RADIUS, gap: float = APPROACH_GAP) -> tuple[float, float, float]:
        """(x, y, yaw) where the robot stands to reach it: off its approach side, facing it."""
        nx, ny = SIDES[self.approach_side]
        half = abs(nx) * self.size[0] / 2 + abs(ny) * self.size[1] / 2
        distance = half + gap + base_radius
        return (self.centre[0] + nx * distance, self.centre[1] + ny * distance, math.atan2(-ny, -nx))


FURNITURE: tuple[Furniture, ...] = (
    Furniture('countertop', (-1.2, 2.69), (3.0, 0.61, 0.91), '-y'),
    Furniture('table', (2.0, 1.0), (1.4, 0.8, 0.75), '-y'),
    Furniture('desk', (3.2, -2.4), (1.2, 0.6, 0.75), '+y'),
    Furniture('office chair', (-0.8, -0.6), (0.62, 0.62, 1.05), '+y', kind='seat'),
    Furniture('chair', (1.6, -1.6), (0.45, 0.45, 0.9), '+y', kind='seat'),
    Furniture('barstool', (-2.6, 0.9), (0.4, 0.4, 0.76), '+x', round=True, kind='seat'),
    # The bins are named by their colour only: which one takes compost, recycling or landfill is what a user tells
    # the robot ("this is the compost bin"), remembered in the session (objects.BIN_LABEL_FOR_GROUP: which label
    # takes what).
    Furniture('green bin', (-3.7, -0.6), (0.35, 0.35, 0.6), '+x', kind='bin'),
    Furniture('blue bin', (-3.7, -1.3), (0.35, 0.35, 0.6), '+x', kind='bin'),
    Furniture('grey bin', (-3.7, -2.0), (0.35, 0.35, 0.6), '+x', kind='bin'),
)
FURNITURE_BY_NAME: dict[str, Furniture] = {piece.name: piece for piece in FURNITURE}
LOCATION_NAMES: tuple[str, ...] = tuple(FURNITURE_BY_NAME)
BIN_NAMES: tuple[str, ...] = tuple(piece.name for piece in FURNITURE if piece.kind == 'bin')

def obstacle_footprints() -> list[tuple[float, float, float, float]]:
    """The floor the furniture stands on, as (x_min, y_min, x_max, y_max) boxes (the walls bound the room)."""
    return [piece.footprint for piece in FURNITURE]


# Where the robot starts an episode: the room's open middle, facing +x.
START_POSE: tuple[float, float, float] = (0.0, 0.0, 0.0)


class UnknownLocationError(KeyError):
    """A location name that is not in the kitchen; the message lists the known ones."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0])


def location(name: str) -> Furniture:
    """The piece of furniture called `name` ("the table", "Countertop" and "countertop" alike)."""
    key = ' '.join(name.lower().replace('_', ' ').split())
    key = key[4:] if key.startswith('the ') else key
    if key not in FURNITURE_BY_NAME:
        raise UnknownLocationError(f'There is no location called {name!r}. Known locations: '
                                   f'{", ".join(LOCATION_NAMES)}.')
    return FURNITURE_BY_NAME[key]
