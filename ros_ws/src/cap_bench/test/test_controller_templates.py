"""The controller benchmark's episodes and judges, without a graph: episodes are fixed by their seeds, the oracle
programs pass the sandbox's checks, and each judge tells a good run from a bad one by the figures it reports."""
from __future__ import annotations

import math

import numpy as np
import pytest

from cap_bench.controllers import templates
from cap_lmp.sandbox import Sandbox


def test_episodes_are_fixed_by_their_seeds_and_cover_every_push_direction():
    assert templates.episode(templates.PUSH, 3) == templates.episode(templates.PUSH, 3)
    directions = {templates.episode(templates.PUSH, seed).push_direction for seed in range(40)}
    assert directions == set(templates.PUSH_DIRECTIONS)
    radii = {templates.episode(templates.TRACK, seed).radius_m for seed in range(40)}
    assert radii == {0.03, 0.04, 0.05}
    balance = templates.episode(templates.BALANCE, 1, balance_seconds=12)
    assert balance.instruction == 'keep the pole upright for 12 seconds' and 'duration=12' in balance.reference
    with pytest.raises(ValueError, match='unknown template'):
        templates.episode('juggle', 1)


@pytest.mark.parametrize('template', templates.TEMPLATES)
def test_the_oracle_programs_pass_the_sandbox_checks(template):
    Sandbox().compile(templates.episode(template, 0).reference)


def test_balance_succeeds_only_for_a_whole_run():
    item = templates.episode(templates.BALANCE, 0)
    assert templates.judge_balance(item, 30.0, '').success
    fallen = templates.judge_balance(item, 4.2, 'the pole leaned 12.3 degrees')
    assert not fallen.success and 'leaned' in fallen.reason and fallen.figures['balanced_s'] == 4.2


def _push_track(item, stiffness=500.0, settle_s=0.3, overshoot=0.0, final=0.0):
    times = np.arange(0.0, templates.PUSH_RUN_S, 0.01)
    direction = np.asarray(templates.PUSH_DIRECTIONS[item.push_direction], dtype=float)
    end = templates.PUSH_START_S + templates.PUSH_DURATION_S
    along = []
    for t in times:
        if t < templates.PUSH_START_S:
            along.append(0.0)
        elif t < end:
            along.append(templates.PUSH_FORCE / stiffness)
        else:
            decay = math.exp(-(t - end) / (settle_s / 5))
            along.append(templates.PUSH_FORCE / stiffness * decay - overshoot * (1 - decay) + final)
    return times, [a * direction for a in along]


def test_a_push_is_judged_by_settling_overshoot_and_final_error():
    item = templates.episode(templates.PUSH, 2)
    good = templates.judge_push(item, *_push_track(item), '')
    assert good.success and good.figures['peak_displacement_mm'] == pytest.approx(40.0)
    assert good.figures['settling_s'] < 0.5
    slow = templates.judge_push(item, *_push_track(item, settle_s=15.0), '')
    assert not slow.success and 'to settle' in slow.reason
    off = templates.judge_push(item, *_push_track(item, final=0.02), '')
    assert not off.success and 'from its goal' in off.reason
    stopped = templates.judge_push(item, [], [], 'the tool left the workspace')
    assert not stopped.success and stopped.reason == 'the tool left the workspace'


def test_tracking_is_judged_by_its_rms_distance_from_the_moving_goal():
    item = templates.episode(templates.TRACK, 5)
    start = np.array([0.1, -0.3, 0.4])
    times = np.arange(0.0, templates.TRACK_RUN_S, 0.01)
    exact = [templates.circle_goal(item, start, t) for t in times]
    assert templates.judge_track(item, times, exact, start, templates.TRACK_RUN_S, '').success
    lagging = [templates.circle_goal(item, start, t - 0.5) for t in times]
    verdict = templates.judge_track(item, times, lagging, start, templates.TRACK_RUN_S, '')
    assert not verdict.success and verdict.figures['rms_error_mm'] > templates.TRACK_RMS_LIMIT_M * 1000
    short = templates.judge_track(item, times[:300], exact[:300], start, 3.0, '')
    assert not short.success and 'ran 3.00 s' in short.reason
