"""Episodes are reproducible and unambiguous; every checker passes a correct final state and fails wrong ones."""
import itertools

import numpy as np
import pytest

from cap_bench.tabletop import table
from cap_bench.tabletop.episodes import MAGNITUDE_DISTANCES
from cap_bench.tabletop.sampling import sample_episode
from cap_bench.tabletop.success import check
from cap_bench.tabletop.templates import GROUPS, TEMPLATES, render

ROWS = [(group, template) for group, (_, templates) in GROUPS.items() for template in templates]
BLOCK_Z, BOWL_Z = 0.02, 0.03


def test_the_benchmark_has_22_rows_over_14_templates():
    assert len(ROWS) == 22
    assert {template for _, template in ROWS} == set(TEMPLATES)


@pytest.mark.parametrize('group, template', ROWS)
def test_episodes_are_deterministic_and_follow_the_spawn_rules(group, template):
    for seed in range(20):
        episode = sample_episode(group, template, seed)
        assert episode == sample_episode(group, template, seed)
        assert 3 <= len(episode.blocks) <= 4 and 3 <= len(episode.bowls) <= 4
        for a, b in itertools.combinations(episode.objects, 2):
            assert np.hypot(a.xy[0] - b.xy[0], a.xy[1] - b.xy[1]) >= table.SPAWN_MIN_DISTANCE
        for obj in episode.objects:
            assert table.SPAWN_X[0] <= obj.xy[0] <= table.SPAWN_X[1]
            assert table.SPAWN_Y[0] <= obj.xy[1] <= table.SPAWN_Y[1]
        unseen = GROUPS[group][0]
        colors = {obj.color for obj in episode.objects}
        assert colors <= set(('pink', 'cyan', 'brown', 'gray', 'purple') if unseen else
                             ('blue', 'red', 'green', 'orange', 'yellow'))
        assert episode.instruction == render(template, episode.attributes)
        assert '{' not in episode.instruction


def test_different_seeds_give_different_scenes():
    layouts = {tuple(o.xy for o in sample_episode('SA-SI', 'stack', seed).objects) for seed in range(30)}
    assert len(layouts) == 30


def test_the_block_to_the_left_of_a_bowl_is_the_only_one_on_that_side():
    for seed in range(30):
        episode = sample_episode('SA-SI', 'block_by_direction', seed)
        unit = np.array(table.DIRECTIONS[episode.attributes['direction']])
        xy = episode.initial_xy()
        bowl = xy[episode.attributes['bowl']]
        ahead = [b for b in episode.blocks if (xy[b] - bowl) @ unit > 0]
        assert ahead == [episode.referents['block']]


def test_unknown_group_or_template_is_refused_by_name():
    with pytest.raises(ValueError, match="unknown group 'XX'"):
        sample_episode('XX', 'stack', 0)
    with pytest.raises(ValueError, match="template 'line' is not in group SA-SI"):
        sample_episode('SA-SI', 'line', 0)


def _initial_state(episode):
    return {o.name: (o.xy[0], o.xy[1], BLOCK_Z if o.category == 'block' else BOWL_Z) for o in episode.objects}


def _stack_at(state, blocks, xy):
    for level, block in enumerate(blocks):
        state[block] = (xy[0], xy[1], BLOCK_Z + level * 0.04)


def correct_final_state(episode):
    """Where a perfect robot leaves the objects, computed from the episode's meaning."""
    state = _initial_state(episode)
    referents, attributes = episode.referents, episode.attributes
    target = referents.get('target')
    template = episode.template
    if template in ('pick_place', 'block_by_direction', 'block_by_distance', 'nth_block', 'corner_by_distance'):
        if target in table.NAMED_POSITIONS:
            xy = table.NAMED_POSITIONS[target]
            state[referents['block']] = (xy[0], xy[1], BLOCK_Z)
        else:
            x, y, z = state[target]
            state[referents['block']] = (x, y, z + 0.04 if target in episode.blocks else BLOCK_Z + 0.005)
    elif template in ('stack', 'stack_on_corner'):
        xy = table.NAMED_POSITIONS[attributes['corner_side']] if template == 'stack_on_corner' else \
            state[episode.blocks[0]][:2]
        _stack_at(state, episode.blocks, xy)
    elif template == 'blocks_on_corner':
        _stack_at(state, episode.blocks, table.NAMED_POSITIONS[target])
    elif template == 'blocks_in_bowl':
        _stack_at(state, episode.blocks, state[target][:2])
    elif template in ('matching_bowls', 'mismatched_bowls'):
        for block in episode.blocks:
            same = template == 'matching_bowls'
            bowl = next(b for b in episode.bowls if (b.split()[0] == block.split()[0]) == same)
            state[block] = (*state[bowl][:2], BLOCK_Z)
    elif template == 'different_corners':
        for block, corner in zip(episode.blocks, table.CORNERS.values()):
            state[block] = (*corner, BLOCK_Z)
    elif template == 'place_by_magnitude':
        xy = np.array(state[referents['bowl']][:2]) + \
            np.array(table.DIRECTIONS[attributes['direction']]) * MAGNITUDE_DISTANCES[attributes['magnitude']]
        state[referents['block']] = (*xy, BLOCK_Z)
    elif template == 'line':
        for i, block in enumerate(episode.blocks):
            offset = -0.15 + 0.1 * i
            state[block] = {'horizontal': (offset, -0.45, BLOCK_Z), 'vertical': (0.0, -0.5 + offset, BLOCK_Z),
                            'diagonal': (offset, -0.5 + offset, BLOCK_Z)}[attributes['line']]
    return state


