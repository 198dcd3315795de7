"""The mobile benchmark's episodes: seeded instructions from templates, the objects in the kitchen, and the reference
(oracle) program of every instruction.

Templates (this project's; the paper reports no number for this domain):
- goto: "go to the desk" (a named location; the base must end within 5 cm and 0.05 rad of its approach pose);
- rectangle: "move in a 2.5m by 1.5m rectangle around the chair" (every corner reached within 5 cm, the base never
  over the location's footprint);
- back_and_forth: "move back and forth between the table and the desk 2 times" (the visits in that order);
- fetch: "bring the coke can to the countertop" (it ends standing on that piece of furniture, within 5 cm of the
  spot the program chose: the furniture's centre);
- bin: "go to the blue bin", "this is the compost bin", "put the apple in the compost bin" (the bins are named by
  colour; which one is the compost bin is what the user says, drawn per episode, and the program must
  remember it; the apple ends inside the blue bin);
- count: "how many snacks are on the table?" (the last number said is the count the simulator has);
- search: the paper's "go in a 1.5m square around the barstool as many times as needed, check each step if there is a
  banana, only stop moving when you see the banana" (any location whose square has its corners on free floor, a
  side of SIDES, any object of the scene the head camera sees from a corner of the square, facing the location's
  centre, and not from the start pose: decided on a headless simulator, cap_bench.mobile.sightlines; the base must
  go round the corners in order and stop at the first one from which the object is seen, and see it there).
Every episode stands six or seven objects on the table, the countertop and the desk (cap_mobile.objects); a
fetch's object starts on another piece of furniture than its destination, whose centre is kept free.

A reference program depends only on its instruction's words (one cassette serves every episode).
"""
from __future__ import annotations

import dataclasses
import math
import re
from typing import Sequence

import numpy as np
from cap_mobile import layout, objects

from cap_bench.mobile import sightlines
from cap_bringup.base_path import rectangle_corners
from cap_control.navigation.executor import NavigationConfig

TEMPLATES = ('goto', 'rectangle', 'back_and_forth', 'fetch', 'bin', 'count', 'search')
GOTO_PLACES = tuple(layout.LOCATION_NAMES)
AROUND = ('office chair', 'chair', 'barstool')  # what rectangles go around
SIDES = (1.5, 2.0, 2.5, 3.0)  # [m] a rectangle's sides
PLACES_KEPT_FREE = 0.2  # [m] around a fetch's destination spot, no object at the start
_GRID = NavigationConfig().grid()


@dataclasses.dataclass(frozen=True)
class KitchenObject:
    name: str
    xy: tuple[float, float]


@dataclasses.dataclass(frozen=True)
class Episode:
    template: str
    seed: int
    instructions: tuple[str, ...]
    objects: tuple[KitchenObject, ...]
    attributes: dict

    @property
    def key(self) -> str:
        return f'{self.template}/{self.seed}'


# ------------------------------------------------------------------------------------------- oracle programs
def oracle_program(instruction: str) -> str:
    """The reference program of an instruction of any template (its words say everything the program needs)."""
    text = instruction.strip().rstrip('.?').lower()
    if match := re.fullmatch(r'go to the (.+)', text):
        return f'goto_loc({match[1]!r})'
    if match := re.fullmatch(r'move in a ([\d.]+)m by ([\d.]+)m rectangle around the (.+)', text):
        half_w, half_h = float(match[1]) / 2, float(match[2]) / 2
        return (f'center = get_loc_pos({match[3]!r})\n'
                f'corners = np.array([{_corner_rows(half_w, half_h)}, [-{half_w}, -{half_h}]])\n'
                'follow_traj(center + corners)')
    if match := re.fullmatch(SEARCH_PATTERN, text):
        return _search_program(match['around'], float(match['side']), match['object'])
    if match := re.fullmatch(r'move back and forth between the (.+) and the (.+) (\d+) times', text):
        return f'for _ in range({int(match[3])}):\n    goto_loc({match[1]!r})\n    goto_loc({match[2]!r})'
    if match := re.fullmatch(r'bring the (.+) to the (.+)', text):
        return f'pick_obj({match[1]!r})\nplace_at_pos(get_loc_pos({match[2]!r}))'
    if match := re.fullmatch(r'this is the (.+ bin)', text):
        # The bin in front of the robot: the location nearest a point ahead of it, remembered in the session.
        return ('pos, angle = get_robot_pos_and_angle()\n'
                'ahead = pos + 0.6 * np.array([np.cos(angle), np.sin(angle)])\n'
                f'{_variable(match[1])} = get_loc_pos(min(get_loc_names(), '
                'key=lambda name: np.linalg.norm(get_loc_pos(name) - ahead)))')
    if match := re.fullmatch(r'put the (.+) in the (.+ bin)', text):
        return f'pick_obj({match[1]!r})\nplace_at_pos({_variable(match[2])})'
    if match := re.fullmatch(r'how many (\w+)s are on the (.+)', text):
        group, surface = match[1], match[2]
        members = sorted(name for name, g in objects.GROUPS.items() if g == group)
        return (f'surface_pos = get_loc_pos({surface!r})\n'
                f'names = [name for name in get_obj_names() if name in {members!r} and '
                f'np.linalg.norm(get_obj_pos(name) - surface_pos) < {surface_radius(surface):.2f}]\n'
                f'say(f"There are {{len(names)}} {group}s on the {surface}")')
    raise ValueError(f'no reference program for {instruction!r}')


