"""The table-top development set: everyday commands in fixed scenes, each judged on the simulator's final state.

Prompts are tuned on these commands, never on the benchmark's episodes. A command is one or more instructions sent
in one session (a later instruction may refer to an earlier one: "undo that"), a fixed layout of 3-6 objects, a
judge of the final state, and a reference program per instruction written against the robot API of the
tabletop_ui prompt (get_obj_names, get_obj_pos, put_first_on_second, denormalize_xy, np).

Only seen colours and seen named positions appear, and no instruction renders one of the benchmark's templates.
Objects a command does not name must stay where they are (within UNTOUCHED). Referents ("the leftmost block") are
resolved when the scene is designed: the judge names the object it expects, so a failure says which one.

References that a later instruction may undo record what they move, before moving it, in the session variable
`moved`: a list of (name, start xy).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Iterable, Mapping, Sequence

import numpy as np

from cap_bench.tabletop import table
from cap_bench.tabletop.episodes import MAGNITUDE_DISTANCES, Episode, SceneObject
from cap_bench.tabletop.oracle import position_code
from cap_bench.tabletop.success import (LINE_MIN_GAP, LINE_SPREAD, MAGNITUDE_PERPENDICULAR, MAGNITUDE_RANGE,
                                        NEAR_PLACE, OK, STACK_STEP, UNTOUCHED, Verdict, is_on)

GROUP = 'dev'  # the group name of a development command's episode (a benchmark record's group is SA-SI etc.)
SHIFT_TOLERANCE = 0.03  # "10 cm to the left": within 3 cm of the asked displacement, along and across
MIDPOINT_TOLERANCE = 0.04  # "halfway between": within 4 cm of the midpoint
BESIDE_GAP = (0.045, 0.15)  # "just left of": centre to centre, clear of the other block and not far off
NEXT_TO_OFFSET = 0.08  # where the reference sets a block down "just left of" another one
SWAP_PARKING = 'middle'  # where the swap reference parks the first block (clear in its scene)
ROW_SPACING = 0.1  # between neighbouring blocks of the reference's row
A_BIT = MAGNITUDE_DISTANCES['a little']  # how far the reference moves a block "a bit" (the benchmark's "a little")
IN_BOWL = 0.05  # a block whose centre is this close to a bowl's lies in it (references decide with this)

Positions = Mapping[str, Sequence[float]]
Judge = Callable[[Positions, Positions], Verdict]
# A condition of one command on its scene's initial and final state.
Condition = Callable[[Episode, Positions, Positions], Verdict]


@dataclass(frozen=True)
class DevCommand:
    key: str
    instructions: tuple[str, ...]  # sent one after another in one session
    objects: tuple[SceneObject, ...]  # the fixed layout the scene is reset to
    judge: Judge  # (initial, final) positions name -> (x, y, z) -> Verdict
    reference: tuple[str, ...]  # the oracle program of each instruction

    def episode(self) -> Episode:
        """The command as an episode of the table-top runner (scene, instruction text, no template of its own)."""
        return _episode(self.key, self.instructions, self.objects)


def _episode(key: str, instructions: Sequence[str], objects: Sequence[SceneObject]) -> Episode:
    return Episode(seed=0, group=GROUP, template=key, instruction=' / '.join(instructions), attributes={},
                   objects=list(objects))


# ------------------------------------------------------------------------------------------------ scene objects
def _block(color: str, x: float, y: float) -> SceneObject:
    return SceneObject(f'{color} block', 'block', color, (x, y))


def _bowl(color: str, x: float, y: float) -> SceneObject:
    return SceneObject(f'{color} bowl', 'bowl', color, (x, y))


def _bowl_holding(bowl_color: str, block_color: str, x: float, y: float) -> list[SceneObject]:
    """A bowl with a block lying in it when the scene starts."""
    return [_bowl(bowl_color, x, y), _block(block_color, x, y)]


# ------------------------------------------------------------------------------------------------ conditions
def _xy(point: Sequence[float]) -> np.ndarray:
    return np.asarray(point, dtype=float)[:2]


def _gap(a: Sequence[float], b: Sequence[float]) -> float:
    return float(np.linalg.norm(_xy(a) - _xy(b)))


def _on(obj: str, target: str) -> Condition:
    """`obj` lies on/in `target`: an object or a named position (success.is_on's tolerances)."""
    return lambda scene, initial, final: is_on(obj, target, final, scene)


def _called(description: str, condition: Condition) -> Condition:
    """The condition, its failure prefixed with what the instruction called the object."""
    def check(scene: Episode, initial: Positions, final: Positions) -> Verdict:
        verdict = condition(scene, initial, final)
        return verdict if verdict else Verdict(False, f'{description}: {verdict.reason}')
    return check


def _where_started(obj: str, start_of: str | None = None) -> Condition:
    """`obj` lies within NEAR_PLACE of where `start_of` (default: itself) stood when the scene started."""
    start_of = start_of or obj

    def check(scene: Episode, initial: Positions, final: Positions) -> Verdict:
        gap = _gap(final[obj], initial[start_of])
        if gap <= NEAR_PLACE:
            return OK
        whose = 'its own' if start_of == obj else f"the {start_of}'s"
        return Verdict(False, f'{obj} is {gap:.3f} m from {whose} starting place (> {NEAR_PLACE})')
    return check


def _along_across(vector: np.ndarray, unit: np.ndarray) -> tuple[float, float]:
    """How far `vector` goes along `unit`, and how far sideways of it (unsigned)."""
    return float(vector @ unit), abs(float(vector @ np.array([-unit[1], unit[0]])))


def _shifted(obj: str, offset: Sequence[float], along_range: tuple[float, float], across_limit: float) -> Condition:
    """`obj` moved from its start in the direction of `offset` by a distance in `along_range`, and at most
    `across_limit` sideways."""
    unit = np.asarray(offset, dtype=float) / np.linalg.norm(offset)

    def check(scene: Episode, initial: Positions, final: Positions) -> Verdict:
        along, across = _along_across(_xy(final[obj]) - _xy(initial[obj]), unit)
        if not along_range[0] <= along <= along_range[1]:
            return Verdict(False, f'{obj} moved {along:.3f} m in the asked direction, not '
                                  f'{along_range[0]:.2f}-{along_range[1]:.2f} m')
        if across > across_limit:
            return Verdict(False, f'{obj} moved {across:.3f} m sideways (> {across_limit})')
        return OK
    return check


def _beside(obj: str, anchor: str, direction: str) -> Condition:
    """`obj` stands on the table to the `direction` of `anchor` (final positions), BESIDE_GAP away, on its line."""
    unit = np.array(table.DIRECTIONS[direction])

    def check(scene: Episode, initial: Positions, final: Positions) -> Verdict:
        along, across = _along_across(_xy(final[obj]) - _xy(final[anchor]), unit)
        if not BESIDE_GAP[0] <= along <= BESIDE_GAP[1]:
            return Verdict(False, f'{obj} is {along:.3f} m to the {direction} of the {anchor}, not '
                                  f'{BESIDE_GAP[0]}-{BESIDE_GAP[1]} m')
        if across > MAGNITUDE_PERPENDICULAR:
            return Verdict(False, f'{obj} is {across:.3f} m off the line through the {anchor} '
                                  f'(> {MAGNITUDE_PERPENDICULAR})')
        return OK
    return check


def _between(obj: str, first: str, second: str) -> Condition:
    """`obj` lies within MIDPOINT_TOLERANCE of the midpoint of `first` and `second` (final positions)."""
    def check(scene: Episode, initial: Positions, final: Positions) -> Verdict:
        midpoint = (_xy(final[first]) + _xy(final[second])) / 2
        gap = _gap(final[obj], midpoint)
        if gap <= MIDPOINT_TOLERANCE:
            return OK
        return Verdict(False, f'{obj} is {gap:.3f} m from the point halfway between the {first} and the {second} '
                              f'(> {MIDPOINT_TOLERANCE})')
    return check


def _tower(names: Sequence[str]) -> Condition:
    """Each block of `names` (lowest first) stands on the one before it, one block higher."""
    def check(scene: Episode, initial: Positions, final: Positions) -> Verdict:
        for lower, upper in zip(names, names[1:]):
            if not (verdict := is_on(upper, lower, final, scene)):
                return verdict
            step = final[upper][2] - final[lower][2]
            if not STACK_STEP[0] <= step <= STACK_STEP[1]:
                return Verdict(False, f'{upper} sits {step:.3f} m above the {lower}, not one block higher')
        return OK
    return check


def _row(names: Sequence[str], side: str) -> Condition:
    """The blocks of `names` stand in this order in a straight row along the named side (within NEAR_PLACE of its
    line, off it by at most LINE_SPREAD from each other, neighbours at least LINE_MIN_GAP apart)."""
    side_xy = np.array(table.NAMED_POSITIONS[side])
    inward = np.array(table.NAMED_POSITIONS['middle']) - side_xy
    inward = inward / np.linalg.norm(inward)
    along = np.array([-inward[1], inward[0]])  # the top side runs left to right, the left side upwards

    def check(scene: Episode, initial: Positions, final: Positions) -> Verdict:
        depths = [float((_xy(final[name]) - side_xy) @ inward) for name in names]
        for name, depth in zip(names, depths):
            if abs(depth) > NEAR_PLACE:
                return Verdict(False, f'{name} is {abs(depth):.3f} m from the line of the {side} (> {NEAR_PLACE})')
        if (spread := max(depths) - min(depths)) > LINE_SPREAD:
            return Verdict(False, f'the blocks are {spread:.3f} m out of line (> {LINE_SPREAD})')
        places = [float(_xy(final[name]) @ along) for name in names]
        for (first, a), (second, b) in zip(zip(names, places), zip(names[1:], places[1:])):
            if b - a < LINE_MIN_GAP:
                return Verdict(False, f'the {second} is {b - a:.3f} m past the {first} along the {side}, not '
                                      f'after it in the row (>= {LINE_MIN_GAP})')
        return OK
    return check


def _judge(scene: Episode, conditions: Iterable[Condition], moves: Iterable[str]) -> Judge:
    """All conditions, then: every object not in `moves` stayed within UNTOUCHED of its start."""
    conditions, moves = tuple(conditions), frozenset(moves)

    def judge(initial: Positions, final: Positions) -> Verdict:
        missing = sorted({o.name for o in scene.objects} - (set(final) & set(initial)))
        if missing:
            return Verdict(False, f'the state lacks objects: {", ".join(missing)}')
        for condition in conditions:
            if not (verdict := condition(scene, initial, final)):
                return verdict
        for obj in scene.objects:
            if obj.name not in moves and (shift := _gap(initial[obj.name], final[obj.name])) > UNTOUCHED:
                return Verdict(False, f'{obj.name} was not to be moved but moved {shift:.3f} m')
        return OK
    return judge


def _command(key: str, instructions: str | tuple[str, ...], objects: Sequence[SceneObject],
             reference: str | tuple[str, ...], conditions: Sequence[Condition], moves: Sequence[str]) -> DevCommand:
    instructions = (instructions,) if isinstance(instructions, str) else instructions
    reference = (reference,) if isinstance(reference, str) else reference
    judge = _judge(_episode(key, instructions, objects), conditions, moves)
    return DevCommand(key, instructions, tuple(objects), judge, reference)


# ------------------------------------------------------------------------------------------------ references
def _put(obj: str, target: str) -> str:
    return f'put_first_on_second({obj!r}, {target})\n'


def _remember(*names: str) -> str:
    """Record where the objects stand before they move (what "undo that" or "put it back" needs)."""
    return f'moved = [(name, get_obj_pos(name)) for name in {list(names)!r}]\n'


_BLOCKS = "block_names = [name for name in get_obj_names() if name.endswith('block')]\n"
_BOWLS = "bowl_names = [name for name in get_obj_names() if name.endswith('bowl')]\n"
_IN_A_BOWL = ("def in_a_bowl(name):\n"
              "    return any(np.linalg.norm(get_obj_pos(name) - get_obj_pos(bowl)) < "
              f"{IN_BOWL} for bowl in bowl_names)\n")


# ------------------------------------------------------------------------------------------------ the commands
def _commands() -> tuple[DevCommand, ...]:
    row = ('red block', 'green block', 'blue block')
    return (
        _command('bowl_by_name', 'drop the yellow block into the red bowl',
                 [_block('yellow', -0.1, -0.4), _block('green', 0.1, -0.62), _bowl('red', 0.12, -0.4),
                  _bowl('blue', -0.12, -0.6)],
                 _put('yellow block', "'red bowl'"), [_on('yellow block', 'red bowl')], ['yellow block']),
        _command('block_on_block', 'put the green block on top of the orange block',
                 [_block('green', -0.15, -0.45), _block('orange', 0.1, -0.5), _block('blue', 0.0, -0.65),
                  _bowl('yellow', -0.05, -0.32), _bowl('red', 0.15, -0.32)],
                 _put('green block', "'orange block'"), [_on('green block', 'orange block')], ['green block']),
        _command('two_blocks_one_bowl', 'put the red block and the blue block in the yellow bowl',
                 [_block('red', -0.15, -0.35), _block('blue', 0.15, -0.6), _block('green', 0.0, -0.5),
                  _bowl('yellow', -0.1, -0.62), _bowl('orange', 0.12, -0.36)],
                 _put('red block', "'yellow bowl'") + _put('blue block', "'yellow bowl'"),
                 [_on('red block', 'yellow bowl'), _on('blue block', 'yellow bowl')], ['red block', 'blue block']),
        _command('colour_sort', 'sort the blocks into the bowls of the same colour',
                 [_block('blue', -0.15, -0.35), _block('red', 0.0, -0.55), _block('yellow', 0.16, -0.4),
                  _bowl('blue', 0.1, -0.68), _bowl('red', -0.15, -0.6), _bowl('yellow', -0.02, -0.36)],
                 _BLOCKS + "for name in block_names:\n"
                           "    bowl = name.replace('block', 'bowl')\n"
                           "    if bowl in get_obj_names():\n"
                           "        put_first_on_second(name, bowl)\n",
                 [_on(f'{c} block', f'{c} bowl') for c in ('blue', 'red', 'yellow')],
                 ['blue block', 'red block', 'yellow block']),
        _command('tower', 'build a tower: the red block first, then the green block, then the yellow block on top',
                 [_block('red', 0.0, -0.5), _block('green', -0.15, -0.35), _block('yellow', 0.15, -0.62),
                  _block('blue', 0.15, -0.35), _bowl('orange', -0.12, -0.62)],
                 _put('green block', "'red block'") + _put('yellow block', "'green block'"),
                 [_tower(('red block', 'green block', 'yellow block'))], ['red block', 'green block', 'yellow block']),
        _command('to_middle', 'move the blue block to the middle of the table',
                 [_block('blue', -0.15, -0.6), _block('red', 0.14, -0.38), _bowl('green', 0.12, -0.62),
                  _bowl('yellow', -0.12, -0.36)],
                 _put('blue block', position_code('middle')), [_on('blue block', 'middle')], ['blue block']),
        _command('to_corner', 'put the orange block in the top right corner',
                 [_block('orange', -0.1, -0.55), _block('blue', 0.05, -0.4), _bowl('red', -0.1, -0.35),
                  _bowl('green', 0.12, -0.6)],
                 _put('orange block', position_code('top right corner')), [_on('orange block', 'top right corner')],
                 ['orange block']),
        _command('to_side', 'move the red block over to the left side',
                 [_block('red', 0.1, -0.45), _block('yellow', -0.05, -0.62), _bowl('blue', -0.1, -0.36),
                  _bowl('orange', 0.12, -0.63)],
                 _put('red block', position_code('left side')), [_on('red block', 'left side')], ['red block']),
        _command('ten_cm_left', 'move the green block 10 cm to the left',
                 [_block('green', 0.05, -0.5), _block('red', -0.15, -0.4), _bowl('yellow', 0.0, -0.66),
                  _bowl('blue', 0.15, -0.35)],
                 _put('green block', "get_obj_pos('green block') + np.array([-0.1, 0.0])"),
                 [_shifted('green block', (-0.1, 0.0), (0.1 - SHIFT_TOLERANCE, 0.1 + SHIFT_TOLERANCE),
                           SHIFT_TOLERANCE)], ['green block']),
        _command('bit_towards_top', 'shift the yellow block a bit towards the top',
                 [_block('yellow', -0.05, -0.55), _block('orange', 0.15, -0.45), _bowl('red', -0.15, -0.35),
                  _bowl('green', 0.1, -0.65)],
                 _put('yellow block', f"get_obj_pos('yellow block') + np.array([0.0, {A_BIT}])"),
                 [_shifted('yellow block', table.DIRECTIONS['top'], MAGNITUDE_RANGE['a little'],
                           MAGNITUDE_PERPENDICULAR)], ['yellow block']),
        _command('halfway_between', 'place the orange block halfway between the red block and the yellow block',
                 [_block('red', -0.15, -0.45), _block('yellow', 0.15, -0.45), _block('orange', 0.0, -0.65),
                  _bowl('blue', 0.0, -0.32), _bowl('green', 0.15, -0.62)],
                 _put('orange block', "(get_obj_pos('red block') + get_obj_pos('yellow block')) / 2"),
                 [_between('orange block', 'red block', 'yellow block')], ['orange block']),
        _command('just_left_of', 'place the red block just left of the orange block',
                 [_block('orange', 0.05, -0.5), _block('red', 0.15, -0.35), _block('green', -0.12, -0.65),
                  _bowl('yellow', 0.1, -0.66), _bowl('blue', -0.12, -0.35)],
                 _put('red block', f"get_obj_pos('orange block') + np.array([{-NEXT_TO_OFFSET}, 0.0])"),
                 [_beside('red block', 'orange block', 'left')], ['red block']),
        _command('swap', 'swap the red block and the green block',
                 [_block('red', -0.12, -0.38), _block('green', 0.12, -0.62), _block('yellow', 0.15, -0.36),
                  _bowl('blue', -0.14, -0.62)],
                 "red_xy = get_obj_pos('red block')\ngreen_xy = get_obj_pos('green block')\n"
                 + _put('red block', position_code(SWAP_PARKING)) + _put('green block', 'red_xy')
                 + _put('red block', 'green_xy'),
                 [_where_started('red block', 'green block'), _where_started('green block', 'red block')],
                 ['red block', 'green block']),
        _command('leftmost_block', 'put the leftmost block in the blue bowl',
                 [_block('green', -0.17, -0.5), _block('red', 0.0, -0.35), _block('yellow', 0.05, -0.6),
                  _block('orange', 0.18, -0.42), _bowl('blue', 0.17, -0.65), _bowl('red', -0.15, -0.33)],
                 _BLOCKS + "leftmost = min(block_names, key=lambda name: get_obj_pos(name)[0])\n"
                           "put_first_on_second(leftmost, 'blue bowl')\n",
                 [_called('the leftmost block (the green block)', _on('green block', 'blue bowl'))], ['green block']),
        _command('nearest_block', 'put the block nearest to the yellow block into the red bowl',
                 [_block('yellow', 0.0, -0.5), _block('blue', 0.12, -0.42), _block('orange', -0.15, -0.62),
                  _block('green', -0.12, -0.33), _bowl('red', 0.13, -0.64)],
                 _BLOCKS + "others = [name for name in block_names if name != 'yellow block']\n"
                           "nearest = min(others, key=lambda name: np.linalg.norm(get_obj_pos(name) - "
                           "get_obj_pos('yellow block')))\n"
                           "put_first_on_second(nearest, 'red bowl')\n",
                 [_called('the block nearest the yellow block (the blue block)', _on('blue block', 'red bowl'))],
                 ['blue block']),
        _command('undo_last', ('put the green block on the red block', 'now put the yellow block in the blue bowl',
                               'undo that'),
                 [_block('green', -0.15, -0.4), _block('red', 0.05, -0.35), _block('yellow', 0.15, -0.55),
                  _block('orange', 0.0, -0.52), _bowl('blue', -0.1, -0.62)],
                 (_remember('green block') + _put('green block', "'red block'"),
                  _remember('yellow block') + _put('yellow block', "'blue bowl'"),
                  "for name, xy in reversed(moved):\n    put_first_on_second(name, xy)\nmoved = []\n"),
                 [_on('green block', 'red block'), _called('undone', _where_started('yellow block'))],
                 ['green block', 'yellow block']),
        # The blue block goes in second, on top of the red one: taking it out lifts nothing else.
        _command('put_back', ('put the red block and the blue block in the green bowl',
                              'take the blue block out again and put it back where it was'),
                 [_block('blue', -0.15, -0.4), _block('red', 0.15, -0.4), _block('yellow', 0.0, -0.35),
                  _bowl('green', 0.0, -0.6), _bowl('orange', -0.15, -0.62)],
                 (_remember('red block', 'blue block') + _put('red block', "'green bowl'")
                  + _put('blue block', "'green bowl'"),
                  "start_xy = dict(moved)\nput_first_on_second('blue block', start_xy['blue block'])\n"),
                 [_on('red block', 'green bowl'), _called('put back', _where_started('blue block'))],
                 ['blue block', 'red block']),
        _command('row_along_top', 'put the red, green and blue blocks in a row along the top side, in that order '
                                  'from the left',
                 [_block('red', 0.1, -0.45), _block('green', -0.1, -0.55), _block('blue', 0.12, -0.65),
                  _block('orange', 0.0, -0.4), _bowl('yellow', -0.15, -0.38)],
                 f"row_xy = {position_code('top side')}\n"
                 f"for i, name in enumerate({list(row)!r}):\n"
                 f"    put_first_on_second(name, row_xy + np.array([(i - 1) * {ROW_SPACING}, 0.0]))\n",
                 [_row(row, 'top side')], row),
        _command('empty_bowl', 'put the orange block in the empty bowl',
                 [*_bowl_holding('blue', 'green', -0.12, -0.4), *_bowl_holding('yellow', 'red', 0.12, -0.62),
                  _bowl('red', 0.14, -0.38), _block('orange', -0.1, -0.62)],
                 _BLOCKS + _BOWLS
                 + "empty = [bowl for bowl in bowl_names if all(np.linalg.norm(get_obj_pos(bowl) - get_obj_pos(name))"
                   f" >= {IN_BOWL} for name in block_names)]\n"
                   "put_first_on_second('orange block', empty[0])\n",
                 [_called('the empty bowl (the red bowl)', _on('orange block', 'red bowl'))], ['orange block']),
        _command('out_of_bowl', 'take the green block out of the blue bowl and put it in the top left corner',
                 [*_bowl_holding('blue', 'green', 0.1, -0.45), _block('red', -0.12, -0.6),
                  _bowl('yellow', -0.1, -0.4), _block('orange', 0.12, -0.65)],
                 _put('green block', position_code('top left corner')), [_on('green block', 'top left corner')],
                 ['green block']),
        _command('loose_blocks', "collect the blocks that aren't in any bowl into the orange bowl",
                 [*_bowl_holding('yellow', 'red', -0.12, -0.4), _bowl('orange', 0.12, -0.6),
                  _block('blue', 0.12, -0.38), _block('green', -0.1, -0.62)],
                 _BLOCKS + _BOWLS + _IN_A_BOWL + "for name in block_names:\n"
                          "    if not in_a_bowl(name):\n"
                          "        put_first_on_second(name, 'orange bowl')\n",
                 [_on('blue block', 'orange bowl'), _on('green block', 'orange bowl')],
                 ['blue block', 'green block']),
        _command('two_corners', 'put the red block in the top left corner and the blue block in the top right corner',
                 [_block('red', 0.1, -0.5), _block('blue', -0.1, -0.5), _bowl('green', 0.0, -0.35),
                  _block('yellow', 0.0, -0.65)],
                 _put('red block', position_code('top left corner'))
                 + _put('blue block', position_code('top right corner')),
                 [_on('red block', 'top left corner'), _on('blue block', 'top right corner')],
                 ['red block', 'blue block']),
    )


COMMANDS: tuple[DevCommand, ...] = _commands()
BY_KEY: dict[str, DevCommand] = {command.key: command for command in COMMANDS}


def select(keys: Iterable[str] = ()) -> tuple[DevCommand, ...]:
    """The commands with these keys in this order (all of them for none); KeyError names unknown keys."""
    keys = [key for key in keys if key]
    unknown = [key for key in keys if key not in BY_KEY]
    if unknown:
        raise KeyError(f'unknown dev command(s): {", ".join(unknown)}; known: {", ".join(BY_KEY)}')
    return tuple(BY_KEY[key] for key in keys) if keys else COMMANDS
