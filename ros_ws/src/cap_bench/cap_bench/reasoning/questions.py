"""The reasoning benchmark's questions: 28 object-selection and 23 position-selection questions about table scenes.

As in the Code as Policies spatial-geometric reasoning evaluation, each question is asked about a small scene (3-6
blocks and bowls, each with an (x, y) position in metres; x to the right, y up) and is answered three ways by the
same model: with code that sets `ret_val`, with the answer given directly as text (vanilla), and with step-by-step
reasoning in text ending in the answer (chain of thought).

Each question is made by a builder for its kind of geometry. The builder computes the answer from the scene and
writes the three reference answers an oracle would give: a program over `objects` (the scene as the code sees it),
the answer text and a chain of thought that computes the distances in text. Object answers are unambiguous: the
runner-up is at least 2 cm worse on the question's measure (the tests check it from the question text).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping

KINDS = ('object', 'position')
COUNTS = {'object': 28, 'position': 23}
STYLES = ('code', 'vanilla', 'cot')

SCENE_DIGITS = 2  # scenes are laid out on a centimetre grid
ANSWER_DIGITS = 3  # text answers give positions to the millimetre, well inside the 1 cm tolerance

Position = tuple[float, float]
Answer = str | Position


@dataclass(frozen=True)
class Question:
    id: str  # 'object-01' ... 'position-23'
    kind: str  # 'object' | 'position'
    objects: Mapping[str, Position] = field(hash=False)  # the scene: name -> (x, y) in metres, a plain dict
    question: str  # object: 'which block is ...?'; position: a noun phrase, 'a point 10 cm to the right of ...'
    answer: Answer  # object name, or (x, y) in metres
    reference_code: str  # sets ret_val from `objects`
    reference_vanilla: str  # the answer alone, as vanilla.txt teaches
    reference_cot: str  # reasoning, then 'So the answer is <answer>.', as cot.txt teaches


# -- how answers are written --------------------------------------------------------------------------------------
def format_number(value: float, digits: int = ANSWER_DIGITS) -> str:
    text = f'{value:.{digits}f}'
    return text[1:] if text.startswith('-') and float(text) == 0 else text  # no '-0.000'


def format_position(xy: Position, digits: int = ANSWER_DIGITS) -> str:
    """'(0.120, -0.300)'."""
    return f'({format_number(xy[0], digits)}, {format_number(xy[1], digits)})'


def format_answer(answer: Answer) -> str:
    """The answer as a text answer gives it: the object's name, or the position to the millimetre."""
    return answer if isinstance(answer, str) else format_position(answer)


# -- shared pieces of the builders --------------------------------------------------------------------------------
def _at(xy: Position) -> str:
    return format_position(xy, SCENE_DIGITS)


_n = format_number


def _sum_text(values: list[float]) -> str:
    """'-0.26 - 0.05 + 0.35': a sum as a person writes it."""
    text = _n(values[0], SCENE_DIGITS)
    for value in values[1:]:
        text += f' {"-" if value < 0 else "+"} {_n(abs(value), SCENE_DIGITS)}'
    return text


def _point(x: float, y: float) -> Position:
    return (round(x, 9), round(y, 9))  # drop float noise such as 0.30000000000000004


def _candidates(objects: Mapping[str, Position], noun: str, named: tuple[str, ...]) -> list[str]:
    """The objects a 'which <noun>' question chooses from: that kind ('object': any), minus those it names."""
    return [name for name in objects if (noun == 'object' or name.endswith(noun)) and name not in named]


def _names_code(noun: str, named: tuple[str, ...]) -> str:
    conditions = [] if noun == 'object' else [f'name.endswith({noun!r})']
    conditions += [f'name != {name!r}' for name in named if noun == 'object' or name.endswith(noun)]
    if not conditions:
        return 'names = list(objects)'
    return f'names = [name for name in objects if {" and ".join(conditions)}]'


def _plural(noun: str, named: tuple[str, ...]) -> str:
    return 'the other objects' if noun == 'object' and named else f'the {noun}s'


def _make(qid: str, kind: str, objects: Mapping[str, Position], text: str, answer: Answer, code: str,
          reasoning: list[str]) -> Question:
    reasoning_text = '\n'.join(reasoning)
    return Question(id=qid, kind=kind, objects=dict(objects), question=text, answer=answer,
                    reference_code=code.strip('\n'), reference_vanilla=format_answer(answer),
                    reference_cot=f'{reasoning_text}\nSo the answer is {format_answer(answer)}.')


def _distance_lines(objects: Mapping[str, Position], names: list[str], origin: Position) -> tuple[list[str],
                                                                                                   dict[str, float]]:
    lines, distances = [], {}
    for name in names:
        x, y = objects[name]
        dx, dy = x - origin[0], y - origin[1]
        distances[name] = math.hypot(dx, dy)
        lines.append(f'- {name} at {_at((x, y))}: dx = {_n(dx)}, dy = {_n(dy)}, distance = {_n(distances[name])}.')
    return lines, distances


# -- object selection ---------------------------------------------------------------------------------------------
def _nearest(qid: str, objects: Mapping[str, Position], noun: str, target: str, farthest: bool = False) -> Question:
    relation = 'farthest from' if farthest else 'closest to'
    names = _candidates(objects, noun, (target,))
    lines, distances = _distance_lines(objects, names, objects[target])
    pick = max if farthest else min
    answer = pick(names, key=distances.__getitem__)
    code = f'''
target = np.array(objects[{target!r}])
{_names_code(noun, (target,))}
ret_val = {pick.__name__}(names, key=lambda name: np.linalg.norm(np.array(objects[name]) - target))
'''
    reasoning = [f'The {target} is at {_at(objects[target])}. Distances of {_plural(noun, (target,))} from it:',
                 *lines, f'The {"largest" if farthest else "smallest"} distance is {_n(distances[answer])}.']
    return _make(qid, 'object', objects, f'which {noun} is {relation} the {target}?', answer, code, reasoning)


