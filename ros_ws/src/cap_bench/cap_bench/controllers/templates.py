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
These success definitions are this project's: the paper shows these controllers without numbers for them.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Sequence

import numpy as np

BALANCE, PUSH, TRACK = 'balance', 'push', 'track'
TEMPLATES = (BALANCE, PUSH, TRACK)
PUSH_FORCE = 20.0  # [N]
PUSH_START_S, PUSH_DURATION_S, PUSH_RUN_S = 1.0, 1.0, 8.0  # [s] of the run
PUSH_DIRECTIONS = {'+x': (1, 0, 0), '-x': (-1, 0, 0), '+y': (0, 1, 0), '-y': (0, -1, 0), '+z': (0, 0, 1),
                   '-z': (0, 0, -1)}
SETTLED_M = 0.005  # [m] within this of the goal counts as back
SETTLING_LIMIT_S = 2.0
OVERSHOOT_LIMIT_M = 0.010
TRACK_PERIOD_S, TRACK_RUN_S = 5.0, 10.0
TRACK_RMS_LIMIT_M = 0.010
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


@dataclasses.dataclass(frozen=True)
class Verdict:
    success: bool
    reason: str  # why not, or the figures of a success
    figures: dict[str, float]


def judge_balance(episode: ControllerEpisode, ran_s: float, outcome: str) -> Verdict:
    """Balanced when the run lasted its whole duration (the controller node stops a fallen pole)."""
    full = ran_s >= episode.duration_s - 1e-6
    figures = {'balanced_s': round(ran_s, 3)}
    if full and not outcome:
        return Verdict(True, f'balanced for {ran_s:.1f} s', figures)
    return Verdict(False, outcome or f'ran {ran_s:.2f} s of {episode.duration_s:g}', figures)


def judge_push(episode: ControllerEpisode, times: Sequence[float], offsets: Sequence[Sequence[float]],
               outcome: str) -> Verdict:
    """`times` [s since the run started] and the tool's `offsets` from its held place [m]."""
    times, offsets = np.asarray(times, dtype=float), np.asarray(offsets, dtype=float)
    if outcome or not len(times):
        return Verdict(False, outcome or 'no tool positions recorded', {})
    direction = np.asarray(PUSH_DIRECTIONS[episode.push_direction], dtype=float)
    end = PUSH_START_S + PUSH_DURATION_S
    after = times >= end
    errors = np.linalg.norm(offsets, axis=1)
    along = offsets @ direction
    peak = float(along[(times >= PUSH_START_S) & (times < end)].max(initial=0.0))
    overshoot = float(max(0.0, -along[after].min(initial=0.0)))
    outside = np.flatnonzero(after & (errors > SETTLED_M))
    settling = float(times[outside[-1]] - end) if len(outside) else 0.0
    final = float(errors[-1])
    figures = {'peak_displacement_mm': round(peak * 1000, 2), 'overshoot_mm': round(overshoot * 1000, 2),
               'settling_s': round(settling, 3), 'final_error_mm': round(final * 1000, 2)}
    problems = []
    if final > SETTLED_M:
        problems.append(f'ended {final * 1000:.1f} mm from its goal')
    if settling > SETTLING_LIMIT_S:
        problems.append(f'took {settling:.2f} s to settle')
    if overshoot > OVERSHOOT_LIMIT_M:
        problems.append(f'overshot by {overshoot * 1000:.1f} mm')
    if peak <= 0.0:
        problems.append('did not yield to the push')
    return Verdict(not problems, '; '.join(problems) or
                   f'yielded {peak * 1000:.1f} mm, settled in {settling:.2f} s', figures)


def circle_goal(episode: ControllerEpisode, start: Sequence[float], t: float) -> np.ndarray:
    """Where the tracking goal is at `t` seconds into the run, from the tool's start position."""
    phase = 2 * math.pi * t / TRACK_PERIOD_S
    return np.asarray(start, dtype=float) + episode.radius_m * np.array([math.cos(phase) - 1.0, math.sin(phase), 0.0])


def judge_track(episode: ControllerEpisode, times: Sequence[float], positions: Sequence[Sequence[float]],
                start: Sequence[float], ran_s: float, outcome: str) -> Verdict:
    """`times` [s since the run started], the tool's `positions` [m] and where it started."""
    if outcome or not len(times):
        return Verdict(False, outcome or 'no tool positions recorded', {})
    late = [(t, p) for t, p in zip(times, positions) if t >= episode.duration_s - TRACK_PERIOD_S]
    if ran_s < episode.duration_s - 1e-6 or not late:
        return Verdict(False, f'ran {ran_s:.2f} s of {episode.duration_s:g}', {})
    errors = np.array([np.linalg.norm(np.asarray(p) - circle_goal(episode, start, t)) for t, p in late])
    rms, worst = float(np.sqrt(np.mean(errors ** 2))), float(errors.max())
    figures = {'rms_error_mm': round(rms * 1000, 2), 'max_error_mm': round(worst * 1000, 2)}
    if rms > TRACK_RMS_LIMIT_M:
        return Verdict(False, f'RMS error {rms * 1000:.1f} mm', figures)
    return Verdict(True, f'RMS error {rms * 1000:.1f} mm', figures)


__all__ = ['BALANCE', 'ControllerEpisode', 'OVERSHOOT_LIMIT_M', 'PAPER', 'PUSH', 'PUSH_DIRECTIONS', 'PUSH_DURATION_S',
           'PUSH_FORCE', 'PUSH_START_S', 'SETTLED_M', 'SETTLING_LIMIT_S', 'TEMPLATES', 'TRACK', 'TRACK_PERIOD_S',
           'TRACK_RMS_LIMIT_M', 'Verdict', 'circle_goal', 'episode', 'judge_balance', 'judge_push', 'judge_track']
