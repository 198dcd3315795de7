"""Reference programs: one per template, written against the robot API seen by generated code.

Given an episode's attribute values (not its resolved referents), each program finds what the instruction refers to
through the API at run time, exactly as a model-written program would, and is executed through the same sandboxed
path. Their success rate measures the robot stack alone.
"""
from __future__ import annotations

import numpy as np

from cap_bench.tabletop import table
from cap_bench.tabletop.episodes import MAGNITUDE_DISTANCES, ORDINALS, Episode
from cap_tabletop.objects import BLOCK_SIZE, BOWL_RIM_RADIUS
from cap_control.pick_place.plan import PickPlaceConfig
from cap_tabletop.workspace import NORMALISED_ORIGIN, NORMALISED_SPAN, TABLE_X_RANGE, TABLE_Y_RANGE

_BLOCKS = "block_names = [name for name in get_obj_names() if name.endswith('block')]\n"
# A block's centre stays this far inside the table's edges when placed (half of it and the robot's edge margin).
_BLOCK_REACH = BLOCK_SIZE / 2 + PickPlaceConfig().edge_margin
# Room from a spot to a bowl's rim that a block set down there needs (half its diagonal, and a little more).
_RIM_ROOM = BLOCK_SIZE / np.sqrt(2) + 0.002
_BOWLS = "bowl_names = [name for name in get_obj_names() if name.endswith('bowl')]\n"


def position_code(name: str) -> str:
    """The named position as generated code would write it, in normalised table coordinates."""
    normalised = (np.array(table.NAMED_POSITIONS[name]) - NORMALISED_ORIGIN) / NORMALISED_SPAN
    return f'denormalize_xy({[float(v) for v in normalised]})'


def _unit(direction: str) -> str:
    return f'np.array({list(table.DIRECTIONS[direction])})'


def oracle_program(episode: Episode) -> str:
    """The reference program for this episode's template and attribute values."""
    a = episode.attributes
    template = episode.template
    if template == 'pick_place':
        return f"put_first_on_second({a['block1']!r}, {a['target']!r})\n"
    if template == 'stack':
        return (_BLOCKS + "for lower, upper in zip(block_names, block_names[1:]):\n"
                          "    put_first_on_second(upper, lower)\n")
    if template == 'blocks_on_corner':
        return _BLOCKS + _corner_program(a['corner_side'])
    if template == 'blocks_in_bowl':
        return _BLOCKS + f"for name in block_names:\n    put_first_on_second(name, {a['bowl']!r})\n"
    if template == 'matching_bowls':
        return (_BLOCKS + "for name in block_names:\n"
                          "    put_first_on_second(name, name.replace('block', 'bowl'))\n")
    if template == 'mismatched_bowls':
        return (_BLOCKS + _BOWLS + "load = {bowl: 0 for bowl in bowl_names}\n"
                "for name in block_names:\n"
                "    others = [bowl for bowl in bowl_names if bowl.split()[0] != name.split()[0]]\n"
                "    bowl = min(others, key=lambda b: load[b])\n"
                "    load[bowl] += 1\n"
                "    put_first_on_second(name, bowl)\n")
    if template == 'block_by_direction':
        return (_BLOCKS + f"bowl_xy = get_obj_pos({a['bowl']!r})\n"
                f"ahead = [np.dot(get_obj_pos(name) - bowl_xy, {_unit(a['direction'])}) for name in block_names]\n"
                "block = block_names[int(np.argmax(ahead))]\n"
                f"put_first_on_second(block, {position_code(a['corner_side'])})\n")
    if template == 'block_by_distance':
        pick = 'argmax' if a['distance'] == 'farthest' else 'argmin'
        return (_BLOCKS + f"bowl_xy = get_obj_pos({a['bowl']!r})\n"
                "distances = [np.linalg.norm(get_obj_pos(name) - bowl_xy) for name in block_names]\n"
                f"block = block_names[int(np.{pick}(distances))]\n"
                f"put_first_on_second(block, {position_code(a['corner_side'])})\n")
    if template == 'nth_block':
        return (_BLOCKS + f"ordered = sorted(block_names, key=lambda name: -np.dot(get_obj_pos(name), "
                f"{_unit(a['direction'])}))\n"
                f"put_first_on_second(ordered[{ORDINALS[a['nth']]}], {position_code(a['corner_side'])})\n")
    if template == 'different_corners':
        corners = ', '.join(position_code(c) for c in table.CORNERS)
        return (_BLOCKS + f"corners = [{corners}]\n"
                          "for name, corner in zip(block_names, corners):\n    put_first_on_second(name, corner)\n")
    if template == 'stack_on_corner':
        return (_BLOCKS + f"put_first_on_second(block_names[0], {position_code(a['corner_side'])})\n"
                          "for lower, upper in zip(block_names, block_names[1:]):\n"
                          "    put_first_on_second(upper, lower)\n")
    if template == 'place_by_magnitude':
        distance = MAGNITUDE_DISTANCES[a['magnitude']]
        return (f"target_xy = get_obj_pos({a['bowl']!r}) + {_unit(a['direction'])} * {distance}\n"
                f"put_first_on_second({a['block1']!r}, target_xy)\n")
    if template == 'corner_by_distance':
        pick = 'max' if a['distance'] == 'farthest' else 'min'
        corners = ', '.join(position_code(c) for c in table.CORNERS)
        return (f"bowl_xy = get_obj_pos({a['bowl']!r})\n"
                f"corner = {pick}([{corners}], key=lambda xy: np.linalg.norm(xy - bowl_xy))\n"
                f"put_first_on_second({a['block1']!r}, corner)\n")
    if template == 'line':
        return _BLOCKS + _line_program(a['line'])
    raise ValueError(f'no reference program for template {template!r}')