def _variable(label: str) -> str:
    """The session variable a told fact lives in: "compost bin" -> compost_bin_pos."""
    return re.sub(r'\W+', '_', label) + '_pos'


def surface_radius(surface: str) -> float:
    """How far from a surface's centre an object on it can be: half its footprint's diagonal."""
    piece = layout.location(surface)
    return math.hypot(*piece.size[:2]) / 2 + 0.01


# ------------------------------------------------------------------------------------------- sampling
def sample_episode(template: str, seed: int) -> Episode:
    """The episode of `template` for `seed` (deterministic); ValueError for an unknown template."""
    if template not in TEMPLATES:
        raise ValueError(f'unknown template {template!r}; templates: {", ".join(TEMPLATES)}')
    rng = np.random.default_rng([seed, TEMPLATES.index(template), 41])
    for attempt in range(100):
        episode = _try_episode(template, seed, rng)
        if episode is not None:
            return episode
    raise ValueError(f'no {template} episode found for seed {seed}')


def _scene(seed: int, rng: np.random.Generator, keep_free: tuple[float, float] | None = None,
           must_have: tuple[str, ...] = ()) -> tuple[KitchenObject, ...] | None:
    names = list(dict.fromkeys([*must_have, *objects.default_objects(int(rng.integers(1 << 30)))]))
    placed = objects.spawn_positions(len(names), int(rng.integers(1 << 30)))
    if keep_free is not None and any(math.dist(p[:2], keep_free) < PLACES_KEPT_FREE for p in placed):
        return None
    return tuple(KitchenObject(name, (round(p[0], 4), round(p[1], 4))) for name, p in zip(names, placed))


def kitchen_scene(seed: int, must_have: Sequence[str] = (), keep_free: str = '') -> tuple[KitchenObject, ...]:
    """The seed's default objects with `must_have` first; with `keep_free` (a surface), that surface's middle stays
    clear and the first object is not on it (something to bring there)."""
    rng = np.random.default_rng([seed, 43])
    free = layout.location(keep_free).centre if keep_free else None
    for _ in range(100):
        scene = _scene(seed, rng, keep_free=free, must_have=tuple(must_have))
        if scene is not None and not (keep_free and objects.surface_of(*scene[0].xy) == keep_free):
            return scene
    raise ValueError(f'no scene for seed {seed} with {list(must_have)} off the {keep_free}')


def _try_episode(template: str, seed: int, rng: np.random.Generator) -> Episode | None:
    attributes: dict = {}
    if template == 'goto':
        place = str(rng.choice(GOTO_PLACES))
        instructions = (f'go to the {place}',)
        attributes['place'] = place
        scene = _scene(seed, rng)
    elif template == 'rectangle':
        around = str(rng.choice(AROUND))
        width, height = (float(v) for v in rng.choice(SIDES, 2))
        if not _fits_around(around, width, height):
            return None
        instructions = (f'move in a {width:g}m by {height:g}m rectangle around the {around}',)
        attributes.update(around=around, width=width, height=height)
        scene = _scene(seed, rng)
    elif template == 'back_and_forth':
        first, second = (str(v) for v in rng.choice(GOTO_PLACES, 2, replace=False))
        times = int(rng.integers(2, 4))
        instructions = (f'move back and forth between the {first} and the {second} {times} times',)
        attributes.update(first=first, second=second, times=times)
        scene = _scene(seed, rng)
    elif template == 'fetch':
        destination = str(rng.choice(objects.SURFACES))
        thing = str(rng.choice(objects.OBJECT_NAMES))
        scene = _scene(seed, rng, keep_free=layout.location(destination).centre, must_have=(thing,))
        if scene is None or objects.surface_of(*scene[0].xy) == destination:
            return None
        instructions = (f'bring the {thing} to the {destination}',)
        attributes.update(object=thing, destination=destination)
    elif template == 'bin':
        thing = str(rng.choice(objects.OBJECT_NAMES))
        bin_name, label = str(rng.choice(layout.BIN_NAMES)), objects.BIN_LABEL_FOR_GROUP[objects.GROUPS[thing]]
        instructions = (f'go to the {bin_name}', f'this is the {label}', f'put the {thing} in the {label}')
        attributes.update(object=thing, bin=bin_name, label=label)
        scene = _scene(seed, rng, must_have=(thing,))
    elif template == 'search':
        return _try_search(seed, rng)
    else:  # count
        group = str(rng.choice([objects.GROUP_SNACK, objects.GROUP_DRINK, objects.GROUP_FRUIT]))
        surface = str(rng.choice(objects.SURFACES))
        instructions = (f'how many {group}s are on the {surface}?',)
        attributes.update(group=group, surface=surface)
        scene = _scene(seed, rng)
    if scene is None:
        return None
    return Episode(template, seed, instructions, scene, attributes)