_SIDES = {  # side -> (axis, +1 when larger coordinates come first, phrase for "farthest ...")
    'left': (0, -1, 'farthest to the left'),
    'right': (0, 1, 'farthest to the right'),
    'top': (1, 1, 'farthest towards the top'),
    'bottom': (1, -1, 'farthest towards the bottom'),
}
_ORDINALS = {1: 'first', 2: 'second', 3: 'third', 4: 'fourth'}


def _extreme(qid: str, objects: Mapping[str, Position], noun: str, side: str) -> Question:
    axis, sign, phrase = _SIDES[side]
    names = _candidates(objects, noun, ())
    pick = max if sign > 0 else min
    answer = pick(names, key=lambda name: objects[name][axis])
    letter = 'xy'[axis]
    code = f'''
{_names_code(noun, ())}
ret_val = {pick.__name__}(names, key=lambda name: objects[name][{axis}])
'''
    values = ', '.join(f'{name} {_n(objects[name][axis], SCENE_DIGITS)}' for name in names)
    reasoning = [f'{phrase.capitalize()} means the {"largest" if sign > 0 else "smallest"} {letter}.',
                 f'The {noun}s\' {letter} values: {values}.',
                 f'The {"largest" if sign > 0 else "smallest"} is {_n(objects[answer][axis], SCENE_DIGITS)}.']
    return _make(qid, 'object', objects, f'which {noun} is {phrase}?', answer, code, reasoning)


def _nth(qid: str, objects: Mapping[str, Position], noun: str, n: int, side: str) -> Question:
    axis, sign, _ = _SIDES[side]
    names = _candidates(objects, noun, ())
    ordered = sorted(names, key=lambda name: -sign * objects[name][axis])
    answer = ordered[n - 1]
    letter = 'xy'[axis]
    key = f'-objects[name][{axis}]' if sign > 0 else f'objects[name][{axis}]'
    code = f'''
{_names_code(noun, ())}
ret_val = sorted(names, key=lambda name: {key})[{n - 1}]
'''
    order = ', '.join(f'{name} ({_n(objects[name][axis], SCENE_DIGITS)})' for name in ordered)
    reasoning = [f'From the {side} means by {"decreasing" if sign > 0 else "increasing"} {letter}.',
                 f'The {noun}s in that order: {order}.',
                 f'Number {n} in that order is at {letter} = {_n(objects[answer][axis], SCENE_DIGITS)}.']
    return _make(qid, 'object', objects, f'which {noun} is {_ORDINALS[n]} from the {side}?', answer, code, reasoning)


def _between(qid: str, objects: Mapping[str, Position], noun: str, a: str, b: str) -> Question:
    """The candidate nearest to the segment from a to b (the scenes put one on it and the others well away)."""
    names = _candidates(objects, noun, (a, b))
    (ax, ay), (bx, by) = objects[a], objects[b]
    vx, vy = bx - ax, by - ay
    lines, distances = [], {}
    for name in names:
        x, y = objects[name]
        t = min(max(((x - ax) * vx + (y - ay) * vy) / (vx * vx + vy * vy), 0.0), 1.0)
        closest = (ax + t * vx, ay + t * vy)
        distances[name] = math.dist((x, y), closest)
        lines.append(f'- {name} at {_at((x, y))}: t = {t:.2f}, closest point {format_position(closest)}, '
                     f'distance = {_n(distances[name])}.')
    answer = min(names, key=distances.__getitem__)
    code = f'''
start = np.array(objects[{a!r}])
end = np.array(objects[{b!r}])
{_names_code(noun, (a, b))}
def distance_to_segment(name):
    point = np.array(objects[name])
    t = np.clip(np.dot(point - start, end - start) / np.dot(end - start, end - start), 0, 1)
    return np.linalg.norm(point - (start + t * (end - start)))
ret_val = min(names, key=distance_to_segment)
'''
    reasoning = [f'The segment goes from the {a} at {_at(objects[a])} to the {b} at {_at(objects[b])}. For each of '
                 f'{_plural(noun, (a, b))}, the closest point of the segment (t from 0 at the {a} to 1 at the {b}) '
                 'and the distance to it:',
                 *lines, f'The nearest to the segment is {_n(distances[answer])} away; the others are far from it.']
    return _make(qid, 'object', objects, f'which {noun} is between the {a} and the {b}?', answer, code, reasoning)


def _near_midpoint(qid: str, objects: Mapping[str, Position], noun: str, a: str, b: str) -> Question:
    names = _candidates(objects, noun, (a, b))
    middle = ((objects[a][0] + objects[b][0]) / 2, (objects[a][1] + objects[b][1]) / 2)
    lines, distances = _distance_lines(objects, names, middle)
    answer = min(names, key=distances.__getitem__)
    code = f'''
middle = (np.array(objects[{a!r}]) + np.array(objects[{b!r}])) / 2
{_names_code(noun, (a, b))}
ret_val = min(names, key=lambda name: np.linalg.norm(np.array(objects[name]) - middle))
'''
    reasoning = [f'The {a} is at {_at(objects[a])} and the {b} at {_at(objects[b])}; halfway between them is '
                 f'{format_position(middle)}. Distances of {_plural(noun, (a, b))} from that point:',
                 *lines, f'The smallest distance is {_n(distances[answer])}.']
    text = f'which {noun} is closest to the point halfway between the {a} and the {b}?'
    return _make(qid, 'object', objects, text, answer, code, reasoning)


