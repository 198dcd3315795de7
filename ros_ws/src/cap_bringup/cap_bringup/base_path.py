"""A mobile base's recorded path: what it did (reached points, visits in turn, loops around a point, how close it
came to a piece of furniture). Plain Python and NumPy; no ROS. The mobile demo (cap_bringup.demos.mobile) and the
mobile benchmark (cap_bench.mobile) judge their runs with it.

A path is an (N, 2) array of the base's x, y [m] sampled while it moved (the mobile demo records it from the
simulator).
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from cap_mobile import layout

REACHED = 0.05  # [m] a point counts as reached when the base's centre came this close


def closest_approach(path: np.ndarray, point: Sequence[float]) -> float:
    """How close the base's centre came to `point` [m]."""
    return float(np.linalg.norm(np.asarray(path)[:, :2] - np.asarray(point[:2], dtype=float), axis=1).min())


def missed_points(path: np.ndarray, points: Sequence[Sequence[float]], within: float = REACHED) -> list[int]:
    """Indices of the points the base never came within `within` of."""
    return [i for i, point in enumerate(points) if closest_approach(path, point) > within]


def visits(path: np.ndarray, places: dict[str, Sequence[float]], within: float = REACHED) -> list[str]:
    """The places the base stopped by, in order: a visit begins when it comes within `within` of a place and the
    next one counts only after it has been at another place."""
    order: list[str] = []
    for xy in np.asarray(path)[:, :2]:
        for name, place in places.items():
            if math.dist(xy, place[:2]) <= within and (not order or order[-1] != name):
                order.append(name)
    return order


def round_visits(path: np.ndarray, corners: Sequence[Sequence[float]],
                 within: float = REACHED) -> tuple[list[int], bool]:
    """The corners (indices into `corners`, a polygon's in order) the base stopped by, in order (`visits`), and
    whether it went round them in turn: each visit the next corner after the one before, or each the one before it
    (either way round), from any corner."""
    order = [int(i) for i in visits(path, {str(i): corner for i, corner in enumerate(corners)}, within)]
    turns = {(after - before) % len(corners) for before, after in zip(order, order[1:])}
    return order, bool(order) and (turns <= {1} or turns <= {len(corners) - 1})


def rectangle_corners(around: str, width: float, height: float) -> np.ndarray:
    """The corners of a width x height rectangle around a location's centre, counterclockwise from its -x, -y one."""
    centre = np.array(layout.location(around).centre)
    return centre + np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * [width / 2, height / 2]


def winding_turns(path: np.ndarray, point: Sequence[float]) -> float:
    """How many times the path went around `point` (signed, counterclockwise positive): its swept angle / 2 pi."""
    offsets = np.asarray(path)[:, :2] - np.asarray(point[:2], dtype=float)
    angles = np.unwrap(np.arctan2(offsets[:, 1], offsets[:, 0]))
    return float((angles[-1] - angles[0]) / (2 * math.pi)) if len(angles) > 1 else 0.0


def clearance_from(path: np.ndarray, footprint: tuple[float, float, float, float]) -> float:
    """The least distance of the base's centre from a box footprint (x_min, y_min, x_max, y_max) [m]."""
    x_min, y_min, x_max, y_max = footprint
    xy = np.asarray(path)[:, :2]
    dx = np.maximum(0.0, np.maximum(x_min - xy[:, 0], xy[:, 0] - x_max))
    dy = np.maximum(0.0, np.maximum(y_min - xy[:, 1], xy[:, 1] - y_max))
    return float(np.hypot(dx, dy).min())


__all__ = ['REACHED', 'clearance_from', 'closest_approach', 'missed_points', 'rectangle_corners', 'round_visits',
           'visits', 'winding_turns']
