"""The ten colours of the table-top objects, RGB 0-255 (the palette of the Code as Policies table-top tasks)."""
from __future__ import annotations

PALETTE: dict[str, tuple[int, int, int]] = {
    'blue': (78, 121, 167),
    'red': (255, 87, 89),
    'green': (89, 169, 79),
    'orange': (242, 142, 43),
    'yellow': (237, 201, 72),
    'purple': (176, 122, 161),
    'pink': (255, 157, 167),
    'cyan': (118, 183, 178),
    'brown': (156, 117, 95),
    'gray': (186, 176, 172),
}
COLOR_NAMES: tuple[str, ...] = tuple(PALETTE)


def rgba(color_name: str) -> tuple[float, float, float, float]:
    """The palette colour as RGBA in [0, 1] (opaque). KeyError for a colour not in the palette."""
    r, g, b = PALETTE[color_name]
    return (r / 255.0, g / 255.0, b / 255.0, 1.0)