def _in_rectangle(qid: str, objects: Mapping[str, Position], noun: str, x_range: Position,
                  y_range: Position) -> Question:
    names = _candidates(objects, noun, ())
    (x0, x1), (y0, y1) = x_range, y_range
    inside = [name for name in names if x0 <= objects[name][0] <= x1 and y0 <= objects[name][1] <= y1]
    bounds = (f'x from {_n(x0, SCENE_DIGITS)} to {_n(x1, SCENE_DIGITS)} '
              f'and y from {_n(y0, SCENE_DIGITS)} to {_n(y1, SCENE_DIGITS)}')
    code = f'''
{_names_code(noun, ())}
ret_val = [name for name in names if {x0} <= objects[name][0] <= {x1} and {y0} <= objects[name][1] <= {y1}][0]
'''
    lines = []
    for name in names:
        x, y = objects[name]
        x_in, y_in = x0 <= x <= x1, y0 <= y <= y1
        lines.append(f'- {name} at {_at((x, y))}: x {"inside" if x_in else "outside"}, '
                     f'y {"inside" if y_in else "outside"}.')
    reasoning = [f'Inside the rectangle means {bounds}, both.', *lines,
                 f'Only one {noun} has both inside.']
    return _make(qid, 'object', objects, f'which {noun} is inside the rectangle with {bounds}?', inside[0], code,
                 reasoning)


def _within(qid: str, objects: Mapping[str, Position], noun: str, target: str, cm: int) -> Question:
    names = _candidates(objects, noun, (target,))
    lines, distances = _distance_lines(objects, names, objects[target])
    inside = [name for name in names if distances[name] <= cm / 100]
    code = f'''
target = np.array(objects[{target!r}])
{_names_code(noun, (target,))}
ret_val = [name for name in names if np.linalg.norm(np.array(objects[name]) - target) <= {cm / 100}][0]
'''
    reasoning = [f'The {target} is at {_at(objects[target])}. Distances of {_plural(noun, (target,))} from it:',
                 *lines, f'Only one is within {_n(cm / 100, SCENE_DIGITS)}.']
    return _make(qid, 'object', objects, f'which {noun} is within {cm} cm of the {target}?', inside[0], code,
                 reasoning)


def _in_triangle(qid: str, objects: Mapping[str, Position], noun: str, corners: tuple[str, str, str]) -> Question:
    names = _candidates(objects, noun, corners)
    points = [objects[corner] for corner in corners]
    lines, inside = [], []
    for name in names:
        x, y = objects[name]
        crosses = []
        for (px, py), (qx, qy) in zip(points, points[1:] + points[:1]):
            crosses.append((qx - px) * (y - py) - (qy - py) * (x - px))
        same_side = all(c > 0 for c in crosses) or all(c < 0 for c in crosses)
        if same_side:
            inside.append(name)
        signs = ', '.join(_n(c, 4) for c in crosses)
        lines.append(f'- {name} at {_at((x, y))}: {signs}; {"all the same sign, inside" if same_side else "outside"}.')
    listed = f'the {corners[0]}, the {corners[1]} and the {corners[2]}'
    corner_list = ', '.join(f'objects[{corner!r}]' for corner in corners)
    code = f'''
triangle = Polygon([{corner_list}])
{_names_code(noun, corners)}
ret_val = [name for name in names if triangle.contains(Point(objects[name]))][0]
'''
    reasoning = [f'The corners are {", ".join(f"the {c} at {_at(objects[c])}" for c in corners)}. A point is inside '
                 'when the cross products of each edge (corner to next corner) with the point (relative to the '
                 'edge\'s first corner) all have the same sign:', *lines]
    return _make(qid, 'object', objects, f'which {noun} is inside the triangle formed by {listed}?', inside[0], code,
                 reasoning)


def _left_right_above_below(qid: str, objects: Mapping[str, Position], noun: str, beside: str, side: str,
                            level: str, vertical: str) -> Question:
    """The one candidate to one side (left/right) of `beside` and above/below `level`."""
    names = _candidates(objects, noun, (beside, level))
    bx, ly = objects[beside][0], objects[level][1]
    x_test = (lambda x: x < bx) if side == 'left' else (lambda x: x > bx)
    y_test = (lambda y: y > ly) if vertical == 'above' else (lambda y: y < ly)
    matching = [name for name in names if x_test(objects[name][0]) and y_test(objects[name][1])]
    x_op, y_op = ('<' if side == 'left' else '>'), ('>' if vertical == 'above' else '<')
    code = f'''
{_names_code(noun, (beside, level))}
x_limit = objects[{beside!r}][0]
y_limit = objects[{level!r}][1]
ret_val = [name for name in names if objects[name][0] {x_op} x_limit and objects[name][1] {y_op} y_limit][0]
'''
    lines = [f'- {name} at {_at(objects[name])}: x {"yes" if x_test(objects[name][0]) else "no"}, '
             f'y {"yes" if y_test(objects[name][1]) else "no"}.' for name in names]
    bx_text, ly_text = _n(bx, SCENE_DIGITS), _n(ly, SCENE_DIGITS)
    reasoning = [f'The {beside} is at x = {bx_text}, so {side} of it means x {x_op} {bx_text}. '
                 f'The {level} is at y = {ly_text}, so {vertical} it means y {y_op} {ly_text}.',
                 *lines, 'Only one has both.']
    text = f'which {noun} is to the {side} of the {beside} and {vertical} the {level}?'
    return _make(qid, 'object', objects, text, matching[0], code, reasoning)


