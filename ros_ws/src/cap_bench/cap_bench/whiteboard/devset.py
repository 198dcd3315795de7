"""The whiteboard's development set: everyday drawing commands of this project, judged on the ink like the benchmark.

Prompts are tuned on these, never on the benchmark's episodes. No instruction renders one of the benchmark's
templates (a named-size polygon or circle at a named place, a line between two named places, a shape around an
object, a square moved or resized, a shape erased): sizes are given as side lengths, widths or diameters, shapes
are made of several strokes, placed relative to other drawings or objects, and a session holds more than one
change. Each command is a sequence of instructions in one session, a fixed set of objects placed clear of every
path, the shapes the ink must show at the end (none: a clean board) and a reference program per instruction.

`cap bench whiteboard --set dev` runs them (oracle: the references; --policy llm: the model), with the benchmark's
runner and ink check.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from cap_whiteboard import board

from cap_bench.whiteboard import shapes
from cap_bench.whiteboard.episodes import Episode, objects_clear_of

Points = np.ndarray
MIDDLE = np.array(board.MIDDLE)
PLACES = {name: np.array(xy) for name, xy in board.PLACES.items()}


@dataclass(frozen=True)
class DevDrawing:
    key: str
    instructions: tuple[str, ...]
    targets: tuple[Points, ...]  # what the ink shows at the end; () for a clean board
    drawn: tuple[Points, ...]  # every path drawn on the way (the objects keep clear of them)
    references: tuple[str, ...]  # one program per instruction
    objects_seed: int = 0
    object_count: int = 3

    def episode(self) -> Episode:
        objects = objects_clear_of(self.drawn, self.objects_seed, self.object_count)
        return Episode('dev', 0, self.instructions, tuple(objects), self.targets, self.drawn,
                       {'instructions': list(self.instructions), 'dev': self.key})


def _rect(center: Sequence[float], width: float, height: float) -> Points:
    """A closed axis-aligned rectangle, from its top left corner clockwise."""
    x, y = center
    w, h = width / 2, height / 2
    return np.array([[x - w, y + h], [x + w, y + h], [x + w, y - h], [x - w, y - h], [x - w, y + h]])


def _line(start: Sequence[float], end: Sequence[float]) -> Points:
    return np.array([start, end], dtype=float)


def _code(points: Points) -> str:
    return f'np.array({np.round(points, 4).tolist()})'


def _draws(*named: tuple[str, Points]) -> str:
    """A reference that keeps each shape in its variable and draws it."""
    return ''.join(f'{name} = {_code(points)}\ndraw({name})\n' for name, points in named)


def _triangle_by_side(center: Sequence[float], side: float) -> Points:
    """An equilateral triangle with a flat bottom, `side` long, centred (circumcentre) at `center`."""
    return shapes.polygon(center, 2 * side / math.sqrt(3), 3)


def _commands() -> list[DevDrawing]:
    out: list[DevDrawing] = []

    def add(key: str, instructions: Sequence[str], targets: Sequence[Points], references: Sequence[str],
            drawn: Sequence[Points] | None = None, seed: int = 0, count: int = 3) -> None:
        out.append(DevDrawing(key, tuple(instructions), tuple(targets), tuple(drawn if drawn is not None else targets),
                              tuple(references), seed, count))

    square = _rect(MIDDLE, 0.06, 0.06)
    add('square_by_side', ['draw a square with 6 cm sides in the middle of the board'], [square],
        [_draws(('square_pts', square))], seed=1)
    rectangle = _rect(MIDDLE, 0.14, 0.06)
    add('rectangle', ['draw a rectangle 14 cm wide and 6 cm tall in the centre of the board'], [rectangle],
        [_draws(('rectangle_pts', rectangle))], seed=2)
    circle = shapes.circle(PLACES['top right corner'], 0.04)
    add('circle_by_diameter', ['draw a circle 8 cm in diameter in the top right corner'], [circle],
        [_draws(('circle_pts', circle))], seed=3)
    horizontal = _line(MIDDLE - [0.1, 0], MIDDLE + [0.1, 0])
    add('horizontal_line', ['draw a horizontal line 20 cm long centred on the middle of the board'], [horizontal],
        [_draws(('line_pts', horizontal))], seed=4, count=2)
    vertical = _line(MIDDLE, MIDDLE + [0, 0.1])
    add('vertical_line_up', ['starting at the middle of the board, draw a line 10 cm straight up'], [vertical],
        [_draws(('line_pts', vertical))], seed=5)
    cross = (_line(MIDDLE + [-0.04, 0.04], MIDDLE + [0.04, -0.04]),
             _line(MIDDLE + [-0.04, -0.04], MIDDLE + [0.04, 0.04]))
    add('x_mark', ['draw an X 8 cm wide and 8 cm tall in the middle of the board'], cross,
        [_draws(('stroke1_pts', cross[0]), ('stroke2_pts', cross[1]))], seed=6)
    top = PLACES['top side']
    plus = (_line(top - [0.04, 0], top + [0.04, 0]), _line(top - [0, 0.04], top + [0, 0.04]))
    add('plus_sign', ['draw a plus sign 8 cm across at the top of the board'], plus,
        [_draws(('horizontal_pts', plus[0]), ('vertical_pts', plus[1]))], seed=7)
    triangle = _triangle_by_side(PLACES['left side'], 0.08)
    add('triangle_by_side', ['draw an equilateral triangle with 8 cm sides, pointing up, on the left side of the '
                             'board'], [triangle], [_draws(('triangle_pts', triangle))], seed=8)
    rings = (shapes.circle(MIDDLE, 0.03), shapes.circle(MIDDLE, 0.05))
    add('concentric_circles', ['draw two circles centred on the middle of the board, of radius 3 cm and 5 cm'],
        rings, [_draws(('small_circle_pts', rings[0]), ('large_circle_pts', rings[1]))], seed=9, count=2)
    corners = (_rect(PLACES['bottom left corner'], 0.05, 0.05), _rect(PLACES['bottom right corner'], 0.05, 0.05))
    add('squares_in_corners', ['draw a square with 5 cm sides in each of the two bottom corners'], corners,
        [_draws(('left_square_pts', corners[0]), ('right_square_pts', corners[1]))], seed=10)
    small = shapes.circle(MIDDLE, 0.03)
    add('circle_twice_as_big', ['draw a circle of 3 cm radius in the middle of the board',
                                'now make the circle twice as big'], [shapes.circle(MIDDLE, 0.06)],
        [_draws(('circle_pts', small)),
         f'erase(circle_pts)\ncenter = {_code(MIDDLE)}\ncircle_pts = center + 2 * (circle_pts - center)\n'
         'draw(circle_pts)\n'],
        drawn=[small, shapes.circle(MIDDLE, 0.06)], seed=11, count=2)
    shifted = _rect(MIDDLE + [0, -0.05], 0.06, 0.06)
    add('square_shifted_down', ['draw a square with 6 cm sides in the middle of the board',
                                'shift the square down by 5 cm'], [shifted],
        [_draws(('square_pts', square)), f'erase(square_pts)\nsquare_pts = {_code(shifted)}\ndraw(square_pts)\n'],
        drawn=[square, shifted], seed=12)
    right = PLACES['right side']
    add('wipe_clean', ['draw a circle 10 cm across on the right side of the board', 'wipe the board clean'], [],
        [_draws(('circle_pts', shapes.circle(right, 0.05))), 'erase(circle_pts)\n'],
        drawn=[shapes.circle(right, 0.05)], seed=13)
    house_walls = _rect(MIDDLE, 0.08, 0.08)
    roof = np.array([MIDDLE + [-0.04, 0.04], MIDDLE + [0, 0.08], MIDDLE + [0.04, 0.04]])
    add('house', ['draw a simple house in the middle of the board: an 8 cm square with a triangular roof on top, '
                  '4 cm high'], [house_walls, roof], [_draws(('walls_pts', house_walls), ('roof_pts', roof))],
        seed=14, count=2)
    left_circle = shapes.circle(PLACES['left side'], 0.04)
    right_circle = shapes.circle(PLACES['right side'], 0.04)
    joining = _line(PLACES['left side'] + [0.04, 0], PLACES['right side'] - [0.04, 0])
    add('two_circles_joined', ['draw a circle of radius 4 cm on the left side and another on the right side',
                               'join the two circles with a straight line between their edges'],
        [left_circle, right_circle, joining],
        [_draws(('left_circle_pts', left_circle), ('right_circle_pts', right_circle)),
         _draws(('joining_pts', joining))], seed=15, count=2)
    underline = _line(PLACES['top side'] + [-0.06, -0.04], PLACES['top side'] + [0.06, -0.04])
    box = _rect(PLACES['top side'], 0.12, 0.05)
    add('box_then_underline', ['draw a rectangle 12 cm wide and 5 cm tall at the top of the board',
                               'erase it and draw a 12 cm line where its bottom edge was'], [underline],
        [_draws(('box_pts', box)), f'erase(box_pts)\nline_pts = {_code(underline)}\ndraw(line_pts)\n'],
        drawn=[box, underline], seed=16)
    return out


COMMANDS: tuple[DevDrawing, ...] = tuple(_commands())
BY_KEY = {command.key: command for command in COMMANDS}
REFERENCES: dict[str, str] = {instruction: reference for command in COMMANDS
                              for instruction, reference in zip(command.instructions, command.references)}


def reference_program(instruction: str) -> str:
    """The reference of a development instruction (KeyError for another)."""
    return REFERENCES[instruction]


def episodes(trials: int = 1) -> list[Episode]:
    """The development set as the runner's episodes, `trials` times over (the keys carry the trial)."""
    out = []
    for trial in range(trials):
        for command in COMMANDS:
            episode = command.episode()
            out.append(Episode(command.key, trial, episode.instructions, episode.objects, episode.targets,
                               episode.drawn, episode.attributes))
    return out


__all__ = ['BY_KEY', 'COMMANDS', 'DevDrawing', 'episodes', 'reference_program']
