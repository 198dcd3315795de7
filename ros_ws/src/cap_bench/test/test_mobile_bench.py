"""The mobile benchmark's episodes, reference programs and judge (no graph here: tests/test_mobile_bench_graph.py
runs episodes through it)."""
import ast
import math

import numpy as np
import pytest
from cap_kitchen import layout, objects

from cap_bench.mobile.bench import judge
from cap_bench.mobile.episodes import TEMPLATES, oracle_program, rectangle_corners, sample_episode
from cap_lmp.functions import undefined_calls
from cap_lmp.sandbox import check_code
from cap_lmp_ros.domains.mobile.domain import ROBOT_FUNCTIONS
from cap_lmp_ros.domains.mobile.lmps import PROMPTS_DIR


@pytest.mark.parametrize('template', TEMPLATES)
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
            calls = {call.name for call in undefined_calls(ast.parse(program), {'np', 'range', 'len'})}
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


def test_no_prompt_holds_a_benchmark_instruction_or_a_demo_command():
    from cap_bringup.mobile_demo import STEPS
    prompts = ' '.join(path.read_text().lower() for path in PROMPTS_DIR.glob('*.txt'))
    instructions = {i.lower().rstrip('?') for t in TEMPLATES for seed in range(50)
                    for i in sample_episode(t, seed).instructions}
    instructions |= {step.command.lower().rstrip('?') for step in STEPS}
    assert [i for i in instructions if i in prompts] == []