def _near_group_mean(qid: str, objects: Mapping[str, Position], noun: str, group: str) -> Question:
    members = _candidates(objects, group, ())
    names = _candidates(objects, noun, ())
    mean = (sum(objects[m][0] for m in members) / len(members), sum(objects[m][1] for m in members) / len(members))
    lines, distances = _distance_lines(objects, names, mean)
    answer = min(names, key=distances.__getitem__)
    code = f'''
mean = np.mean([objects[name] for name in objects if name.endswith({group!r})], axis=0)
{_names_code(noun, ())}
ret_val = min(names, key=lambda name: np.linalg.norm(np.array(objects[name]) - mean))
'''
    xs = _sum_text([objects[m][0] for m in members])
    ys = _sum_text([objects[m][1] for m in members])
    reasoning = [f'The {group}s are {", ".join(f"the {m} at {_at(objects[m])}" for m in members)}. Their average '
                 f'position: x = ({xs}) / {len(members)} = {_n(mean[0])}, y = ({ys}) / {len(members)} = '
                 f'{_n(mean[1])}. Distances of the {noun}s from {format_position(mean)}:',
                 *lines, f'The smallest distance is {_n(distances[answer])}.']
    text = f'which {noun} is closest to the average position of the {group}s?'
    return _make(qid, 'object', objects, text, answer, code, reasoning)


# -- position selection -------------------------------------------------------------------------------------------
_DIRECTIONS = {'right': ((1, 0), 'to the right of'), 'left': ((-1, 0), 'to the left of'),
               'above': ((0, 1), 'above'), 'below': ((0, -1), 'below')}


def _offset(qid: str, objects: Mapping[str, Position], target: str, cm: int, direction: str) -> Question:
    (ux, uy), phrase = _DIRECTIONS[direction]
    x, y = objects[target]
    d = cm / 100
    answer = _point(x + ux * d, y + uy * d)
    code = f'''
ret_val = np.array(objects[{target!r}]) + np.array([{ux * d}, {uy * d}])
'''
    axis, step = ('x', ux * d) if ux else ('y', uy * d)
    reasoning = [f'The {target} is at {_at((x, y))}. {cm} cm {phrase} it changes {axis} by {_n(step)}: '
                 f'{format_position(answer)}.']
    return _make(qid, 'position', objects, f'a point {cm} cm {phrase} the {target}', answer, code, reasoning)


def _midpoint(qid: str, objects: Mapping[str, Position], a: str, b: str, wording: str) -> Question:
    (ax, ay), (bx, by) = objects[a], objects[b]
    answer = _point((ax + bx) / 2, (ay + by) / 2)
    code = f'''
ret_val = (np.array(objects[{a!r}]) + np.array(objects[{b!r}])) / 2
'''
    reasoning = [f'The {a} is at {_at((ax, ay))} and the {b} at {_at((bx, by))}. Halfway: '
                 f'x = ({_sum_text([ax, bx])}) / 2 = {_n(answer[0])}, '
                 f'y = ({_sum_text([ay, by])}) / 2 = {_n(answer[1])}.']
    return _make(qid, 'position', objects, wording.format(a=a, b=b), answer, code, reasoning)


def _mean_of(qid: str, objects: Mapping[str, Position], names: tuple[str, ...], wording: str) -> Question:
    answer = _point(sum(objects[n][0] for n in names) / len(names), sum(objects[n][1] for n in names) / len(names))
    listed = ', '.join(f'objects[{name!r}]' for name in names)
    code = f'''
ret_val = tuple(np.mean([{listed}], axis=0))
'''
    xs = _sum_text([objects[n][0] for n in names])
    ys = _sum_text([objects[n][1] for n in names])
    reasoning = [f'The {", the ".join(f"{n} is at {_at(objects[n])}" for n in names)}. The average: '
                 f'x = ({xs}) / {len(names)} = {_n(answer[0])}, y = ({ys}) / {len(names)} = {_n(answer[1])}.']
    text = wording.format(*(f'the {n}' for n in names))
    return _make(qid, 'position', objects, text, answer, code, reasoning)


_FRACTIONS = {'a quarter': (1, 4), 'one third': (1, 3), 'three quarters': (3, 4), 'two fifths': (2, 5)}


def _fraction_along(qid: str, objects: Mapping[str, Position], a: str, b: str, fraction: str) -> Question:
    top, bottom = _FRACTIONS[fraction]
    (ax, ay), (bx, by) = objects[a], objects[b]
    f = top / bottom
    answer = _point(ax + f * (bx - ax), ay + f * (by - ay))
    code = f'''
start = np.array(objects[{a!r}])
end = np.array(objects[{b!r}])
ret_val = start + (end - start) * {top} / {bottom}
'''
    reasoning = [f'The {a} is at {_at((ax, ay))} and the {b} at {_at((bx, by))}; from the first to the second is '
                 f'({_n(bx - ax)}, {_n(by - ay)}). {fraction.capitalize()} of that is ({_n(f * (bx - ax))}, '
                 f'{_n(f * (by - ay))}), added to the {a}: {format_position(answer)}.']
    text = f'the point {fraction} of the way from the {a} to the {b}'
    return _make(qid, 'position', objects, text, answer, code, reasoning)


