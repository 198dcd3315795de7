"""The mobile demo's map: a top-down PNG of the kitchen with the base's path during each command drawn in a colour
of its own (plain Python, NumPy and OpenCV; no ROS). A path is an (N, 2) array of the base's x, y [m]
(cap_bringup.base_path).
"""
from __future__ import annotations

import pathlib
from typing import Sequence

import numpy as np
from cap_mobile import layout

PIXELS_PER_METRE = 100
_MARGIN = 20  # [px] around the room
_COLOURS = [(31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189), (140, 86, 75),
            (227, 119, 194), (127, 127, 127)]  # RGB, one per command


def _pixel(x: float, y: float) -> tuple[int, int]:
    """The map's pixel of a floor point (+y up in the picture)."""
    column = _MARGIN + (x - layout.ROOM_X_RANGE[0]) * PIXELS_PER_METRE
    row = _MARGIN + (layout.ROOM_Y_RANGE[1] - y) * PIXELS_PER_METRE
    return int(round(column)), int(round(row))


_LINE = 22  # [px] a legend line's height


def _wrap(text: str, width: int) -> list[str]:
    """`text` in lines that fit `width` pixels of the legend's font."""
    import cv2

    lines: list[str] = []
    for word in text.split():
        candidate = f'{lines[-1]} {word}' if lines else word
        if lines and cv2.getTextSize(candidate, cv2.FONT_HERSHEY_SIMPLEX, 0.5, 1)[0][0] <= width:
            lines[-1] = candidate
        else:
            lines.append(word)
    return lines or ['']


def draw_map(paths: Sequence[tuple[str, np.ndarray]], out: pathlib.Path) -> pathlib.Path:
    """A top-down PNG of the kitchen: walls, furniture with names, and each (label, path) in a colour of its own,
    numbered where it starts; the robot's last position as a circle of the base's size."""
    import cv2

    width = int((layout.ROOM_X_RANGE[1] - layout.ROOM_X_RANGE[0]) * PIXELS_PER_METRE) + 2 * _MARGIN
    legend = [_wrap(f'{index + 1}. {label}', width - 2 * _MARGIN) for index, (label, _) in enumerate(paths)]
    height = int((layout.ROOM_Y_RANGE[1] - layout.ROOM_Y_RANGE[0]) * PIXELS_PER_METRE) + 2 * _MARGIN + \
        _LINE * sum(len(lines) for lines in legend)
    image = np.full((height, width, 3), 255, dtype=np.uint8)
    cv2.rectangle(image, _pixel(layout.ROOM_X_RANGE[0], layout.ROOM_Y_RANGE[1]),
                  _pixel(layout.ROOM_X_RANGE[1], layout.ROOM_Y_RANGE[0]), (60, 60, 60), 3)
    for piece in layout.FURNITURE:
        x_min, y_min, x_max, y_max = piece.footprint
        cv2.rectangle(image, _pixel(x_min, y_max), _pixel(x_max, y_min), (200, 200, 200), -1)
        cv2.rectangle(image, _pixel(x_min, y_max), _pixel(x_max, y_min), (120, 120, 120), 1)
        column, row = _pixel(x_min, (y_min + y_max) / 2)
        cv2.putText(image, piece.name, (column + 2, row + 4), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (40, 40, 40), 1,
                    cv2.LINE_AA)
    row = height - _LINE * sum(len(lines) for lines in legend)
    for index, (label, path) in enumerate(paths):
        colour = _COLOURS[index % len(_COLOURS)]
        points = np.array([_pixel(x, y) for x, y in np.asarray(path)[:, :2]], dtype=np.int32)
        if len(points) > 1:
            cv2.polylines(image, [points], False, colour, 2, cv2.LINE_AA)
        if len(points):
            cv2.circle(image, tuple(int(v) for v in points[0]), 5, colour, -1)
            cv2.putText(image, str(index + 1), (int(points[0][0]) + 6, int(points[0][1]) - 6),
                        cv2.FONT_HERSHEY_SIMPLEX, 0.5, colour, 1, cv2.LINE_AA)
        for line in legend[index]:
            cv2.putText(image, line, (_MARGIN, row + 16), cv2.FONT_HERSHEY_SIMPLEX, 0.5, colour, 1, cv2.LINE_AA)
            row += _LINE
    last = next((np.asarray(path)[-1] for _, path in reversed(paths) if len(path)), None)
    if last is not None:
        cv2.circle(image, _pixel(*last[:2]), int(layout.BASE_RADIUS * PIXELS_PER_METRE), (0, 0, 0), 2, cv2.LINE_AA)
    out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out), image[..., ::-1])
    return out


__all__ = ['PIXELS_PER_METRE', 'draw_map']
