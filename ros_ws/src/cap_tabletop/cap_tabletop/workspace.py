"""Where things are on the table top (world frame, metres; "top" of the table is +y, "left" is -x).

The robot stands at the world origin beside the table; the table's upper surface is the plane z = TABLE_Z over
x in TABLE_X_RANGE, y in TABLE_Y_RANGE. Normalised table coordinates map [0, 0] to the bottom-left point
NORMALISED_ORIGIN and [1, 1] to the top-right point NORMALISED_ORIGIN + NORMALISED_SPAN.
"""
from __future__ import annotations

import numpy as np

TABLE_X_RANGE: tuple[float, float] = (-0.3, 0.3)
TABLE_Y_RANGE: tuple[float, float] = (-0.8, -0.2)
TABLE_Z = 0.0  # height of the table-top surface in the world frame [m]

# The arm's joint positions at a scene reset (base, shoulder, elbow, three wrists) [rad]: the tool points straight
# down at (0, -0.2, 0.45), above the table's top edge, out of the top camera's view of the table.
REST_JOINTS: tuple[float, ...] = (0.8413, -2.2842, 1.7017, -0.9883, -1.5708, -0.7295)

NORMALISED_ORIGIN = np.array([-0.25, -0.75])
NORMALISED_SPAN = np.array([0.5, 0.5])

# Named positions on the table surface that the robot API of generated code knows.
CORNERS: dict[str, tuple[float, float]] = {
    'top left corner': (-0.25, -0.25), 'top right corner': (0.25, -0.25),
    'bottom left corner': (-0.25, -0.75), 'bottom right corner': (0.25, -0.75),
}
SIDES: dict[str, tuple[float, float]] = {
    'top side': (0.0, -0.25), 'bottom side': (0.0, -0.75), 'left side': (-0.25, -0.5), 'right side': (0.25, -0.5)}
MIDDLE: tuple[float, float] = (0.0, -0.5)

# Where objects spawn at reset, and how far apart their centres are at least.
SPAWN_X_RANGE: tuple[float, float] = (-0.2, 0.2)
SPAWN_Y_RANGE: tuple[float, float] = (-0.7, -0.3)
SPAWN_MIN_SEPARATION = 0.15


# Words a person uses for the same place: "the centre of the table", "the upper-left corner", "the right edge".
_PLACE_WORDS = {'center': 'middle', 'centre': 'middle', 'upper': 'top', 'lower': 'bottom', 'edge': 'side'}
_PLACE_FILLER = ('the', 'of', 'table', 'table\'s')


def named_place(text: str) -> tuple[float, float] | None:
    """The table position a place name means (a corner, a side, the middle), in the words people use for it;
    None when `text` names no place. Only whole names: "top left corner" or "the upper-left corner of the table",
    not "left" alone (the left of what?)."""
    if not isinstance(text, str) or len(text) > 100:
        return None
    words = [_PLACE_WORDS.get(word, word) for word in text.lower().replace('-', ' ').split()
             if word not in _PLACE_FILLER]
    if words in (['middle'], ['middle', 'point']):
        return MIDDLE
    if len(words) == 3 and words[2] == 'corner' or len(words) == 2 and words[0] in ('top', 'bottom') \
            and words[1] in ('left', 'right'):
        vertical, horizontal = sorted(words[:2], key=lambda word: word not in ('top', 'bottom'))
        return CORNERS.get(f'{vertical} {horizontal} corner')
    if len(words) == 2 and words[1] == 'side':
        return SIDES.get(f'{words[0]} side')
    return None


def on_table(x: float, y: float, margin: float = 0.0) -> bool:
    """Whether (x, y) lies over the table top, at least `margin` inside its edges."""
    return (TABLE_X_RANGE[0] + margin <= x <= TABLE_X_RANGE[1] - margin
            and TABLE_Y_RANGE[0] + margin <= y <= TABLE_Y_RANGE[1] - margin)