def _box_corner(qid: str, objects: Mapping[str, Position], group: str, corner: str) -> Question:
    """A corner ('top left', ...) or the 'centre' of the axis-aligned bounding box of a group of objects."""
    members = _candidates(objects, group, ())
    xs, ys = [objects[m][0] for m in members], [objects[m][1] for m in members]
    x_pick = {'left': min(xs), 'right': max(xs), 'centre': (min(xs) + max(xs)) / 2}
    y_pick = {'top': max(ys), 'bottom': min(ys), 'centre': (min(ys) + max(ys)) / 2}
    vertical, horizontal = corner.split() if corner != 'centre' else ('centre', 'centre')
    answer = _point(x_pick[horizontal], y_pick[vertical])
    selection = f'[objects[name] for name in objects if name.endswith({group!r})]' if group != 'object' \
        else 'list(objects.values())'
    x_code = {'left': 'np.min(points[:, 0])', 'right': 'np.max(points[:, 0])',
              'centre': '(np.min(points[:, 0]) + np.max(points[:, 0])) / 2'}[horizontal]
    y_code = {'top': 'np.max(points[:, 1])', 'bottom': 'np.min(points[:, 1])',
              'centre': '(np.min(points[:, 1]) + np.max(points[:, 1])) / 2'}[vertical]
    code = f'''
points = np.array({selection})
ret_val = ({x_code}, {y_code})
'''
    group_text = 'all the objects' if group == 'object' else f'the {group}s'
    reasoning = [f'The x values of {group_text}: {", ".join(_n(x, SCENE_DIGITS) for x in xs)}; from '
                 f'{_n(min(xs), 2)} to {_n(max(xs), 2)}. The y values: {", ".join(_n(y, SCENE_DIGITS) for y in ys)}; '
                 f'from {_n(min(ys), 2)} to {_n(max(ys), 2)}.']
    if corner == 'centre':
        reasoning.append(f'The centre is halfway on both: x = {_n(answer[0])}, y = {_n(answer[1])}.')
        text = f'the centre of the bounding box of {group_text}'
    else:
        reasoning.append(f'The {corner} corner takes the {"smallest" if horizontal == "left" else "largest"} x and '
                         f'the {"largest" if vertical == "top" else "smallest"} y.')
        text = f'the {corner} corner of the bounding box of {group_text}'
    return _make(qid, 'position', objects, text, answer, code, reasoning)


def _point_mirror(qid: str, objects: Mapping[str, Position], source: str, centre: str, wording: str) -> Question:
    (sx, sy), (cx, cy) = objects[source], objects[centre]
    answer = _point(2 * cx - sx, 2 * cy - sy)
    code = f'''
centre = np.array(objects[{centre!r}])
ret_val = centre + (centre - np.array(objects[{source!r}]))
'''
    reasoning = [f'The {source} is at {_at((sx, sy))} and the {centre} at {_at((cx, cy))}. From the {source} to the '
                 f'{centre} is ({_n(cx - sx)}, {_n(cy - sy)}); the same again from the {centre}: '
                 f'{format_position(answer)}.']
    return _make(qid, 'position', objects, wording.format(source=source, centre=centre), answer, code, reasoning)


def _line_mirror(qid: str, objects: Mapping[str, Position], source: str, through: str) -> Question:
    (sx, sy), lx = objects[source], objects[through][0]
    answer = _point(2 * lx - sx, sy)
    code = f'''
line_x = objects[{through!r}][0]
ret_val = (2 * line_x - objects[{source!r}][0], objects[{source!r}][1])
'''
    reasoning = [f'The vertical line through the {through} is x = {_n(lx, SCENE_DIGITS)}. The {source} at '
                 f'{_at((sx, sy))} is {_n(sx - lx)} from it in x; mirrored, x = {_n(lx, 2)} - ({_n(sx - lx)}) = '
                 f'{_n(answer[0])} and y stays {_n(sy, SCENE_DIGITS)}.']
    text = f'the mirror image of the {source} across the vertical line through the {through}'
    return _make(qid, 'position', objects, text, answer, code, reasoning)


def _square_corner(qid: str, objects: Mapping[str, Position], centre: str, cm: int, corner: str) -> Question:
    vertical, horizontal = corner.split()
    half = cm / 200
    ux, uy = (1 if horizontal == 'right' else -1), (1 if vertical == 'top' else -1)
    x, y = objects[centre]
    answer = _point(x + ux * half, y + uy * half)
    code = f'''
ret_val = np.array(objects[{centre!r}]) + np.array([{ux * half}, {uy * half}])
'''
    reasoning = [f'The {centre} is at {_at((x, y))}. A {cm} cm square centred on it reaches {_n(half)} to each '
                 f'side; the {corner} corner is {_n(ux * half)} in x and {_n(uy * half)} in y from the centre: '
                 f'{format_position(answer)}.']
    text = f'the {corner} corner of a {cm} cm square centred on the {centre}'
    return _make(qid, 'position', objects, text, answer, code, reasoning)


def _offset_midpoint(qid: str, objects: Mapping[str, Position], a: str, b: str, cm: int, direction: str,
                     wording: str) -> Question:
    (ux, uy), phrase = _DIRECTIONS[direction]
    (ax, ay), (bx, by) = objects[a], objects[b]
    middle = ((ax + bx) / 2, (ay + by) / 2)
    d = cm / 100
    answer = _point(middle[0] + ux * d, middle[1] + uy * d)
    code = f'''
middle = (np.array(objects[{a!r}]) + np.array(objects[{b!r}])) / 2
ret_val = middle + np.array([{ux * d}, {uy * d}])
'''
    reasoning = [f'The {a} is at {_at((ax, ay))} and the {b} at {_at((bx, by))}; halfway between them is '
                 f'{format_position(middle)}. {cm} cm {phrase} that moves it by ({_n(ux * d)}, {_n(uy * d)}): '
                 f'{format_position(answer)}.']
    text = f'a point {cm} cm {phrase} {wording.format(a=a, b=b)}'
    return _make(qid, 'position', objects, text, answer, code, reasoning)


