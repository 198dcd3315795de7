"""Seeded episode sampler: objects, attribute values and an unambiguous instruction for one benchmark trial.

Each episode is fully determined by (group, template, seed). Choices this project made where the paper's evaluation
code was never published, kept fixed:
- 3-4 blocks and 3-4 bowls at explicit positions (x in [-0.2, 0.2], y in [-0.7, -0.3], pairwise >= 0.15 m); colours
  from the group's seen or unseen pool; "matching colors" episodes have a bowl for every block colour, "nth" episodes
  enough blocks for the ordinal.
- Referents are resolved from the initial state and must win by at least 0.03 m: "the block to the <direction> of
  the <bowl>" is the only block on that side of the bowl (every other block is at least 0.03 m on the other side);
  "closest/farthest" beats the runner-up by 0.03 m; the <nth> block from a direction is 0.03 m clear of its
  neighbours in that order; "the corner closest/farthest to the bowl" beats the other corners by 0.03 m.
- A named position an object is sent to (corner, side) has no object that stays put within 0.10 m, and a magnitude
  target (0.10 m for "a little", 0.25 m for "a lot", the distances the oracle uses) lies on the table with the same
  clearance, so that a failure is about the policy rather than a blocked target.
- An episode whose initial layout already meets its instruction is resampled.
"""
from __future__ import annotations

import random

import numpy as np

from cap_bench.tabletop import table
from cap_bench.tabletop.episodes import MAGNITUDE_DISTANCES, ORDINALS, Episode, SceneObject
from cap_bench.tabletop.success import check
from cap_bench.tabletop.templates import GROUPS, TEMPLATES, attribute_pool, render

REFERENT_MARGIN = 0.03
TARGET_CLEARANCE = 0.10
_MAX_LAYOUT_TRIES = 2000
_MAX_EPISODE_TRIES = 500


class SamplingError(RuntimeError):
    """No valid episode was found for a seed (should not happen for the benchmark's templates)."""


def sample_layout(rng: random.Random, count: int) -> list[tuple[float, float]]:
    """`count` points in the spawn area, pairwise at least SPAWN_MIN_DISTANCE apart (restarting when stuck)."""
    for _ in range(_MAX_LAYOUT_TRIES):
        points: list[tuple[float, float]] = []
        for _ in range(200):
            candidate = (rng.uniform(*table.SPAWN_X), rng.uniform(*table.SPAWN_Y))
            if all(np.hypot(candidate[0] - p[0], candidate[1] - p[1]) >= table.SPAWN_MIN_DISTANCE for p in points):
                points.append(candidate)
                if len(points) == count:
                    return [(round(x, 4), round(y, 4)) for x, y in points]
    raise SamplingError(f'could not place {count} objects {table.SPAWN_MIN_DISTANCE} m apart')


def sample_episode(group: str, template: str, seed: int) -> Episode:
    """The episode for (group, template, seed); the same arguments always give the same episode."""
    if group not in GROUPS:
        raise ValueError(f'unknown group {group!r}; groups: {", ".join(GROUPS)}')
    unseen, templates = GROUPS[group]
    if template not in templates:
        raise ValueError(f'template {template!r} is not in group {group}; it has: {", ".join(templates)}')
    rng = random.Random(f'{group}/{template}/{seed}')
    for _ in range(_MAX_EPISODE_TRIES):
        episode = _try_episode(rng, group, template, seed, unseen)
        if episode is not None and not _already_done(episode):
            return episode
    raise SamplingError(f'no unambiguous {template} episode for seed {seed} in {group}')


def episode_for_key(key: str) -> Episode:
    """The episode named `key` ('group/template/seed', see episodes.episode_key)."""
    group, template, seed = key.split('/')
    return sample_episode(group, template, int(seed))