def _corner_rows(half_w: float, half_h: float) -> str:
    """A program's rows of rectangle_corners' offsets from the centre (the same order)."""
    return f'[-{half_w}, -{half_h}], [{half_w}, -{half_h}], [{half_w}, {half_h}], [-{half_w}, {half_h}]'


def _fits_around(around: str, width: float, height: float) -> bool:
    """Whether a rectangle around the location keeps its legs off the furniture and its corners on free floor."""
    piece = layout.location(around)
    if width / 2 < piece.size[0] / 2 + 0.45 or height / 2 < piece.size[1] / 2 + 0.45:
        return False  # the legs would pass over the furniture
    return all(_GRID.is_free(corner) for corner in rectangle_corners(around, width, height))


# ------------------------------------------------------------------------------------------- search
SEARCH_PATTERN = (r'go in a (?P<side>[\d.]+)m square around the (?P<around>.+) as many times as needed, check each '
                  r'step if there is an? (?P<object>.+), only stop moving when you see the (?P=object)')
# Squares that fit: (location, side). Any piece of furniture, not only the seats rectangles go around.
SEARCH_SQUARES: tuple[tuple[str, float], ...] = tuple(
    (name, side) for name in layout.LOCATION_NAMES for side in SIDES if _fits_around(name, side, side))
# Laps of the reference program before it gives up. The kitchen does not change while the robot searches, so a lap
# that did not see the object would not see it again, except when a look came before perception caught up with the
# stopped base; the bound ends the program well within the sandbox's time limit (a lap of a 2.5 m square takes about
# 40 s of driving) and lets it say that it did not find the object.
SEARCH_LAPS = 3


def search_instruction(around: str, side: float, thing: str) -> str:
    article = 'an' if thing[0] in 'aeiou' else 'a'
    return (f'go in a {side:g}m square around the {around} as many times as needed, check each step if there is '
            f'{article} {thing}, only stop moving when you see the {thing}')


def square_poses(around: str, side: float) -> np.ndarray:
    """(x, y, yaw) of the corners of a search's square, in rectangle_corners' order (counterclockwise from -x, -y),
    each facing the location's centre: where the searching robot looks from."""
    corners = rectangle_corners(around, side, side)
    toward = np.array(layout.location(around).centre) - corners
    return np.column_stack([corners, np.arctan2(toward[:, 1], toward[:, 0])])


def _search_program(around: str, side: float, thing: str) -> str:
    half = side / 2
    return (f'center = get_loc_pos({around!r})\n'
            f'corners = center + np.array([{_corner_rows(half, half)}])\n'
            'seen = False\n'
            f'for lap in range({SEARCH_LAPS}):\n'
            '    for corner in corners:\n'
            '        offset = center - corner\n'
            '        goto_pos(corner, angle=np.arctan2(offset[1], offset[0]))\n'
            f'        if is_obj_visible({thing!r}):\n'
            '            seen = True\n'
            '            break\n'
            '    if seen:\n'
            '        break\n'
            f'say({f"I see the {thing}"!r} if seen else '
            f'{f"I went around the {around} {SEARCH_LAPS} times and did not see the {thing}"!r})')


def _try_search(seed: int, rng: np.random.Generator) -> Episode | None:
    around, side = SEARCH_SQUARES[int(rng.integers(len(SEARCH_SQUARES)))]
    scene = _scene(seed, rng)
    start = np.array(layout.START_POSE)
    seen = sightlines.sightings([(o.name, o.xy) for o in scene], np.vstack([start, square_poses(around, side)]), seed)
    # Solvable and worth a search: out of view at the start, in view from a corner, every corner's answer certain.
    candidates = sorted(name for name, views in seen.items()
                        if views[0] is False and None not in views[1:] and any(views[1:]))
    if not candidates:
        return None
    thing = str(rng.choice(candidates))
    return Episode('search', seed, (search_instruction(around, side, thing),), scene,
                   {'around': around, 'side': side, 'object': thing, 'seen_from': seen[thing][1:]})


__all__ = ['Episode', 'KitchenObject', 'TEMPLATES', 'kitchen_scene', 'oracle_program', 'rectangle_corners',
           'sample_episode', 'search_instruction', 'square_poses', 'surface_radius']
