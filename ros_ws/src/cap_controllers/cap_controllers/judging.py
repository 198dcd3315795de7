"""How a controller's run is judged from what the plant did (pure Python): the pole stayed up, the tool held its
place under a push and came back, the tool followed a circle. The controller benchmark (cap_bench.controllers) and
the controllers demo (cap_bringup.demos.controllers) judge their runs with these, so a run passes or fails for the
same reasons in both. These success definitions are this project's: the paper shows these controllers without
numbers for them.

- balance: the run lasted its whole duration (the controller node stops a run the moment the pole leans past
  12 degrees or the cart leaves +-2.4 m), and the pole's lean, where it was recorded, stayed within 12 degrees.
- push: one second into the run the tool is pushed with 20 N for 1 s along one of +-x, +-y, +-z. The tool yields,
  settles back within 5 mm of where it was held within SETTLING_LIMIT_S after the push ends, overshoots the other
  way by at most OVERSHOOT_LIMIT_M, and ends within 5 mm.
- track: the tool goes round a horizontal circle (from its place, counter-clockwise seen from above, centred a
  radius to its -x side, once every TRACK_PERIOD_S); its RMS distance from the moving goal over the last period
  at most TRACK_RMS_LIMIT_M, and the run complete.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Sequence

import numpy as np

from cap_controllers.plants import POLE_ANGLE_LIMIT

PUSH_FORCE = 20.0  # [N]
PUSH_START_S, PUSH_DURATION_S = 1.0, 1.0  # [s] of the run
PUSH_DIRECTIONS = {'+x': (1, 0, 0), '-x': (-1, 0, 0), '+y': (0, 1, 0), '-y': (0, -1, 0), '+z': (0, 0, 1),
                   '-z': (0, 0, -1)}
SETTLED_M = 0.005  # [m] within this of the goal counts as back
SETTLING_LIMIT_S = 2.0
OVERSHOOT_LIMIT_M = 0.010
TRACK_PERIOD_S = 5.0
TRACK_RMS_LIMIT_M = 0.010


@dataclasses.dataclass(frozen=True)
class Verdict:
    success: bool
    reason: str  # why not, or the figures of a success
    figures: dict[str, float]


def judge_balance(duration_s: float, ran_s: float, outcome: str, leans: Sequence[float] = ()) -> Verdict:
    """Balanced when the run lasted its whole `duration_s` (the controller node stops a fallen pole) and none of
    the pole's recorded `leans` [rad] (if any) went past the limit. `outcome`: '' or why the command failed."""
    full = ran_s >= duration_s - 1e-6
    figures = {'balanced_s': round(ran_s, 3)}
    if len(leans):
        figures['max_lean_deg'] = round(math.degrees(float(np.max(np.abs(leans)))), 2)
    if outcome or not full:
        return Verdict(False, outcome or f'ran {ran_s:.2f} s of {duration_s:g}', figures)
    if len(leans) and np.max(np.abs(leans)) > POLE_ANGLE_LIMIT:
        return Verdict(False, f'the pole leaned {figures["max_lean_deg"]:g} degrees', figures)
    return Verdict(True, f'balanced for {ran_s:.1f} s', figures)


def judge_push(direction: str, times: Sequence[float], offsets: Sequence[Sequence[float]], outcome: str) -> Verdict:
    """`direction` of the push (a key of PUSH_DIRECTIONS), `times` [s since the run started; the push began at
    PUSH_START_S] and the tool's `offsets` from its held place [m]."""
    times, offsets = np.asarray(times, dtype=float), np.asarray(offsets, dtype=float)
    if outcome or not len(times):
        return Verdict(False, outcome or 'no tool positions recorded', {})
    unit = np.asarray(PUSH_DIRECTIONS[direction], dtype=float)
    end = PUSH_START_S + PUSH_DURATION_S
    after = times >= end
    errors = np.linalg.norm(offsets, axis=1)
    along = offsets @ unit
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


def circle_goal(radius_m: float, start: Sequence[float], t: float) -> np.ndarray:
    """Where the tracking goal is at `t` seconds into the run, from the tool's start position."""
    phase = 2 * math.pi * t / TRACK_PERIOD_S
    return np.asarray(start, dtype=float) + radius_m * np.array([math.cos(phase) - 1.0, math.sin(phase), 0.0])


def judge_track(radius_m: float, duration_s: float, times: Sequence[float], positions: Sequence[Sequence[float]],
                start: Sequence[float], ran_s: float, outcome: str) -> Verdict:
    """`times` [s since the run started], the tool's `positions` [m] and where it started, for a run of
    `duration_s` round a circle of `radius_m`."""
    if outcome or not len(times):
        return Verdict(False, outcome or 'no tool positions recorded', {})
    late = [(t, p) for t, p in zip(times, positions) if t >= duration_s - TRACK_PERIOD_S]
    if ran_s < duration_s - 1e-6 or not late:
        return Verdict(False, f'ran {ran_s:.2f} s of {duration_s:g}', {})
    errors = np.array([np.linalg.norm(np.asarray(p) - circle_goal(radius_m, start, t)) for t, p in late])
    rms, worst = float(np.sqrt(np.mean(errors ** 2))), float(errors.max())
    figures = {'rms_error_mm': round(rms * 1000, 2), 'max_error_mm': round(worst * 1000, 2)}
    if rms > TRACK_RMS_LIMIT_M:
        return Verdict(False, f'RMS error {rms * 1000:.1f} mm', figures)
    return Verdict(True, f'RMS error {rms * 1000:.1f} mm', figures)


__all__ = ['OVERSHOOT_LIMIT_M', 'PUSH_DIRECTIONS', 'PUSH_DURATION_S', 'PUSH_FORCE', 'PUSH_START_S', 'SETTLED_M',
           'SETTLING_LIMIT_S', 'TRACK_PERIOD_S', 'TRACK_RMS_LIMIT_M', 'Verdict', 'circle_goal', 'judge_balance',
           'judge_push', 'judge_track']
