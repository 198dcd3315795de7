"""The mobile demo's map of the kitchen with the base's paths drawn on it."""
import numpy as np
from cap_mobile import layout

from cap_bringup.demos import _mobile_map

SQUARE = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]


def _through(*points, steps: int = 20) -> np.ndarray:
    """A path through the points in straight legs, sampled finely."""
    legs = [np.linspace(a, b, steps) for a, b in zip(points, points[1:])]
    return np.vstack(legs)


def test_the_maps_legend_wraps_a_long_command_inside_the_picture(tmp_path):
    import cv2

    long = ('go in a 1.5m square around the barstool as many times as needed, check each step if there is a '
            'banana, only stop moving when you see the banana')
    room_width = int(np.ptp(layout.ROOM_X_RANGE) * _mobile_map.PIXELS_PER_METRE)
    lines = _mobile_map._wrap(long, room_width)
    assert len(lines) > 1 and ' '.join(lines) == long
    assert all(cv2.getTextSize(line, cv2.FONT_HERSHEY_SIMPLEX, 0.5, 1)[0][0] <= room_width for line in lines)
    short = cv2.imread(str(_mobile_map.draw_map([('go to the table', _through(*SQUARE))], tmp_path / 'a.png')))
    wrapped = cv2.imread(str(_mobile_map.draw_map([(long, _through(*SQUARE))], tmp_path / 'b.png')))
    assert wrapped.shape[0] > short.shape[0] and wrapped.shape[1] == short.shape[1]
