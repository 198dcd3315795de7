"""The mobile benchmark's episodes, reference programs and judge (no graph here: tests/test_mobile_bench_graph.py
runs episodes through it)."""
import ast
import math

import numpy as np
import pytest
from cap_mobile import layout, objects

from cap_bench.mobile.bench import judge
from cap_bench.mobile.episodes import (SEARCH_LAPS, TEMPLATES, Episode, oracle_program, rectangle_corners,
                                       sample_episode, search_instruction, square_poses)
from cap_lmp.functions import undefined_calls
from cap_lmp.sandbox import check_code
from cap_lmp_ros.domains.mobile.domain import ROBOT_FUNCTIONS
from cap_lmp_ros.domains.mobile.lmps import PROMPTS_DIR


# A search's sampling asks a headless simulator (tens of milliseconds an episode): with the slow tests.
@pytest.mark.parametrize('template', [pytest.param(t, marks=pytest.mark.slow) if t == 'search' else t
                                      for t in TEMPLATES])
def test_episodes_are_reproducible_and_their_programs_are_code_the_sandbox_accepts(template):
    for seed in range(30):
        episode = sample_episode(template, seed)
        assert episode == sample_episode(template, seed)
        names = [o.name for o in episode.objects]
        assert len(set(names)) == len(names)
        assert all(objects.surface_of(*o.xy) in objects.SURFACES for o in episode.objects)
        for instruction in episode.instructions:
            program = oracle_program(instruction)
            check_code(program)
            calls = {call.name for call in undefined_calls(ast.parse(program), {'np', 'range', 'len', 'min'})}
            assert calls <= set(ROBOT_FUNCTIONS), calls


def test_a_fetch_starts_elsewhere_with_its_destination_free_and_a_rectangle_keeps_off_its_furniture():
    for seed in range(30):
        fetch = sample_episode('fetch', seed)
        thing = next(o for o in fetch.objects if o.name == fetch.attributes['object'])
        assert objects.surface_of(*thing.xy) != fetch.attributes['destination']
        spot = layout.location(fetch.attributes['destination']).centre
        assert all(math.dist(o.xy, spot) >= 0.2 for o in fetch.objects)
        rectangle = sample_episode('rectangle', seed).attributes
        piece = layout.location(rectangle['around'])
        assert rectangle['width'] / 2 > piece.size[0] / 2 + layout.BASE_RADIUS


class State:
    def __init__(self, name, xyz):
        self.name, self.position = name, tuple(xyz)


def test_the_judge_passes_what_was_asked_and_says_what_went_wrong_otherwise():
    goto = sample_episode('goto', 0)
    goal = np.array(layout.location(goto.attributes['place']).approach())
    assert judge(goto, np.array([goal[:2]]), goal, {}, []) == ''
    assert 'from the' in judge(goto, np.array([goal[:2]]), goal + [0.1, 0, 0], {}, [])
    rectangle = sample_episode('rectangle', 0)
    a = rectangle.attributes
    corners = rectangle_corners(a['around'], a['width'], a['height'])
    loop = np.vstack([corners, corners[:1]])
    assert judge(rectangle, loop, goal, {}, []) == ''
    assert 'not reached' in judge(rectangle, loop[:2], goal, {}, [])
    count = sample_episode('count', 0)
    piece = layout.location(count.attributes['surface'])
    members = [n for n, g in objects.GROUPS.items() if g == count.attributes['group']][:2]
    states = {n: State(n, (*piece.centre, 1.0)) for n in members}
    assert judge(count, loop, goal, states, ['There are 2 on it']) == ''
    assert 'but there are 2' in judge(count, loop, goal, states, ['There are 3 on it'])
    put_away = sample_episode('bin', 0)
    thing, bin_ = put_away.attributes['object'], layout.location(put_away.attributes['bin'])
    assert judge(put_away, loop, goal, {thing: State(thing, (*bin_.centre, 0.1))}, []) == ''
    assert f'not in the {bin_.name}' in judge(put_away, loop, goal, {thing: State(thing, (0, 0, 0.8))}, [])


def test_a_put_away_episode_names_a_bin_by_colour_and_teaches_its_use_first():
    for seed in range(20):
        episode = sample_episode('bin', seed)
        bin_name, label = episode.attributes['bin'], episode.attributes['label']
        assert bin_name in layout.BIN_NAMES and label in objects.BIN_LABEL_FOR_GROUP.values()
        assert episode.instructions == (f'go to the {bin_name}', f'this is the {label}',
                                        f'put the {episode.attributes["object"]} in the {label}')
        assert f'{label.replace(" ", "_")}_pos' in oracle_program(episode.instructions[1])


def test_no_prompt_holds_a_benchmark_instruction_or_a_demo_command():
    from cap_bringup.demos.mobile import STEPS
    prompts = ' '.join(path.read_text().lower() for path in PROMPTS_DIR.glob('*.txt'))
    instructions = {i.lower().rstrip('?') for t in TEMPLATES for seed in range(50)
                    for i in sample_episode(t, seed).instructions}
    instructions |= {step.command.lower().rstrip('?') for step in STEPS}
    assert [i for i in instructions if i in prompts] == []


