"""The whiteboard benchmark's episodes: seeded instructions from templates, the objects on the board, the shapes the
ink must show, and the reference (oracle) program of every instruction.

Templates (this project's; the paper reports no number for this domain):
- polygon: "draw a 6 cm hexagon at the top left corner" (3 to 6 sides, 4 to 10 cm across, a named place);
- circle: "draw a circle of radius 3 cm at the bottom side" (2 to 5 cm);
- line: "draw a line from the left side to the top right corner" (two named places);
- around_object: "draw a circle around the apple" / "draw a square around the red block" (the object's footprint
  plus 2.5 cm);
- transform: "draw a 6 cm square in the middle", then "move it 5 cm to the left" or "make it bigger" (by half) or
  "make it smaller" (by a third): only the transformed shape may be left;
- erase: "draw a ... at the ...", then "erase it": the board must be clean.
Every episode also stands two blocks and two fruit on the board, sampled where no drawn path comes within
CLEARANCE of them (the pen would knock them over), except the object a shape goes around.

A reference program depends only on its instruction's words (so one cassette serves every episode): it finds
positions through the robot API at run time (get_obj_pos) and writes the geometry of shapes.py as code.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Sequence

import numpy as np
from cap_whiteboard import board, objects as board_objects

from cap_bench.whiteboard import shapes

TEMPLATES = ('polygon', 'circle', 'line', 'around_object', 'transform', 'erase')
CLEARANCE = 0.05  # [m] between a drawn path and an object's footprint
AROUND_MARGIN = 0.025  # [m] between an object's footprint and the shape around it
MOVES = {'left': (-1.0, 0.0), 'right': (1.0, 0.0), 'up': (0.0, 1.0), 'down': (0.0, -1.0)}
BIGGER, SMALLER = 1.5, 1 / 1.5


@dataclasses.dataclass(frozen=True)
class BoardObject:
    name: str
    category: str
    color: str
    xy: tuple[float, float]


@dataclasses.dataclass(frozen=True)
class Episode:
    template: str
    seed: int
    instructions: tuple[str, ...]
    objects: tuple[BoardObject, ...]
    targets: tuple[np.ndarray, ...]  # polylines the ink must show at the end (empty: the board must be clean)
    drawn: tuple[np.ndarray, ...]  # every path the pen draws on the way (for the objects' clearance)
    attributes: dict

    @property
    def key(self) -> str:
        return f'{self.template}/{self.seed}'

    @property
    def erase(self) -> bool:
        return not self.targets


# ------------------------------------------------------------------------------------------------ wording
def place_words(place: str) -> str:
    return 'in the middle' if place == 'middle' else f'at the {place}'


def _place_code(place: str) -> str:
    x, y = board.PLACES[place]
    return f'np.array([{x}, {y}])'


def _polygon_code(center_code: str, size_cm: float, sides: int) -> str:
    return (f'center = {center_code}\n'
            f'angles = -np.pi / 2 + np.pi / {sides} + np.arange({sides + 1}) * 2 * np.pi / {sides}\n'
            f'shape_pts = center + {size_cm / 200!r} * np.column_stack([np.cos(angles), np.sin(angles)])\n')


def _circle_code(center_code: str, radius: float) -> str:
    return (f'center = {center_code}\n'
            f'angles = np.linspace(0, 2 * np.pi, {shapes.CIRCLE_SEGMENTS + 1})\n'
            f'shape_pts = center + {radius!r} * np.column_stack([np.cos(angles), np.sin(angles)])\n')


def _around_radius(name: str) -> float:
    return board_objects.footprint_radius(name) + AROUND_MARGIN


# ------------------------------------------------------------------------------------------------ oracle
def oracle_program(instruction: str) -> str:
    """The reference program of one instruction of these templates (ValueError for other words)."""
    words = instruction.rstrip('.').split()
    text = ' '.join(words)
    if text == 'erase it':
        return 'erase(shape_pts)\n'
    if text.startswith('move it '):
        distance_cm, direction = float(words[2]), words[-1]
        dx, dy = MOVES[direction]
        return (f'erase(shape_pts)\nshape_pts = shape_pts + np.array([{dx * distance_cm / 100!r}, '
                f'{dy * distance_cm / 100!r}])\ndraw(shape_pts)\n')
    if text in ('make it bigger', 'make it smaller'):
        factor = BIGGER if words[-1] == 'bigger' else SMALLER
        return ('erase(shape_pts)\ncenter = (shape_pts.min(axis=0) + shape_pts.max(axis=0)) / 2\n'
                f'shape_pts = center + (shape_pts - center) * {factor!r}\ndraw(shape_pts)\n')
    if text.startswith('draw a line from the '):
        start, end = text[len('draw a line from the '):].split(' to the ')
        return f'shape_pts = np.array([{_place_code(start)}, {_place_code(end)}])\ndraw(shape_pts)\n'
    if text.startswith('draw a circle of radius '):
        radius = float(words[5]) / 100
        return _circle_code(_place_code(_place_of(text)), radius) + 'draw(shape_pts)\n'
    if ' around the ' in text:
        kind, name = words[2], text.split(' around the ')[1]
        center = f'get_obj_pos({name!r})'
        radius = _around_radius(name)
        if kind == 'circle':
            return _circle_code(center, radius) + 'draw(shape_pts)\n'
        return (f'center = {center}\nshape_pts = center + {radius!r} * np.array([[-1, 1], [1, 1], [1, -1], '
                '[-1, -1], [-1, 1]])\ndraw(shape_pts)\n')
    if text.startswith('draw a ') and words[3] == 'cm' and words[4] in shapes.SIDES_OF:
        return _polygon_code(_place_code(_place_of(text)), float(words[2]), shapes.SIDES_OF[words[4]]) + \
            'draw(shape_pts)\n'
    raise ValueError(f'no reference program for {instruction!r}')


def _place_of(text: str) -> str:
    if text.endswith(' in the middle'):
        return 'middle'
    return text.split(' at the ')[1]


# ------------------------------------------------------------------------------------------------ sampling
def _shape_instruction(rng: np.random.Generator, places: list[str], max_size: float) -> tuple[str, np.ndarray]:
    """A polygon or circle at a named place: (instruction, its points)."""
    place = places[int(rng.integers(len(places)))]
    center = board.PLACES[place]
    if rng.random() < 0.5:
        name = list(shapes.SIDES_OF)[int(rng.integers(len(shapes.SIDES_OF)))]
        size = int(rng.integers(4, int(max_size * 100) + 1))
        return f'draw a {size} cm {name} {place_words(place)}', shapes.polygon(center, size / 100,
                                                                              shapes.SIDES_OF[name])
    radius = int(rng.integers(2, int(max_size * 50) + 1))
    return f'draw a circle of radius {radius} cm {place_words(place)}', shapes.circle(center, radius / 100)


def _sample_objects(rng: np.random.Generator, paths: list[np.ndarray], fixed: list[BoardObject],
                    names: list[tuple[str, str, str]]) -> list[BoardObject] | None:
    placed = list(fixed)
    dense = [_dense(path) for path in paths]
    for name, category, color in names:
        radius = board_objects.footprint_radius(name)
        for _ in range(200):
            xy = (float(rng.uniform(*board_objects.SPAWN_X_RANGE)), float(rng.uniform(*board_objects.SPAWN_Y_RANGE)))
            if any(math.dist(xy, other.xy) < board_objects.SPAWN_MIN_SEPARATION for other in placed):
                continue
            if any(np.min(np.linalg.norm(points - xy, axis=1)) < radius + CLEARANCE for points in dense):
                continue
            placed.append(BoardObject(name, category, color, xy))
            break
        else:
            return None
    return placed


def objects_clear_of(paths: Sequence[np.ndarray], seed: int, count: int = 4) -> list[BoardObject]:
    """`count` of the seed's default objects (blocks first, then fruit), placed where no path comes within
    CLEARANCE of them (ValueError when they do not fit)."""
    rng = np.random.default_rng([seed, 23])
    names = board_objects.default_objects(seed)[:count]
    for _ in range(100):
        objects = _sample_objects(rng, list(paths), [], list(names))
        if objects is not None:
            return objects
    raise ValueError(f'{count} objects do not fit clear of the paths (seed {seed})')


def _dense(path: np.ndarray, step: float = 0.005) -> np.ndarray:
    out = [path[:1]]
    for start, end in zip(path[:-1], path[1:]):
        count = max(1, int(np.ceil(np.linalg.norm(end - start) / step)))
        out.append(start + (np.arange(1, count + 1) / count)[:, None] * (end - start))
    return np.vstack(out)


def sample_episode(template: str, seed: int) -> Episode:
    """The episode of `template` for `seed` (the same seed always gives the same episode)."""
    if template not in TEMPLATES:
        raise ValueError(f'unknown template {template!r}; templates: {", ".join(TEMPLATES)}')
    rng = np.random.default_rng([seed, TEMPLATES.index(template), 17])
    for _ in range(100):
        episode = _try_episode(template, seed, rng)
        if episode is not None:
            return episode
    raise ValueError(f'no layout found for {template} seed {seed}')


def _try_episode(template: str, seed: int, rng: np.random.Generator) -> Episode | None:
    names = board_objects.default_objects(int(rng.integers(1 << 30)))
    places = list(board.PLACES)
    fixed: list[BoardObject] = []
    attributes: dict = {}
    if template in ('polygon', 'circle'):
        while True:
            instruction, points = _shape_instruction(rng, places, 0.10)
            if instruction.startswith('draw a circle') == (template == 'circle'):
                break
        instructions, targets, drawn = (instruction,), (points,), (points,)
    elif template == 'line':
        start, end = rng.choice(places, 2, replace=False)
        points = np.array([board.PLACES[str(start)], board.PLACES[str(end)]])
        instructions, targets, drawn = (f'draw a line from the {start} to the {end}',), (points,), (points,)
    elif template == 'around_object':
        name, category, color = names.pop(int(rng.integers(len(names))))
        radius = _around_radius(name)
        inset = board.DRAW_MARGIN + radius + 0.005  # the whole shape on the board
        xy = (float(rng.uniform(board.X_RANGE[0] + inset, board.X_RANGE[1] - inset)),
              float(rng.uniform(board.Y_RANGE[0] + inset, board.Y_RANGE[1] - inset)))
        fixed = [BoardObject(name, category, color, xy)]
        kind = 'circle' if rng.random() < 0.5 else 'square'
        points = shapes.circle(xy, radius) if kind == 'circle' else shapes.square_around(xy, radius)
        instructions, targets, drawn = (f'draw a {kind} around the {name}',), (points,), (points,)
        attributes = {'object': name, 'shape': kind}
    elif template == 'transform':
        size = int(rng.integers(5, 9))
        first = shapes.polygon(board.MIDDLE, size / 100, 4)
        choice = int(rng.integers(3))
        if choice == 0:
            direction = list(MOVES)[int(rng.integers(len(MOVES)))]
            distance = int(rng.integers(3, 9))
            second = first + np.array(MOVES[direction]) * distance / 100
            change = f'move it {distance} cm {"to the " if direction in ("left", "right") else ""}{direction}'
        else:
            bigger = choice == 1
            second = shapes.scaled(first, BIGGER if bigger else SMALLER)
            change = f'make it {"bigger" if bigger else "smaller"}'
        instructions = (f'draw a {size} cm square in the middle', change)
        targets, drawn = (second,), (first, second)
    else:  # erase
        instruction, points = _shape_instruction(rng, places, 0.08)
        instructions, targets, drawn = (instruction, 'erase it'), (), (points,)
    objects = _sample_objects(rng, list(drawn), fixed, names)
    if objects is None:
        return None
    attributes.setdefault('instructions', list(instructions))
    return Episode(template, seed, instructions, tuple(objects), tuple(targets), tuple(drawn), attributes)


__all__ = ['AROUND_MARGIN', 'BoardObject', 'CLEARANCE', 'Episode', 'TEMPLATES', 'objects_clear_of', 'oracle_program',
           'place_words', 'sample_episode']