@pytest.mark.parametrize('group, template', ROWS)
def test_checker_passes_a_correct_final_state(group, template):
    for seed in range(10):
        episode = sample_episode(group, template, seed)
        verdict = check(episode, _initial_state(episode), correct_final_state(episode))
        assert verdict.success, f'{episode.instruction} (seed {seed}): {verdict.reason}'


@pytest.mark.parametrize('group, template', ROWS)
def test_checker_fails_when_nothing_moved_and_says_why(group, template):
    for seed in range(10):
        episode = sample_episode(group, template, seed)
        verdict = check(episode, _initial_state(episode), _initial_state(episode))
        assert not verdict.success
        assert verdict.reason


SINGLE_OBJECT = [(g, t) for g, t in ROWS if TEMPLATES[t].single_object]


@pytest.mark.parametrize('group, template', SINGLE_OBJECT)
def test_checker_fails_when_the_wrong_block_is_moved(group, template):
    for seed in range(10):
        episode = sample_episode(group, template, seed)
        right = correct_final_state(episode)
        wrong_block = next(b for b in episode.blocks
                           if b != episode.referents['block'] and b != episode.referents.get('target'))
        wrong = _initial_state(episode)
        wrong[wrong_block] = right[episode.referents['block']]
        verdict = check(episode, _initial_state(episode), wrong)
        assert not verdict.success, episode.instruction


@pytest.mark.parametrize('group, template', SINGLE_OBJECT)
def test_checker_fails_when_a_bystander_is_knocked_away(group, template):
    episode = sample_episode(group, template, 0)
    state = correct_final_state(episode)
    bystander = next(b for b in episode.bowls if b != episode.referents.get('bowl')
                     and b != episode.referents.get('target'))
    x, y, z = state[bystander]
    state[bystander] = (x + 0.08, y, z)
    verdict = check(episode, _initial_state(episode), state)
    assert not verdict.success and bystander in verdict.reason


def test_a_block_beside_another_is_not_on_it():
    episode = next(e for e in (sample_episode('SA-SI', 'pick_place', s) for s in range(50))
                   if e.referents['target'] in e.blocks)
    state = correct_final_state(episode)
    x, y, _ = state[episode.referents['target']]
    state[episode.referents['block']] = (x + 0.035, y, BLOCK_Z)
    verdict = check(episode, _initial_state(episode), state)
    assert not verdict.success and 'not on top' in verdict.reason


def test_a_toppled_stack_fails():
    episode = sample_episode('SA-SI', 'stack', 1)
    state = correct_final_state(episode)
    top = max(episode.blocks, key=lambda b: state[b][2])
    x, y, _ = state[top]
    state[top] = (x + 0.06, y, BLOCK_Z)
    assert not check(episode, _initial_state(episode), state).success


def test_a_line_of_stacked_blocks_fails():
    episode = sample_episode('UA-UI', 'line', 2)
    state = correct_final_state(episode)
    first, second = episode.blocks[:2]
    state[second] = (state[first][0], state[first][1], BLOCK_Z + 0.04)
    verdict = check(episode, _initial_state(episode), state)
    assert not verdict.success


@pytest.mark.parametrize('magnitude, distance, ok', [('a little', 0.10, True), ('a little', 0.20, False),
                                                     ('a lot', 0.25, True), ('a lot', 0.10, False)])
def test_magnitude_ranges(magnitude, distance, ok):
    # The benchmark only samples the unseen 'a lot'; the checker knows both.
    episode = sample_episode('UA-UI', 'place_by_magnitude', 0)
    episode.attributes = {**episode.attributes, 'magnitude': magnitude}
    state = _initial_state(episode)
    xy = np.array(state[episode.referents['bowl']][:2]) + \
        np.array(table.DIRECTIONS[episode.attributes['direction']]) * distance
    state[episode.referents['block']] = (*xy, BLOCK_Z)
    assert check(episode, _initial_state(episode), state).success is ok
