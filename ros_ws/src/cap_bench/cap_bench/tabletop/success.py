"""One success checker per instruction template, on the simulator's final state.

An episode succeeds when its final state meets the template's condition within the tolerances below (e.g. a block
"in" a bowl lies within NEAR_PLACE of its centre; objects the instruction does not name moved less than UNTOUCHED).

Positions are world-frame (x, y, z) in metres; distances are in the table plane unless stated. Every failure comes
with a reason a developer can act on, naming the object and the measured distance.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

import numpy as np

from cap_bench.tabletop import table
from cap_bench.tabletop.episodes import Episode

NEAR_PLACE = 0.06  # "on / in" a bowl, corner or side
NEAR_BLOCK = 0.04  # "on" a block (and higher than it)
UNTOUCHED = 0.05  # objects a single-object task does not name may move at most this much
STACK_STEP = (0.03, 0.05)  # consecutive heights in a stack differ by about one block (0.04 m)
MAGNITUDE_RANGE = {'a little': (0.03, 0.15), 'a lot': (0.15, float('inf'))}
MAGNITUDE_PERPENDICULAR = 0.05
LINE_SPREAD = 0.03
LINE_MIN_GAP = 0.045
DIAGONAL_ANGLE = (25.0, 65.0)  # 45° ± 20°, either diagonal

Positions = Mapping[str, Sequence[float]]


@dataclass(frozen=True)
class Verdict:
    success: bool
    reason: str = ''

    def __bool__(self) -> bool:
        return self.success


OK = Verdict(True)


def _xy(point) -> np.ndarray:
    return np.asarray(point, dtype=float)[:2]


def _distance(a, b) -> float:
    return float(np.linalg.norm(_xy(a) - _xy(b)))


def is_on(obj: str, target: str, final: Positions, episode: Episode) -> Verdict:
    """Is `obj` on/in `target` (an object name or a named position)?"""
    if target in table.NAMED_POSITIONS:
        gap = _distance(final[obj], table.NAMED_POSITIONS[target])
        return OK if gap <= NEAR_PLACE else Verdict(False, f'{obj} is {gap:.3f} m from the {target} (> {NEAR_PLACE})')
    gap = _distance(final[obj], final[target])
    if target in episode.bowls:
        return OK if gap <= NEAR_PLACE else Verdict(False, f'{obj} is {gap:.3f} m from the {target} (> {NEAR_PLACE})')
    if gap > NEAR_BLOCK:
        return Verdict(False, f'{obj} is {gap:.3f} m from the {target} (> {NEAR_BLOCK})')
    if final[obj][2] <= final[target][2]:
        return Verdict(False, f'{obj} is beside the {target}, not on top (z {final[obj][2]:.3f} <= '
                              f'{final[target][2]:.3f})')
    return OK


def _others_untouched(episode: Episode, moved: str, initial: Positions, final: Positions) -> Verdict:
    for name in initial:
        if name != moved and (shift := _distance(initial[name], final[name])) > UNTOUCHED:
            return Verdict(False, f'{name} was not to be moved but moved {shift:.3f} m')
    return OK


def _all(verdicts) -> Verdict:
    for verdict in verdicts:
        if not verdict:
            return verdict
    return OK


def _single(episode: Episode, initial: Positions, final: Positions, target: str) -> Verdict:
    block = episode.referents['block']
    return _all((is_on(block, target, final, episode), _others_untouched(episode, block, initial, final)))


def _stack(episode: Episode, final: Positions) -> tuple[Verdict, str]:
    """Whether the blocks form one stack; also the name of its bottom block."""
    ordered = sorted(episode.blocks, key=lambda b: final[b][2])
    bottom = ordered[0]
    for lower, upper in zip(ordered, ordered[1:]):
        if (gap := _distance(final[upper], final[bottom])) > NEAR_BLOCK:
            return Verdict(False, f'{upper} is {gap:.3f} m off the stack on the {bottom} (> {NEAR_BLOCK})'), bottom
        step = final[upper][2] - final[lower][2]
        if not STACK_STEP[0] <= step <= STACK_STEP[1]:
            return Verdict(False, f'{upper} sits {step:.3f} m above the {lower}, not one block higher'), bottom
    return OK, bottom


def _matching(episode: Episode, final: Positions, want_same: bool) -> Verdict:
    for block in episode.blocks:
        color = block.split()[0]
        bowls = [b for b in episode.bowls if (b.split()[0] == color) == want_same]
        if not bowls:
            return Verdict(False, f'no bowl fits {block}')
        nearest = min(bowls, key=lambda b: _distance(final[block], final[b]))
        if not (verdict := is_on(block, nearest, final, episode)):
            kind = 'its matching bowl' if want_same else 'a bowl of another colour'
            return Verdict(False, f'{block} is not in {kind}: {verdict.reason}')
    return OK


def _different_corners(episode: Episode, final: Positions) -> Verdict:
    corners = {}
    for block in episode.blocks:
        corner = min(table.CORNERS, key=lambda c: _distance(final[block], table.CORNERS[c]))
        if not (verdict := is_on(block, corner, final, episode)):
            return Verdict(False, f'{block} is in no corner: {verdict.reason}')
        if corner in corners:
            return Verdict(False, f'{block} and {corners[corner]} share the {corner}')
        corners[corner] = block
    return OK


def _magnitude(episode: Episode, initial: Positions, final: Positions) -> Verdict:
    block, bowl = episode.referents['block'], episode.referents['bowl']
    unit = np.array(table.DIRECTIONS[episode.attributes['direction']])
    offset = _xy(final[block]) - _xy(final[bowl])
    along = float(offset @ unit)
    across = abs(float(offset @ np.array([-unit[1], unit[0]])))
    low, high = MAGNITUDE_RANGE[episode.attributes['magnitude']]
    if not low <= along <= high:
        return Verdict(False, f'{block} is {along:.3f} m to the {episode.attributes["direction"]} of the {bowl}; '
                              f'"{episode.attributes["magnitude"]}" means {low}-{high} m')
    if across > MAGNITUDE_PERPENDICULAR:
        return Verdict(False, f'{block} is {across:.3f} m off the line from the {bowl} (> {MAGNITUDE_PERPENDICULAR})')
    return _others_untouched(episode, block, initial, final)


def _line(episode: Episode, final: Positions) -> Verdict:
    kind = episode.attributes['line']
    points = np.array([_xy(final[b]) for b in episode.blocks])
    if kind == 'horizontal':
        spread, order_axis = np.ptp(points[:, 1]), 0
    elif kind == 'vertical':
        spread, order_axis = np.ptp(points[:, 0]), 1
    else:
        centred = points - points.mean(axis=0)
        _, _, axes = np.linalg.svd(centred)
        direction = axes[0]
        angle = np.degrees(np.arctan2(abs(direction[1]), abs(direction[0])))
        if not DIAGONAL_ANGLE[0] <= angle <= DIAGONAL_ANGLE[1]:
            return Verdict(False, f'the blocks line up at {angle:.0f}° from the x axis, not diagonally')
        spread = float(np.max(np.abs(centred @ axes[1])))
        points = np.column_stack([centred @ direction, np.zeros(len(points))])
        order_axis = 0
    if spread > LINE_SPREAD:
        return Verdict(False, f'the blocks are {spread:.3f} m off a {kind} line (> {LINE_SPREAD})')
    along = np.sort(points[:, order_axis])
    if len(along) > 1 and (gap := float(np.min(np.diff(along)))) < LINE_MIN_GAP:
        return Verdict(False, f'neighbouring blocks in the line are {gap:.3f} m apart (< {LINE_MIN_GAP}); stacked?')
    return OK


def _stack_on(episode: Episode, final: Positions, place: str | None) -> Verdict:
    verdict, bottom = _stack(episode, final)
    if verdict and place is not None:
        return is_on(bottom, place, final, episode)
    return verdict


CHECKERS: dict[str, Callable[[Episode, Positions, Positions], Verdict]] = {
    'pick_place': lambda e, i, f: _single(e, i, f, e.referents['target']),
    'stack': lambda e, i, f: _stack_on(e, f, None),
    'blocks_on_corner': lambda e, i, f: _all(is_on(b, e.referents['target'], f, e) for b in e.blocks),
    'blocks_in_bowl': lambda e, i, f: _all(is_on(b, e.referents['target'], f, e) for b in e.blocks),
    'matching_bowls': lambda e, i, f: _matching(e, f, want_same=True),
    'block_by_direction': lambda e, i, f: _single(e, i, f, e.referents['target']),
    'block_by_distance': lambda e, i, f: _single(e, i, f, e.referents['target']),
    'nth_block': lambda e, i, f: _single(e, i, f, e.referents['target']),
    'different_corners': lambda e, i, f: _different_corners(e, f),
    'mismatched_bowls': lambda e, i, f: _matching(e, f, want_same=False),
    'stack_on_corner': lambda e, i, f: _stack_on(e, f, e.attributes['corner_side']),
    'place_by_magnitude': _magnitude,
    'corner_by_distance': lambda e, i, f: _single(e, i, f, e.referents['target']),
    'line': lambda e, i, f: _line(e, f),
}


def check(episode: Episode, initial: Positions, final: Positions) -> Verdict:
    """Judge an episode: `initial` and `final` map every object name to its (x, y, z) position."""
    missing = sorted(set(initial) ^ set(final) | set(o.name for o in episode.objects) - set(final))
    if missing:
        return Verdict(False, f'the final state lacks objects: {", ".join(missing)}')
    return CHECKERS[episode.template](episode, initial, final)


__all__ = ['CHECKERS', 'Verdict', 'check', 'is_on']