def _try_episode(rng: random.Random, group: str, template: str, seed: int, unseen: bool) -> Episode | None:
    def pick(attribute: str) -> str:
        return rng.choice(attribute_pool(attribute, unseen))

    colors = list(attribute_pool('color', unseen))
    attributes: dict[str, str] = {}
    if template == 'nth_block':
        attributes['nth'] = pick('nth')
    n_blocks = 4 if attributes.get('nth') == 'fourth' else rng.choice((3, 4))
    n_bowls = rng.choice((3, 4))
    block_colors = rng.sample(colors, n_blocks)
    if template == 'matching_bowls':
        n_bowls = max(n_bowls, n_blocks)
        bowl_colors = block_colors + rng.sample([c for c in colors if c not in block_colors], n_bowls - n_blocks)
        rng.shuffle(bowl_colors)
    else:
        bowl_colors = rng.sample(colors, n_bowls)
    points = sample_layout(rng, n_blocks + n_bowls)
    objects = [SceneObject(f'{c} block', 'block', c, xy) for c, xy in zip(block_colors, points)]
    objects += [SceneObject(f'{c} bowl', 'bowl', c, xy) for c, xy in zip(bowl_colors, points[n_blocks:])]
    blocks = [o.name for o in objects if o.category == 'block']
    bowls = [o.name for o in objects if o.category == 'bowl']
    xy = {o.name: np.array(o.xy) for o in objects}
    referents: dict[str, str] = {}

    if template == 'pick_place':
        attributes['block1'] = rng.choice(blocks)
        attributes['target'] = rng.choice([b for b in blocks if b != attributes['block1']] + bowls)
        referents.update(block=attributes['block1'], target=attributes['target'])
    elif template in ('blocks_on_corner', 'stack_on_corner'):
        attributes['corner_side'] = pick('corner_side')
        if not _clear(table.NAMED_POSITIONS[attributes['corner_side']], bowls, xy):
            return None
        referents['target'] = attributes['corner_side']
    elif template == 'blocks_in_bowl':
        attributes['bowl'] = rng.choice(bowls)
        referents['target'] = attributes['bowl']
    elif template in ('block_by_direction', 'block_by_distance', 'nth_block'):
        attributes['corner_side'] = pick('corner_side')
        if template == 'block_by_direction':
            attributes.update(direction=pick('direction'), bowl=rng.choice(bowls))
            chosen = _block_by_direction(blocks, xy, attributes['bowl'], attributes['direction'])
        elif template == 'block_by_distance':
            attributes.update(distance=pick('distance'), bowl=rng.choice(bowls))
            chosen = _extreme(blocks, lambda b: np.linalg.norm(xy[b] - xy[attributes['bowl']]),
                              attributes['distance'] == 'farthest')
        else:
            attributes['direction'] = pick('direction')
            chosen = _nth_block(blocks, xy, attributes['nth'], attributes['direction'])
        if chosen is None:
            return None
        others = [name for name in xy if name != chosen]
        if not _clear(table.NAMED_POSITIONS[attributes['corner_side']], others, xy):
            return None
        referents.update(block=chosen, target=attributes['corner_side'])
    elif template == 'different_corners':
        if not all(_clear(corner, bowls, xy) for corner in table.CORNERS.values()):
            return None
    elif template == 'place_by_magnitude':
        attributes.update(block1=rng.choice(blocks), magnitude=pick('magnitude'), direction=pick('direction'),
                          bowl=rng.choice(bowls))
        target = xy[attributes['bowl']] + np.array(table.DIRECTIONS[attributes['direction']]) * \
            MAGNITUDE_DISTANCES[attributes['magnitude']]
        on_table = (table.TABLE_X[0] + 0.03 <= target[0] <= table.TABLE_X[1] - 0.03
                    and table.TABLE_Y[0] + 0.03 <= target[1] <= table.TABLE_Y[1] - 0.03)
        if not on_table or not _clear(target, [n for n in xy if n != attributes['block1']], xy):
            return None
        referents.update(block=attributes['block1'], bowl=attributes['bowl'])
    elif template == 'corner_by_distance':
        attributes.update(block1=rng.choice(blocks), distance=pick('distance'), bowl=rng.choice(bowls))
        corner = _extreme(list(table.CORNERS), lambda c: np.linalg.norm(np.array(table.CORNERS[c])
                                                                         - xy[attributes['bowl']]),
                          attributes['distance'] == 'farthest')
        if corner is None or not _clear(table.CORNERS[corner], [n for n in xy if n != attributes['block1']], xy):
            return None
        referents.update(block=attributes['block1'], target=corner)
    elif template == 'line':
        attributes['line'] = pick('line')
    elif template not in ('stack', 'matching_bowls', 'mismatched_bowls'):
        raise ValueError(f'unknown template {template!r}; templates: {", ".join(TEMPLATES)}')
    return Episode(seed=seed, group=group, template=template, instruction=render(template, attributes),
                   attributes=attributes, objects=objects, referents=referents)


def _already_done(episode: Episode) -> bool:
    """True when the initial layout already meets the instruction (e.g. the block already lies 'a lot' left)."""
    state = {o.name: (o.xy[0], o.xy[1], 0.02 if o.category == 'block' else 0.03) for o in episode.objects}
    return check(episode, state, state).success


def _clear(point, names, xy) -> bool:
    return all(np.linalg.norm(np.asarray(point) - xy[name]) >= TARGET_CLEARANCE for name in names)


def _extreme(candidates, score, largest: bool) -> str | None:
    """The candidate with the smallest (or largest) score, if it wins by REFERENT_MARGIN."""
    ranked = sorted(candidates, key=score, reverse=largest)
    if abs(score(ranked[0]) - score(ranked[1])) < REFERENT_MARGIN:
        return None
    return ranked[0]


def _block_by_direction(blocks, xy, bowl, direction) -> str | None:
    unit = np.array(table.DIRECTIONS[direction])
    ahead = [b for b in blocks if (xy[b] - xy[bowl]) @ unit >= REFERENT_MARGIN]
    behind = [b for b in blocks if (xy[b] - xy[bowl]) @ unit <= -REFERENT_MARGIN]
    return ahead[0] if len(ahead) == 1 and len(behind) == len(blocks) - 1 else None


def _nth_block(blocks, xy, nth, direction) -> str | None:
    """The nth block counted from the given edge of the table ("the first block from the top" is the topmost)."""
    unit = np.array(table.DIRECTIONS[direction])
    index = ORDINALS[nth]
    if index >= len(blocks):
        return None
    ordered = sorted(blocks, key=lambda b: -(xy[b] @ unit))
    along = [xy[b] @ unit for b in ordered]
    neighbours = [i for i in (index - 1, index + 1) if 0 <= i < len(ordered)]
    if any(abs(along[index] - along[i]) < REFERENT_MARGIN for i in neighbours):
        return None
    return ordered[index]
