"""The whiteboard domain in the engine: the paper's session from the reference cassette, with a recording robot."""
import numpy as np

from cap_lmp.cassette import CassetteClient
from cap_lmp_ros.domains.registry import get_domain
from cap_lmp_ros.domains.whiteboard.robot_api import stroke_points
from cap_lmp.errors import RobotApiError

import pytest

# The paper's drawing session, as the whiteboard demo runs it.
SESSION = ('draw a 5cm hexagon around the middle', 'draw a line that bisects the hexagon', 'make them both bigger',
           'erase the hexagon and the line', 'draw the sun as a circle at the top right',
           'draw the ground as a line at the bottom', 'draw a pyramid as a triangle on the ground',
           'draw a smaller pyramid a little bit to the left', 'draw circles around the blocks',
           'draw a square around the sweeter fruit')
OBJECTS = {'red block': np.array([0.18, -0.52]), 'blue block': np.array([0.05, -0.37]),
           'apple': np.array([-0.17, -0.52]), 'lemon': np.array([-0.12, -0.38])}


class Board:
    """The robot functions of the whiteboard, recording strokes instead of moving."""

    def __init__(self):
        self.strokes: list[tuple[str, np.ndarray]] = []

    def functions(self):
        return {'get_obj_names': lambda: list(OBJECTS), 'get_obj_pos': lambda name: OBJECTS[name].copy(),
                'draw': lambda pts: self.strokes.append(('draw', stroke_points(pts, 'draw'))),
                'erase': lambda pts: self.strokes.append(('erase', stroke_points(pts, 'erase'))),
                'say': lambda text: None}


def test_the_reference_session_draws_erases_and_remembers_its_shapes():
    domain = get_domain('whiteboard')
    robot = Board()
    engine = domain.build_engine(robot.functions(), CassetteClient(domain.cassette))
    for command in SESSION:
        result = engine.run(command)
        assert result.success, (command, result.error)
    kinds = [kind for kind, _ in robot.strokes]
    assert kinds.count('erase') == 4 and kinds.count('draw') == 11
    # "make them both bigger" erased the hexagon and line it drew, then drew them 1.5 times as big.
    hexagon, bigger = robot.strokes[0][1], robot.strokes[4][1]
    assert np.allclose(robot.strokes[2][1], hexagon)
    assert np.ptp(bigger[:, 0]) == pytest.approx(1.5 * np.ptp(hexagon[:, 0]))
    # The square goes around the sweeter fruit: the apple, not the lemon.
    square = robot.strokes[-1][1]
    assert np.allclose(square[:-1].mean(axis=0), OBJECTS['apple'])


@pytest.mark.parametrize('bad, words', [('not points', 'rows of [x, y]'), ([[0.1, np.inf]], 'not a number'),
                                        (np.zeros((2, 4)), 'shape (2, 4)'), (np.zeros((6000, 2)), 'at most')])
def test_draw_refuses_what_is_not_a_stroke_with_a_clear_error(bad, words):
    with pytest.raises(RobotApiError, match=words.replace('[', r'\[').replace('(', r'\(').replace(')', r'\)')):
        stroke_points(bad, 'draw')


def test_a_stopped_motion_that_never_answers_names_the_wait_after_the_cancel():
    import threading
    from concurrent.futures import Future

    from cap_lmp_ros.domains.ros_api import wait_for_future

    stop, cancels = threading.Event(), []
    stop.set()
    with pytest.raises(RobotApiError, match=r'within 0.05 s of the cancel'):
        wait_for_future(Future(), 180.0, 'the path-following controller', stop, 0.05, lambda: cancels.append(1))
    assert cancels


def test_the_places_the_shape_prompt_names_are_the_boards_own():
    """parse_shape_pts's prompt says where the named places are; they must be cap_whiteboard.board's PLACES."""
    import json
    import re

    from cap_whiteboard import board

    from cap_lmp.prompts import load_prompt
    from cap_lmp_ros.domains.whiteboard.lmps import PROMPTS_DIR, denormalize_xy

    header = load_prompt(PROMPTS_DIR, 'parse_shape_pts').split('\n\n')[0].replace('\n# ', ' ')
    named = dict(re.findall(r'the (middle|top left corner) is denormalize_xy\((\[[^\]]+\])\)', header))
    sides = header.split('the top, bottom, left and right side ')[1].split(';')[0]
    named.update(zip(('top side', 'bottom side', 'left side', 'right side'), re.findall(r'\[[^\]]+\]', sides)))
    assert len(named) == 6
    for place, normalised in named.items():
        assert np.allclose(denormalize_xy(json.loads(normalised)), board.PLACES[place]), place
