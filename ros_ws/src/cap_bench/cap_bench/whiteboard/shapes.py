"""The shapes the whiteboard episodes ask for, as points on the board [m] (pure NumPy; the reference programs
write the same geometry as code, and the checker compares the ink with it).

A regular polygon "N cm" across has its corners on a circle N cm in diameter, a flat bottom side, and repeats its
first corner at the end; a circle is 72 segments.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

SIDES_OF = {'triangle': 3, 'square': 4, 'pentagon': 5, 'hexagon': 6}
CIRCLE_SEGMENTS = 72


def polygon(center: Sequence[float], size: float, sides: int) -> np.ndarray:
    """A closed regular polygon with `sides` corners on a circle `size` across, centred at `center`."""
    angles = -math.pi / 2 + math.pi / sides + np.arange(sides + 1) * 2 * math.pi / sides
    return np.asarray(center, dtype=float) + size / 2 * np.column_stack([np.cos(angles), np.sin(angles)])


def circle(center: Sequence[float], radius: float) -> np.ndarray:
    """A closed circle of `radius` around `center`."""
    angles = np.linspace(0.0, 2 * math.pi, CIRCLE_SEGMENTS + 1)
    return np.asarray(center, dtype=float) + radius * np.column_stack([np.cos(angles), np.sin(angles)])


def square_around(center: Sequence[float], half: float) -> np.ndarray:
    """A closed axis-aligned square of half-width `half` around `center`."""
    corners = np.asarray(center, dtype=float) + half * np.array([[-1, 1], [1, 1], [1, -1], [-1, -1], [-1, 1]])
    return corners


def scaled(points: np.ndarray, factor: float) -> np.ndarray:
    """`points` scaled by `factor` about the centre of their bounding box."""
    center = (points.min(axis=0) + points.max(axis=0)) / 2
    return center + (points - center) * factor


__all__ = ['CIRCLE_SEGMENTS', 'SIDES_OF', 'circle', 'polygon', 'scaled', 'square_around']
