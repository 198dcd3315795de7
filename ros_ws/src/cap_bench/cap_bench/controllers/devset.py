"""The controllers' development set: controller commands of this project, each judged by its template's judge.

Prompts are tuned on these, never on the benchmark's episodes. Each command is a benchmark template's task (balance
the cart-pole, hold the tool against a push, track a circle) asked in words of its own, some with other durations,
so the judges apply unchanged; the reference program is the template's. `cap bench controllers --set dev` runs
them.
"""
from __future__ import annotations

import dataclasses

from cap_bench.controllers import templates
from cap_bench.controllers.templates import BALANCE, PUSH, TRACK, ControllerEpisode


def _episode(key: int, template: str, seed: int, instruction: str, balance_seconds: float = 30.0) -> ControllerEpisode:
    base = templates.episode(template, seed, balance_seconds)
    return dataclasses.replace(base, seed=key, instruction=instruction)


def _track(key: int, seed: int, words: str) -> ControllerEpisode:
    """A track command whose words give the seed's radius (3-5 cm)."""
    radius_cm = round(templates.episode(TRACK, seed).radius_m * 100)
    return _episode(key, TRACK, seed, words.format(radius=radius_cm))


COMMANDS: tuple[ControllerEpisode, ...] = (
    _episode(101, BALANCE, 11, 'balance the pole on the cart for 15 seconds', 15.0),
    _episode(102, BALANCE, 12, 'stabilise the inverted pendulum with a PD controller for 20 seconds', 20.0),
    _episode(103, PUSH, 13, 'make the arm act like a stiff spring-damper at its current pose for 8 seconds'),
    _episode(104, PUSH, 14, 'for the next 8 seconds, hold the end effector in place compliantly, springing back if '
                            'it is pushed'),
    _track(105, 15, 'trace a horizontal circle of radius {radius} cm with the tool, one lap every 5 seconds, for 10 '
                    'seconds'),
    _track(106, 16, 'for 10 seconds, make the tool follow a {radius} cm radius circle, taking 5 seconds per lap'),
)


def episodes(trials: int = 1) -> list[ControllerEpisode]:
    """The set `trials` times over (trial t adds 100 * t to the keys' numbers)."""
    return [dataclasses.replace(item, seed=item.seed + 100 * trial) for trial in range(trials) for item in COMMANDS]


__all__ = ['COMMANDS', 'episodes']