def _corner_program(place: str) -> str:
    # Two short stacks side by side, far enough apart (7.5 cm) that the open fingers clear the neighbour whichever
    # way they close: every block within 0.045 m of the place, and no tower tall enough to topple. The pair stands
    # across the line to the table's middle, 1.5 cm in from the place, so that at a corner neither block hangs over
    # an edge. With a bowl's rim within reach of a spot, the pair is turned and shifted (on the table, still within
    # 0.045 m) to where its spots keep farthest from the rims. The blocks nearest the place go first, so that none
    # still stands on a spot when a block is set down there.
    (x_low, x_high), (y_low, y_high) = ((low + _BLOCK_REACH, high - _BLOCK_REACH)
                                        for low, high in (TABLE_X_RANGE, TABLE_Y_RANGE))
    return (f"target_xy = {position_code(place)}\n"
            "block_names = sorted(block_names, key=lambda name: np.linalg.norm(get_obj_pos(name) - target_xy))\n"
            f"inward = np.array({list(table.SIDES['middle'])}) - target_xy\n"
            "inward = inward / np.linalg.norm(inward)\n"
            "along = np.array([-inward[1], inward[0]])\n"
            "spots = [target_xy + 0.015 * inward - 0.0375 * along, target_xy + 0.015 * inward + 0.0375 * along]\n"
            "bowl_xy = [get_obj_pos(name) for name in get_obj_names() if name.endswith('bowl')]\n"
            "def room(pair):\n"
            f"    return min([np.linalg.norm(spot - xy) - {BOWL_RIM_RADIUS:.3f} for spot in pair for xy in bowl_xy] "
            "+ [1.0])\n"
            f"if room(spots) < {_RIM_ROOM:.3f}:\n"
            "    pairs = []\n"
            "    for turn in np.radians(np.arange(-90, 91, 10)):\n"
            "        turned = np.array([np.cos(turn) * along[0] - np.sin(turn) * along[1],\n"
            "                           np.sin(turn) * along[0] + np.cos(turn) * along[1]])\n"
            "        for shift_in in (0.0, 0.015, 0.03):\n"
            "            for shift_along in (-0.015, 0.0, 0.015):\n"
            "                centre = target_xy + shift_in * inward + shift_along * turned\n"
            "                pair = [centre - 0.0375 * turned, centre + 0.0375 * turned]\n"
            f"                if all({x_low:.3f} <= x <= {x_high:.3f} and {y_low:.3f} <= y <= {y_high:.3f} and "
            "np.linalg.norm(np.array([x, y]) - target_xy) <= 0.045 for x, y in pair):\n"
            "                    pairs.append(pair)\n"
            "    spots = max([spots] + pairs, key=room)\n"
            "for i, name in enumerate(block_names):\n"
            "    if i < 2:\n"
            "        put_first_on_second(name, spots[i])\n"
            "    else:\n"
            "        put_first_on_second(name, block_names[i - 2])\n")


def _line_program(kind: str) -> str:
    # Blocks 0.1 m apart along the line. The line's centre (and, for a diagonal, which diagonal) is searched over
    # the middle of the table for where its spots keep farthest from the objects' footprints as they stand (a
    # bowl's rim, a block's side), so that no block lands on a rim or on a block still waiting to be moved, and
    # the fingers have room beside each spot.
    if kind == 'horizontal':
        directions = '[np.array([1.0, 0.0])]'
    elif kind == 'vertical':
        directions = '[np.array([0.0, 1.0])]'
    else:
        directions = '[np.array([1.0, 1.0]) / np.sqrt(2), np.array([1.0, -1.0]) / np.sqrt(2)]'
    return ("offsets = (np.arange(len(block_names)) - (len(block_names) - 1) / 2) * 0.1\n"
            "others = np.array([get_obj_pos(name) for name in get_obj_names()])\n"
            f"radii = np.array([{BOWL_RIM_RADIUS:.3f} if name.endswith('bowl') else {BLOCK_SIZE / 2:.3f} "
            "for name in get_obj_names()])\n"
            "def clearance(line):\n"
            "    return np.min(np.linalg.norm(line[:, None, :] - others[None, :, :], axis=2) - radii[None, :])\n"
            "candidates = [offsets[:, None] * direction + np.array([x, y])\n"
            f"              for direction in {directions}\n"
            "              for x in np.linspace(-0.1, 0.1, 11) for y in np.linspace(-0.6, -0.4, 11)]\n"
            "best = max(candidates, key=clearance)\n"
            "for name, xy in zip(block_names, best):\n"
            "    put_first_on_second(name, xy)\n")
