"""The benchmark's instruction templates, attribute pools and groups.

Three groups as in the Code as Policies table-top evaluation: SA-SI (seen attributes, seen instructions), UA-SI
(unseen attributes, seen instructions) and UA-UI (unseen attributes, unseen instructions). Seen attribute values
may appear in prompts; unseen ones never do.

A template names the attributes it needs; `render` turns a template and its attribute values into the
instruction a person would type.
"""
from __future__ import annotations

from dataclasses import dataclass

SEEN_COLORS = ('blue', 'red', 'green', 'orange', 'yellow')
UNSEEN_COLORS = ('pink', 'cyan', 'brown', 'gray', 'purple')

# attribute -> (seen values, unseen values)
ATTRIBUTE_POOLS: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    'color': (SEEN_COLORS, UNSEEN_COLORS),
    'corner_side': (('left side', 'top left corner', 'top side', 'top right corner'),
                    ('bottom right corner', 'bottom side', 'bottom left corner')),
    'direction': (('top', 'left'), ('bottom', 'right')),
    'distance': (('closest',), ('farthest',)),
    'magnitude': (('a little',), ('a lot',)),
    'nth': (('first', 'second'), ('third', 'fourth')),
    'line': (('horizontal', 'vertical'), ('diagonal',)),
}


@dataclass(frozen=True)
class Template:
    key: str
    text: str  # with {placeholders} named after the episode's attributes
    seen: bool  # a "seen instruction" (may appear in prompts)
    single_object: bool  # only one block is meant to move


TEMPLATES: dict[str, Template] = {t.key: t for t in (
    Template('pick_place', 'Pick up the {block1} and place it on the {target}', True, True),
    Template('stack', 'Stack all the blocks', True, False),
    Template('blocks_on_corner', 'Put all the blocks on the {corner_side}', True, False),
    Template('blocks_in_bowl', 'Put the blocks in the {bowl}', True, False),
    Template('matching_bowls', 'Put all the blocks in the bowls with matching colors', True, False),
    Template('block_by_direction',
             'Pick up the block to the {direction} of the {bowl} and place it on the {corner_side}', True, True),
    Template('block_by_distance',
             'Pick up the block {distance} to the {bowl} and place it on the {corner_side}', True, True),
    Template('nth_block', 'Pick up the {nth} block from the {direction} and place it on the {corner_side}',
             True, True),
    Template('different_corners', 'Put all the blocks in different corners', False, False),
    Template('mismatched_bowls', 'Put the blocks in the bowls with mismatched colors', False, False),
    Template('stack_on_corner', 'Stack all the blocks on the {corner_side}', False, False),
    Template('place_by_magnitude',
             'Pick up the {block1} and place it {magnitude} to the {direction} of the {bowl}', False, True),
    Template('corner_by_distance', 'Pick up the {block1} and place it in the corner {distance} to the {bowl}',
             False, True),
    Template('line', 'Put all the blocks in a {line} line', False, False),
)}

SEEN_TEMPLATES = tuple(key for key, t in TEMPLATES.items() if t.seen)
UNSEEN_TEMPLATES = tuple(key for key, t in TEMPLATES.items() if not t.seen)

# group -> (uses unseen attribute values, templates): 8 + 8 + 6 = 22 rows.
GROUPS: dict[str, tuple[bool, tuple[str, ...]]] = {
    'SA-SI': (False, SEEN_TEMPLATES),
    'UA-SI': (True, SEEN_TEMPLATES),
    'UA-UI': (True, UNSEEN_TEMPLATES),
}


def attribute_pool(attribute: str, unseen: bool) -> tuple[str, ...]:
    seen_values, unseen_values = ATTRIBUTE_POOLS[attribute]
    return unseen_values if unseen else seen_values


def render(template_key: str, attributes: dict[str, str]) -> str:
    """The instruction text, e.g. 'Pick up the red block and place it on the blue bowl'."""
    return TEMPLATES[template_key].text.format(**attributes)
