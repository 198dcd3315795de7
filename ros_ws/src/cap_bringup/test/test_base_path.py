"""What a recorded base path says (visits, going round corners, clearance)."""
import numpy as np

from cap_bringup import base_path

SQUARE = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]


def _through(*points, steps: int = 20) -> np.ndarray:
    """A path through the points in straight legs, sampled finely."""
    legs = [np.linspace(a, b, steps) for a, b in zip(points, points[1:])]
    return np.vstack(legs)


def test_corners_gone_round_either_way_from_any_corner_are_in_turn_and_a_skipped_one_is_not():
    assert base_path.round_visits(_through(SQUARE[2], SQUARE[3], SQUARE[0]), SQUARE) == ([2, 3, 0], True)
    assert base_path.round_visits(_through(SQUARE[1], SQUARE[0], SQUARE[3]), SQUARE) == ([1, 0, 3], True)
    order, in_turn = base_path.round_visits(_through(SQUARE[0], SQUARE[2]), SQUARE)
    assert order == [0, 2] and not in_turn
    assert base_path.round_visits(np.array([[5.0, 5.0]]), SQUARE) == ([], False)


def test_a_place_counts_again_only_after_another_one_and_clearance_is_from_the_box():
    path = _through((0.0, 0.0), (0.02, 0.0), (2.0, 0.0), (0.0, 0.0))
    assert base_path.visits(path, {'a': (0.0, 0.0), 'b': (2.0, 0.0)}) == ['a', 'b', 'a']
    assert base_path.clearance_from(path, (0.5, 0.3, 1.0, 0.8)) == 0.3