def _parallelogram(qid: str, objects: Mapping[str, Position], a: str, b: str, c: str) -> Question:
    """Corners a, b, c, d in order: d = a + c - b."""
    (ax, ay), (bx, by), (cx, cy) = objects[a], objects[b], objects[c]
    answer = _point(ax + cx - bx, ay + cy - by)
    code = f'''
ret_val = np.array(objects[{a!r}]) + np.array(objects[{c!r}]) - np.array(objects[{b!r}])
'''
    reasoning = [f'The corners in order are the {a} at {_at((ax, ay))}, the {b} at {_at((bx, by))} and the {c} at '
                 f'{_at((cx, cy))}. The fourth corner is the {a} plus the step from the {b} to the {c} '
                 f'({_n(cx - bx)}, {_n(cy - by)}): {format_position(answer)}.']
    text = (f'the fourth corner of the parallelogram whose first three corners, in order, are the {a}, the {b} and '
            f'the {c}')
    return _make(qid, 'position', objects, text, answer, code, reasoning)


def _quarter_turn(qid: str, objects: Mapping[str, Position], source: str, centre: str) -> Question:
    """Rotate `source` 90 degrees counter-clockwise about `centre`: (dx, dy) -> (-dy, dx)."""
    (sx, sy), (cx, cy) = objects[source], objects[centre]
    dx, dy = sx - cx, sy - cy
    answer = _point(cx - dy, cy + dx)
    code = f'''
centre = np.array(objects[{centre!r}])
dx, dy = np.array(objects[{source!r}]) - centre
ret_val = centre + np.array([-dy, dx])
'''
    reasoning = [f'The {centre} is at {_at((cx, cy))} and the {source} at {_at((sx, sy))}, ({_n(dx)}, {_n(dy)}) from '
                 f'it. A quarter turn counter-clockwise makes that ({_n(-dy)}, {_n(dx)}); from the {centre}: '
                 f'{format_position(answer)}.']
    text = f'the point the {source} reaches when turned 90 degrees counter-clockwise around the {centre}'
    return _make(qid, 'position', objects, text, answer, code, reasoning)


_HALFWAY = 'the point halfway between the {a} and the {b}'
_MIDPOINT = 'the midpoint of the {a} and the {b}'