# ------------------------------------------------------------------------------------------- search
def _run_search_program(instruction: str, seen_at: int | None, folder) -> tuple[list, list]:
    """Run a search's reference program the way lmp_node does (a cassette, the mobile engine, its sandbox) over
    stand-in robot functions: the object comes into view at the `seen_at`-th corner visited (None: never). Returns
    the poses driven to and the words said."""
    from cap_lmp.cassette import ANY_CONTEXT, Cassette, CassetteClient, CassetteEntry
    from cap_lmp_ros.domains.registry import get_domain

    cassette = Cassette(folder / 'search.yaml', [CassetteEntry(
        lmp='mobile_ui', query=instruction, context=ANY_CONTEXT, completion=oracle_program(instruction),
        source='the benchmark\'s reference program')])
    cassette.save()
    driven, said = [], []
    functions = {'get_loc_pos': lambda name: np.array(layout.location(name).centre),
                 'goto_pos': lambda pos, angle=None: driven.append((*pos, angle)),
                 'is_obj_visible': lambda name: seen_at is not None and len(driven) == seen_at + 1,
                 'say': said.append, 'get_loc_names': lambda: list(layout.LOCATION_NAMES)}
    result = get_domain('mobile').build_engine(functions, CassetteClient(cassette.path)).run(instruction)
    assert result.success, result.error
    return driven, said


def test_the_search_program_goes_round_the_square_facing_its_centre_and_stops_when_it_sees_the_object(tmp_path):
    instruction = search_instruction('barstool', 1.5, 'banana')
    assert instruction == ('go in a 1.5m square around the barstool as many times as needed, check each step if '
                           'there is a banana, only stop moving when you see the banana')
    poses = square_poses('barstool', 1.5)
    driven, said = _run_search_program(instruction, 2, tmp_path)
    assert np.allclose(driven, poses[:3]) and said == ['I see the banana']
    driven, said = _run_search_program(instruction, None, tmp_path)
    assert np.allclose(driven, np.vstack([poses] * SEARCH_LAPS))
    assert said == [f'I went around the barstool {SEARCH_LAPS} times and did not see the banana']
    assert "is_obj_visible('apple')" in oracle_program(search_instruction('office chair', 2.0, 'apple'))
    # Each corner faces the location's centre.
    centre = np.array(layout.location('barstool').centre)
    for x, y, yaw in poses:
        assert np.allclose([math.cos(yaw), math.sin(yaw)], (centre - [x, y]) / np.linalg.norm(centre - [x, y]))


class SeenState:
    def __init__(self, name, visible):
        self.name, self.visible = name, visible


def test_the_search_judge_wants_the_corners_in_turn_and_a_stop_at_the_first_that_sees_the_object():
    episode = Episode('search', 0, (search_instruction('barstool', 1.5, 'banana'),), (),
                      {'around': 'barstool', 'side': 1.5, 'object': 'banana', 'seen_from': [False, True, False, True]})
    corners = square_poses('barstool', 1.5)
    start = np.array([layout.START_POSE[:2]])
    seen, unseen = {'banana': SeenState('banana', True)}, {'banana': SeenState('banana', False)}

    def run(*visited):
        return np.vstack([start, corners[list(visited), :2]]), corners[visited[-1]]

    assert judge(episode, *run(0, 1), seen, []) == ''
    assert judge(episode, *run(2, 3), seen, []) == ''  # another corner first, the same way round
    assert judge(episode, *run(0, 3), seen, []) == ''  # the other way round
    assert 'went on to corners [2]' in judge(episode, *run(0, 1, 2), seen, [])
    assert 'before any corner' in judge(episode, *run(0,), seen, [])
    assert 'did not go round' in judge(episode, *run(0, 2, 3), seen, [])
    assert 'reached no corner' in judge(episode, start, np.array(layout.START_POSE), seen, [])
    path, _ = run(0, 1)
    assert 'ended 0.300 m from corner 1' in judge(episode, path, corners[1] + [0.3, 0, 0], seen, [])
    assert 'does not see the banana' in judge(episode, *run(0, 1), unseen, [])


@pytest.mark.slow
def test_a_search_episode_hides_its_object_at_the_start_and_shows_it_from_a_corner_of_a_square_on_free_floor():
    from cap_sim_bridge.objects import ObjectSpec
    from cap_sim_bridge.world import World

    from cap_control.navigation.executor import NavigationConfig

    grid, world = NavigationConfig().grid(), World('mobile')
    for seed in range(10):
        episode = sample_episode('search', seed)
        a = episode.attributes
        assert episode.instructions == (search_instruction(a['around'], a['side'], a['object']),)
        assert a['object'] in {o.name for o in episode.objects} and any(a['seen_from'])
        assert all(grid.is_free(corner) for corner in square_poses(a['around'], a['side'])[:, :2])
        # At the start pose after a reset like the graph's, the head camera does not see it.
        world.reset(seed, [ObjectSpec.from_name(o.name, o.xy) for o in episode.objects])
        assert not world.object_state(a['object']).visible, episode.key
