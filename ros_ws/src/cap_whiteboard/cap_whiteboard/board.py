"""The whiteboard: where it lies, its ink image, and the places on it that commands name (world frame, metres).

The board lies flat on the table top, its writing surface the plane z = SURFACE_Z over X_RANGE x Y_RANGE. Flat on
the table rather than upright: the objects that drawings refer to ("circles around the blocks") stand on it, the
table top's cameras see it whole, and the arm presses down with gravity's help, as the paper's whiteboard set-up
did. "Top" of the board is +y and "left" is -x, as on the table top.

Ink is an image of the board, INK_RESOLUTION metres per pixel: row 0 is the top edge (largest y), column 0 the left
edge (smallest x). A pixel's centre is ink_pixel_centre(row, col).
"""
from __future__ import annotations

import numpy as np

X_RANGE: tuple[float, float] = (-0.25, 0.25)
Y_RANGE: tuple[float, float] = (-0.70, -0.30)
THICKNESS = 0.012
SURFACE_Z = THICKNESS  # the board lies on the table top (z = 0)
CENTRE: tuple[float, float] = ((X_RANGE[0] + X_RANGE[1]) / 2, (Y_RANGE[0] + Y_RANGE[1]) / 2)
SIZE: tuple[float, float] = (X_RANGE[1] - X_RANGE[0], Y_RANGE[1] - Y_RANGE[0])

# Paths must keep this far inside the board's edges: the tip's ink and the eraser's pad stay on the board.
DRAW_MARGIN = 0.01

INK_RESOLUTION = 0.001  # [m per pixel]
INK_WIDTH = int(round(SIZE[0] / INK_RESOLUTION))  # columns
INK_HEIGHT = int(round(SIZE[1] / INK_RESOLUTION))  # rows

# Normalised board coordinates: [0, 0] is the bottom-left corner, [1, 1] the top-right one.
NORMALISED_ORIGIN = np.array([X_RANGE[0], Y_RANGE[0]])
NORMALISED_SPAN = np.array(SIZE)

# Places on the board that commands name ("at the top right", "at the bottom"): 6 cm inside the edges, so that a
# shape up to 10 cm across drawn there keeps DRAW_MARGIN inside the board.
CORNERS: dict[str, tuple[float, float]] = {
    'top left corner': (-0.19, -0.36), 'top right corner': (0.19, -0.36),
    'bottom left corner': (-0.19, -0.64), 'bottom right corner': (0.19, -0.64),
}
SIDES: dict[str, tuple[float, float]] = {
    'top side': (0.0, -0.36), 'bottom side': (0.0, -0.64), 'left side': (-0.19, -0.5), 'right side': (0.19, -0.5)}
MIDDLE: tuple[float, float] = CENTRE
PLACES: dict[str, tuple[float, float]] = {**CORNERS, **SIDES, 'middle': MIDDLE}


def on_board(x: float, y: float, margin: float = 0.0) -> bool:
    """Whether (x, y) lies on the board, at least `margin` inside its edges (a point computed exactly on a limit,
    such as -0.64 - 0.05, is on it)."""
    inside = margin - 1e-9
    return X_RANGE[0] + inside <= x <= X_RANGE[1] - inside and Y_RANGE[0] + inside <= y <= Y_RANGE[1] - inside


def world_to_ink(xy: np.ndarray) -> np.ndarray:
    """(..., 2) world x, y [m] -> (..., 2) fractional (row, col) in the ink image (pixel centres at integers)."""
    xy = np.asarray(xy, dtype=float)
    col = (xy[..., 0] - X_RANGE[0]) / INK_RESOLUTION - 0.5
    row = (Y_RANGE[1] - xy[..., 1]) / INK_RESOLUTION - 0.5
    return np.stack([row, col], axis=-1)


def ink_pixel_centres() -> np.ndarray:
    """(INK_HEIGHT, INK_WIDTH, 2) world x, y of every ink pixel's centre [m]."""
    cols = X_RANGE[0] + (np.arange(INK_WIDTH) + 0.5) * INK_RESOLUTION
    rows = Y_RANGE[1] - (np.arange(INK_HEIGHT) + 0.5) * INK_RESOLUTION
    x, y = np.meshgrid(cols, rows)
    return np.stack([x, y], axis=-1)


__all__ = ['CENTRE', 'CORNERS', 'DRAW_MARGIN', 'INK_HEIGHT', 'INK_RESOLUTION', 'INK_WIDTH', 'MIDDLE',
           'NORMALISED_ORIGIN', 'NORMALISED_SPAN', 'PLACES', 'SIDES', 'SIZE', 'SURFACE_Z', 'THICKNESS', 'X_RANGE',
           'Y_RANGE',
           'ink_pixel_centres', 'on_board', 'world_to_ink']