QUESTIONS: tuple[Question, ...] = (
    # object selection
    _nearest('object-01', {'yellow block': (0.01, 0.22), 'red block': (-0.2, 0.06), 'orange bowl': (-0.16, 0.18),
                           'green bowl': (-0.22, -0.35), 'blue block': (0.41, 0.22)}, 'block', 'green bowl'),
    _nearest('object-02', {'red block': (-0.38, -0.15), 'yellow bowl': (-0.34, 0.31), 'blue bowl': (0.03, -0.2),
                           'purple block': (0.07, 0.07), 'pink bowl': (0.27, 0.11)}, 'bowl', 'red block'),
    _nearest('object-03', {'orange block': (0.21, 0.36), 'red bowl': (0.08, -0.12), 'cyan bowl': (-0.27, -0.24),
                           'green block': (-0.1, 0.21)}, 'object', 'cyan bowl'),
    _nearest('object-04', {'yellow bowl': (0.18, 0.31), 'blue block': (0.01, -0.12), 'pink block': (0.14, 0.17),
                           'green block': (0.24, 0.18), 'brown block': (0.06, -0.37)}, 'block', 'yellow bowl',
             farthest=True),
    _nearest('object-05', {'purple bowl': (0.08, -0.27), 'orange bowl': (0.33, 0.29), 'green bowl': (0.43, 0.25),
                           'red block': (0.36, -0.16), 'blue block': (-0.19, 0.03)}, 'bowl', 'blue block',
             farthest=True),
    _nearest('object-06', {'red bowl': (0.16, 0.11), 'cyan block': (0.23, 0.12), 'gray bowl': (0.28, -0.02),
                           'pink block': (0.0, 0.3), 'yellow block': (0.39, -0.18), 'blue bowl': (0.17, -0.25)},
             'object', 'pink block', farthest=True),
    _extreme('object-07', {'yellow bowl': (-0.01, -0.33), 'green block': (-0.16, 0.16), 'cyan block': (-0.44, -0.14),
                           'red block': (0.28, 0.01), 'blue bowl': (0.39, -0.4)}, 'block', 'left'),
    _extreme('object-08', {'orange block': (-0.41, 0.36), 'green bowl': (-0.23, -0.01), 'pink bowl': (-0.23, -0.12),
                           'purple block': (0.21, -0.33)}, 'object', 'left'),
    _extreme('object-09', {'brown bowl': (0.21, 0.16), 'yellow block': (-0.02, -0.3), 'blue bowl': (0.45, -0.27),
                           'red bowl': (-0.39, -0.22)}, 'bowl', 'right'),
    _extreme('object-10', {'cyan bowl': (-0.22, -0.39), 'blue block': (0.17, -0.31), 'red bowl': (0.21, 0.21),
                           'green block': (-0.24, 0.24), 'gray block': (-0.15, -0.13), 'orange block': (-0.1, -0.29)},
             'block', 'top'),
    _extreme('object-11', {'purple bowl': (0.4, 0.37), 'yellow block': (-0.14, 0.28), 'red block': (-0.35, 0.12)},
             'object', 'top'),
    _extreme('object-12', {'green bowl': (0.01, -0.08), 'pink block': (-0.42, 0.13), 'orange bowl': (-0.23, 0.16),
                           'red block': (0.06, 0.16), 'blue block': (0.19, -0.07)}, 'block', 'bottom'),
    _between('object-13', {'green block': (-0.4, 0.23), 'yellow block': (0.13, 0.3), 'blue bowl': (-0.07, 0.11),
                           'orange block': (0.12, 0.05), 'red bowl': (0.36, 0.01)}, 'block', 'red bowl', 'blue bowl'),
    _between('object-14', {'cyan bowl': (0.38, -0.06), 'yellow block': (-0.4, -0.14), 'pink bowl': (-0.17, 0.15),
                           'red block': (0.14, -0.2), 'green block': (-0.05, 0.33)}, 'object', 'green block',
             'yellow block'),
    _between('object-15', {'brown block': (0.02, -0.1), 'orange bowl': (0.02, -0.38), 'gray bowl': (-0.16, -0.27),
                           'purple block': (0.01, 0.03), 'blue block': (-0.29, -0.1)}, 'block', 'orange bowl',
             'purple block'),
    _nth('object-16', {'yellow block': (-0.32, -0.02), 'orange bowl': (0.17, 0.27), 'red block': (0.41, 0.11),
                       'blue block': (-0.1, 0.15), 'green block': (0.3, -0.01)}, 'block', 2, 'left'),
    _nth('object-17', {'pink block': (-0.41, 0.19), 'green bowl': (0.22, 0.21), 'cyan block': (0.3, 0.25),
                       'red bowl': (0.05, 0.38), 'blue bowl': (-0.24, 0.33)}, 'object', 3, 'left'),
    _nth('object-18', {'yellow bowl': (0.16, 0.14), 'brown bowl': (-0.21, -0.28), 'purple block': (0.0, -0.01),
                       'gray bowl': (-0.32, -0.03), 'blue bowl': (-0.11, -0.39), 'orange block': (0.4, -0.04)},
         'bowl', 2, 'right'),
    _nth('object-19', {'green block': (0.05, 0.1), 'red block': (0.45, -0.28), 'pink bowl': (0.41, -0.12),
                       'yellow block': (0.3, 0.0)}, 'block', 2, 'top'),
    _near_midpoint('object-20', {'red block': (-0.41, 0.02), 'blue bowl': (-0.18, -0.28), 'yellow bowl': (-0.15, 0.17),
                                 'green block': (0.33, 0.29), 'orange block': (0.41, -0.11)},
                   'object', 'red block', 'blue bowl'),
    _near_midpoint('object-21', {'purple block': (-0.31, -0.37), 'green bowl': (0.14, 0.11),
                                 'cyan block': (0.29, -0.18), 'red block': (-0.08, -0.18),
                                 'yellow bowl': (0.31, -0.06)},
                   'block', 'green bowl', 'yellow bowl'),
    _near_midpoint('object-22', {'red bowl': (0.22, 0.25), 'green bowl': (-0.23, 0.32), 'pink bowl': (-0.14, -0.08),
                                 'blue bowl': (0.23, 0.12), 'cyan block': (0.31, 0.15), 'orange block': (0.42, 0.12)},
                   'bowl', 'orange block', 'cyan block'),
    _in_rectangle('object-23', {'red block': (0.19, 0.27), 'green block': (-0.04, -0.22), 'yellow block': (0.18, -0.13),
                                'blue block': (-0.41, 0.34), 'purple bowl': (0.11, 0.02)},
                  'block', (0.10, 0.30), (-0.20, 0.00)),
    _within('object-24', {'red bowl': (-0.41, 0.36), 'orange block': (-0.28, -0.13), 'yellow bowl': (0.24, -0.19),
                          'blue bowl': (-0.34, -0.36), 'brown block': (-0.42, -0.4)}, 'bowl', 'brown block', 12),
    _in_triangle('object-25', {'yellow block': (-0.3, 0.18), 'blue bowl': (0.42, 0.31), 'red bowl': (-0.42, 0.12),
                               'pink block': (-0.43, -0.38), 'green bowl': (-0.14, -0.21), 'cyan block': (-0.03, 0.04)},
                 'block', ('red bowl', 'green bowl', 'blue bowl')),
    _left_right_above_below('object-26', {'blue block': (-0.38, 0.03), 'red bowl': (-0.23, 0.01),
                                          'orange block': (0.39, 0.12), 'green bowl': (-0.04, -0.09),
                                          'yellow block': (0.39, 0.02)}, 'block', 'red bowl', 'left', 'green bowl',
                            'above'),
    _left_right_above_below('object-27', {'purple bowl': (-0.42, 0.2), 'yellow block': (-0.11, 0.09),
                                          'pink bowl': (0.43, -0.07), 'blue block': (-0.17, 0.33),
                                          'cyan bowl': (0.08, 0.17)}, 'bowl', 'blue block', 'right', 'yellow block',
                            'below'),
    _near_group_mean('object-28', {'green block': (-0.43, -0.26), 'blue block': (-0.35, 0.29),
                                   'yellow bowl': (0.17, -0.12), 'orange bowl': (-0.45, 0.36),
                                   'red block': (0.44, 0.12)}, 'bowl', 'block'),
    # position selection
    _offset('position-01', {'green block': (0.45, -0.37), 'blue bowl': (-0.27, 0.39), 'red block': (-0.11, -0.39)},
            'red block', 10, 'right'),
    _offset('position-02', {'red bowl': (0.08, -0.4), 'green bowl': (-0.09, 0.01), 'yellow block': (0.44, 0.2)},
            'green bowl', 7, 'left'),
    _offset('position-03', {'blue block': (0.07, -0.15), 'orange block': (-0.2, 0.1), 'pink bowl': (-0.38, 0.14),
                            'cyan bowl': (0.11, 0.17)}, 'blue block', 15, 'above'),
    _offset('position-04', {'yellow bowl': (0.17, 0.36), 'purple bowl': (-0.18, -0.37), 'red block': (0.31, -0.07)},
            'yellow bowl', 5, 'below'),
    _midpoint('position-05', {'green block': (-0.29, 0.12), 'blue bowl': (0.16, 0.02), 'red block': (-0.32, 0.32),
                              'yellow bowl': (-0.25, 0.01)}, 'red block', 'blue bowl', _HALFWAY),
    _midpoint('position-06', {'blue block': (0.23, 0.23), 'green block': (0.14, -0.12), 'orange block': (0.21, -0.17),
                              'red bowl': (-0.33, -0.15)}, 'green block', 'blue block', _MIDPOINT),
    _midpoint('position-07', {'cyan bowl': (-0.06, -0.12), 'pink bowl': (-0.29, -0.12), 'purple block': (-0.14, -0.17)},
              'cyan bowl', 'pink bowl', 'the point midway between the {a} and the {b}'),
    _mean_of('position-08', {'orange bowl': (-0.42, 0.04), 'red block': (-0.26, 0.22), 'green bowl': (-0.35, -0.33),
                             'blue block': (-0.05, 0.06)}, ('red block', 'blue block', 'green bowl'),
             'the centroid of {}, {} and {}'),
    _mean_of('position-09', {'cyan block': (-0.38, 0.33), 'purple block': (0.27, -0.08), 'orange bowl': (0.27, 0.39),
                             'yellow bowl': (0.13, -0.08)}, ('yellow bowl', 'purple block', 'cyan block'),
             'the average position of {}, {} and {}'),
    _fraction_along('position-10', {'yellow block': (-0.24, 0.33), 'green block': (-0.09, -0.29),
                                    'red bowl': (0.37, -0.17)}, 'red bowl', 'yellow block', 'a quarter'),
    _fraction_along('position-11', {'pink block': (-0.24, -0.38), 'yellow block': (0.38, -0.03),
                                    'blue block': (-0.16, -0.35), 'gray bowl': (0.35, -0.23)},
                    'pink block', 'yellow block', 'one third'),
    _fraction_along('position-12', {'red block': (-0.43, 0.0), 'orange block': (0.35, 0.3), 'blue bowl': (0.38, 0.39),
                                    'cyan bowl': (-0.02, 0.32)}, 'red block', 'cyan bowl', 'three quarters'),
    _box_corner('position-13', {'blue block': (-0.07, 0.31), 'pink bowl': (-0.29, -0.21), 'green block': (-0.4, -0.03),
                                'red block': (-0.22, 0.26), 'yellow bowl': (-0.04, -0.23)}, 'block', 'top left'),
    _box_corner('position-14', {'green bowl': (-0.09, -0.38), 'orange block': (-0.21, 0.13), 'blue bowl': (0.24, 0.25),
                                'purple block': (-0.06, -0.2)}, 'object', 'bottom right'),
    _point_mirror('position-15', {'red block': (0.08, -0.02), 'green bowl': (0.37, 0.29), 'yellow bowl': (0.11, -0.12)},
                  'green bowl', 'red block',
                  'the point on the other side of the {centre} from the {source}, at the same distance'),
    _point_mirror('position-16', {'red bowl': (-0.33, -0.04), 'green block': (-0.12, -0.2), 'purple bowl': (0.4, -0.35),
                                  'blue block': (0.24, 0.08)}, 'red bowl', 'green block',
                  'the reflection of the {source} through the {centre}'),
    _line_mirror('position-17', {'orange block': (0.45, 0.21), 'red bowl': (0.15, -0.38),
                                 'yellow block': (0.03, -0.27)}, 'orange block', 'red bowl'),
    _box_corner('position-18', {'blue bowl': (-0.13, -0.09), 'orange bowl': (-0.3, 0.03), 'pink block': (-0.26, -0.06),
                                'green bowl': (-0.04, 0.14)}, 'bowl', 'centre'),
    _square_corner('position-19', {'cyan bowl': (-0.32, 0.36), 'green block': (-0.01, 0.02),
                                   'red block': (-0.19, -0.34)}, 'green block', 10, 'top right'),
    _offset_midpoint('position-20', {'yellow block': (-0.03, -0.27), 'blue block': (-0.09, 0.15),
                                     'green bowl': (-0.02, -0.04), 'red bowl': (0.15, -0.35)},
                     'red bowl', 'blue block', 5, 'below', _MIDPOINT),
    _offset_midpoint('position-21', {'purple bowl': (0.13, -0.05), 'pink block': (0.06, 0.13),
                                     'orange bowl': (0.17, -0.13), 'cyan block': (0.45, 0.01)},
                     'orange bowl', 'pink block', 8, 'left', _HALFWAY),
    _parallelogram('position-22', {'blue block': (0.17, -0.05), 'red block': (0.26, -0.11), 'yellow bowl': (0.0, 0.3),
                                   'green block': (0.12, 0.36)}, 'red block', 'blue block', 'yellow bowl'),
    _quarter_turn('position-23', {'blue bowl': (-0.06, -0.36), 'orange block': (-0.42, 0.21),
                                  'pink bowl': (-0.17, 0.16), 'red block': (0.11, 0.17)}, 'red block', 'pink bowl'),
)

_BY_ID = {q.id: q for q in QUESTIONS}


def question(id: str) -> Question:
    """The question with this id ('object-01' ... 'position-23')."""
    try:
        return _BY_ID[id]
    except KeyError:
        raise KeyError(f'no reasoning question {id!r}; ids run object-01..object-{COUNTS["object"]:02d} and '
                       f'position-01..position-{COUNTS["position"]:02d}') from None
