"""What a table-top episode is: its objects, instruction and the referents it was sampled with (sampling.py samples
them, success.py judges them, oracle.py writes their reference programs); also the words for distances and orders
the instructions use."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

# How far "a little" and "a lot" move a block (the sampler keeps these targets clear; the oracle moves by them).
MAGNITUDE_DISTANCES = {'a little': 0.10, 'a lot': 0.25}
ORDINALS = {'first': 0, 'second': 1, 'third': 2, 'fourth': 3}


def episode_key(group: str, template: str, seed: int) -> str:
    """The episode's name in records and on the command line: 'group/template/seed'."""
    return f'{group}/{template}/{seed}'


@dataclass(frozen=True)
class SceneObject:
    name: str  # "<colour> <category>"
    category: str  # "block" or "bowl"
    color: str
    xy: tuple[float, float]


@dataclass
class Episode:
    seed: int
    group: str
    template: str
    instruction: str
    attributes: dict[str, str]  # the template's slot values as rendered
    objects: list[SceneObject]
    # Resolved meaning, for the success checker: e.g. {'block': 'red block', 'target': 'blue bowl'}.
    referents: dict[str, str] = field(default_factory=dict)

    @property
    def key(self) -> str:
        return episode_key(self.group, self.template, self.seed)

    @property
    def blocks(self) -> list[str]:
        return [obj.name for obj in self.objects if obj.category == 'block']

    @property
    def bowls(self) -> list[str]:
        return [obj.name for obj in self.objects if obj.category == 'bowl']

    def initial_xy(self) -> dict[str, np.ndarray]:
        return {obj.name: np.array(obj.xy) for obj in self.objects}
