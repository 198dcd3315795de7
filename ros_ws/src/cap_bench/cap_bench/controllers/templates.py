"""The controller benchmark's templates: seeded episodes, their instructions, the oracle's reference programs and
the judges (pure Python; the runner in bench.py brings up the graph).

Three templates, each episode fully determined by its seed:
- **balance**: "keep the pole upright for N seconds" from the cart-pole's seeded start (cart position and pole lean
  each uniform in +-0.05, at rest; the scene's reset draws them). Success: the run lasted the N seconds; the
  controller node stops a run the moment the pole leans past 12 degrees or the cart leaves +-2.4 m, so a full run
  is a balanced one (the paper's claim: the pole balanced for the whole episode).
- **push**: "hold the tool where it is with impedance control for 8 seconds", and one second into the run the tool
  is pushed with 20 N for 1 s along a seeded direction (+-x, +-y, +-z). Success: the tool settles back within 5 mm
  of where it was held within SETTLING_LIMIT_S after the push ends, overshoots the other way by at most
  OVERSHOOT_LIMIT_M, and ends within 5 mm.
- **track**: "move the tool around a circle of R cm radius once every 5 seconds for 10 seconds" (R = 3, 4 or 5 by
  seed; the circle in the horizontal plane, starting at the tool's place and turning counter-clockwise seen from
  above, centred R to its -x side). Success: the tool's RMS distance from the moving goal over the last 5 s at most
  TRACK_RMS_LIMIT_M, and the run complete.
These success definitions are this project's: the paper shows these controllers without numbers for them. The
judges and their limits are cap_controllers.judging's (the controllers demo judges its runs with them too).
"""
from __future__ import annotations

import dataclasses
from typing import Sequence

import numpy as np
from cap_controllers import judging
from cap_controllers.judging import (OVERSHOOT_LIMIT_M, PUSH_DIRECTIONS, PUSH_DURATION_S, PUSH_FORCE, PUSH_START_S,
                                     SETTLED_M, SETTLING_LIMIT_S, TRACK_PERIOD_S, TRACK_RMS_LIMIT_M, Verdict)

BALANCE, PUSH, TRACK = 'balance', 'push', 'track'
TEMPLATES = (BALANCE, PUSH, TRACK)
PUSH_RUN_S = 8.0  # [s] of the run
TRACK_RUN_S = 10.0
# The paper's figure beside each template (percent), where it has one: its cart-pole PD controller balanced the
# pole for the whole episode.
PAPER = {BALANCE: 100.0, PUSH: None, TRACK: None}

_BALANCE_PROGRAM = """def controller(x, x_dot, theta, theta_dot):
    return keep_pole_upright_with_pd_control(x, x_dot, theta, theta_dot)
run = run_controller(controller, rate=100, duration={seconds}, plant='cartpole')
say(f"The pole stayed up for {{run['simulated_time']:.1f}} s")"""
_PUSH_PROGRAM = """goal_pose = get_ee_pose()
def controller(t):
    return ee_impedance_control(goal_pose, stiffness=500, damping=60)
run_controller(controller, rate=100, duration={seconds}, plant='arm')"""
_TRACK_PROGRAM = """start_pose = get_ee_pose()
def controller(t):
    phase = 2 * np.pi * t / {period}
    goal_pose = np.array(start_pose)
    goal_pose[:3, 3] = start_pose[:3, 3] + {radius} * np.array([np.cos(phase) - 1.0, np.sin(phase), 0.0])
    goal_velocity = {radius} * 2 * np.pi / {period} * np.array([-np.sin(phase), np.cos(phase), 0.0])
    error = pose_error(goal_pose, get_ee_pose())
    velocity = get_ee_velocity()
    force = 800 * error[:3] + 80 * (goal_velocity - velocity[:3])
    moment = 30 * error[3:] - 2 * velocity[3:]
    return get_jacobian().T @ np.concatenate([force, moment])
run_controller(controller, rate=100, duration={seconds}, plant='arm')"""


@dataclasses.dataclass(frozen=True)
class ControllerEpisode:
    template: str
    seed: int
    instruction: str
    reference: str  # the oracle's program for the instruction
    duration_s: float  # of the controller run
    push_direction: str = ''  # push: '+x', ...
    radius_m: float = 0.0  # track

    @property
    def key(self) -> str:
        return f'{self.template}-{self.seed}'


def episode(template: str, seed: int, balance_seconds: float = 30.0) -> ControllerEpisode:
    """The episode of `template` with `seed` (ValueError for an unknown template)."""
    rng = np.random.default_rng(seed)
    if template == BALANCE:
        seconds = f'{balance_seconds:g}'
        return ControllerEpisode(BALANCE, seed, f'keep the pole upright for {seconds} seconds',
                                 _BALANCE_PROGRAM.format(seconds=seconds), balance_seconds)
    if template == PUSH:
        direction = list(PUSH_DIRECTIONS)[int(rng.integers(len(PUSH_DIRECTIONS)))]
        return ControllerEpisode(PUSH, seed, f'hold the tool where it is with impedance control for '
                                             f'{PUSH_RUN_S:g} seconds', _PUSH_PROGRAM.format(seconds=f'{PUSH_RUN_S:g}'),
                                 PUSH_RUN_S, push_direction=direction)
    if template == TRACK:
        centimetres = int(rng.integers(3, 6))
        radius = centimetres / 100.0
        return ControllerEpisode(
            TRACK, seed, f'move the tool around a circle of {centimetres} cm radius once every '
                         f'{TRACK_PERIOD_S:g} seconds for {TRACK_RUN_S:g} seconds',
            _TRACK_PROGRAM.format(period=f'{TRACK_PERIOD_S:g}', radius=f'{radius:g}', seconds=f'{TRACK_RUN_S:g}'),
            TRACK_RUN_S, radius_m=radius)
    raise ValueError(f'unknown template {template!r}; the templates are: {", ".join(TEMPLATES)}')


def judge_balance(episode: ControllerEpisode, ran_s: float, outcome: str) -> Verdict:
    """Balanced when the run lasted its whole duration (the controller node stops a fallen pole)."""
    return judging.judge_balance(episode.duration_s, ran_s, outcome)


def judge_push(episode: ControllerEpisode, times: Sequence[float], offsets: Sequence[Sequence[float]],
               outcome: str) -> Verdict:
    """`times` [s since the run started] and the tool's `offsets` from its held place [m]."""
    return judging.judge_push(episode.push_direction, times, offsets, outcome)


def circle_goal(episode: ControllerEpisode, start: Sequence[float], t: float) -> np.ndarray:
    """Where the tracking goal is at `t` seconds into the run, from the tool's start position."""
    return judging.circle_goal(episode.radius_m, start, t)


def judge_track(episode: ControllerEpisode, times: Sequence[float], positions: Sequence[Sequence[float]],
                start: Sequence[float], ran_s: float, outcome: str) -> Verdict:
    """`times` [s since the run started], the tool's `positions` [m] and where it started."""
    return judging.judge_track(episode.radius_m, episode.duration_s, times, positions, start, ran_s, outcome)


__all__ = ['BALANCE', 'ControllerEpisode', 'OVERSHOOT_LIMIT_M', 'PAPER', 'PUSH', 'PUSH_DIRECTIONS', 'PUSH_DURATION_S',
           'PUSH_FORCE', 'PUSH_START_S', 'SETTLED_M', 'SETTLING_LIMIT_S', 'TEMPLATES', 'TRACK', 'TRACK_PERIOD_S',
           'TRACK_RMS_LIMIT_M', 'Verdict', 'circle_goal', 'episode', 'judge_balance', 'judge_push', 'judge_track']
