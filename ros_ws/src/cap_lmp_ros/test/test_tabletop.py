"""The table-top helpers generated code relies on, the reference cassette kept in the repository, the table top's
check of an answer (an object the model made up) and its words for a planned call."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import cap_lmp_ros.domains.tabletop as tabletop_domain
from cap_lmp.approval import PlannedCall
from cap_lmp.cassette import Cassette, CassetteClient
from cap_lmp.llm import OpenAICompatibleClient
from cap_lmp.outcome import Outcome
from cap_lmp.sandbox import SandboxLimits
from cap_lmp.testing.openai_server import ScriptedOpenAIServer, by_attempt
from cap_lmp_ros.domains.tabletop.lmps import build_engine, denormalize_xy, get_corner_name, get_side_name
from cap_lmp_ros.domains.tabletop.plan import describe_call
from cap_lmp_ros.plan_steps import plan_summary
from cap_lmp_ros.testing.table import Table

REFERENCE = Path(tabletop_domain.__file__).parent / 'cassettes' / 'tabletop_reference.yaml'


def test_normalised_coordinates_follow_the_paper():
    assert np.allclose(denormalize_xy([0, 0]), [-0.25, -0.75])
    assert np.allclose(denormalize_xy([1, 1]), [0.25, -0.25])
    assert np.allclose(denormalize_xy([0.5, 0.5]), [0.0, -0.5])


def test_corner_and_side_names():
    assert get_corner_name([-0.2, -0.3]) == 'top left corner'
    assert get_corner_name([0.2, -0.7]) == 'bottom right corner'
    assert get_side_name([0.0, -0.27]) == 'top side'
    assert get_side_name([-0.24, -0.5]) == 'left side'


def test_the_reference_cassette_states_its_provenance():
    cassette = Cassette.load(REFERENCE)
    assert len(cassette) >= 4
    assert all(entry.source == 'written by hand as a reference program' for entry in cassette.entries())


SCENE = {'blue block': (-0.15, -0.35), 'red block': (0.0, -0.4), 'green block': (0.15, -0.45),
         'blue bowl': (0.05, -0.65), 'red bowl': (-0.2, -0.7), 'green bowl': (0.2, -0.3)}


@pytest.mark.parametrize('command, expected', [
    ('put all the blocks in the bowls with matching colors',
     {'blue block': 'blue bowl', 'red block': 'red bowl', 'green block': 'green bowl'}),
    ('put the blocks in the green bowl', {'blue block': 'green bowl', 'red block': 'green bowl'}),
])
def test_reference_programs_replay_offline(command, expected):
    table = Table.with_objects(SCENE)
    result = build_engine(table.api(), CassetteClient(REFERENCE)).run(command)
    assert result.success, result.message
    for block, bowl in expected.items():
        assert np.allclose(table.get_obj_pos(block), table.get_obj_pos(bowl)), block


def test_stacking_reference_program_builds_one_stack():
    table = Table.with_objects(SCENE)
    result = build_engine(table.api(), CassetteClient(REFERENCE)).run('stack all the blocks')
    assert result.success, result.message
    blocks = [table.objects[name] for name in ('blue block', 'red block', 'green block')]
    assert all(np.allclose(block.xy, blocks[0].xy) for block in blocks)
    assert sorted(block.height for block in blocks) == pytest.approx([0.0, 0.04, 0.08])


# -------------------------------------------------------------------------------------------------------------------
# The table top's answer check, in an engine that may ask again (regenerations=1).
FOUR_OBJECTS = {'red block': (-0.1, -0.4), 'blue block': (0.1, -0.45), 'red bowl': (-0.15, -0.65),
                'blue bowl': (0.15, -0.3)}


@pytest.fixture
def server():
    with ScriptedOpenAIServer() as scripted:
        yield scripted


def regenerating_engine(server: ScriptedOpenAIServer, table: Table):
    client = OpenAICompatibleClient(server.base_url, model='scripted-model', api='completions', backoff_s=0.01,
                                    timeout_s=5.0)
    return build_engine(table.api(), client, limits=SandboxLimits(time_limit_s=1.0), regenerations=1)


def test_an_object_the_model_made_up_is_asked_for_again_before_anything_moves(server):
    server.responder = by_attempt({'put the red block and the blue block in the blue bowl': (
        "put_first_on_second('red block', 'blue bowl')\nput_first_on_second('green block', 'blue bowl')",
        "put_first_on_second('red block', 'blue bowl')\nput_first_on_second('blue block', 'blue bowl')")})
    table = Table.with_objects(FOUR_OBJECTS)
    engine = regenerating_engine(server, table)
    result = engine.run('put the red block and the blue block in the blue bowl')
    assert result.success, result.message
    assert table.moves == [('red block', 'blue bowl'), ('blue block', 'blue bowl')]  # the first answer never ran

    server.responder = None
    server.answers['put the blue block on the red block'] = "put_first_on_second('green block', 'red block')"
    made_up = engine.run('put the blue block on the red block')
    assert made_up.outcome is Outcome.MODEL_ERROR and 'names the green block, which is neither on the table' in \
        made_up.message
    assert len(table.moves) == 2


def test_an_object_the_command_names_is_the_users_and_the_program_runs(server):
    server.answers['put the purple block in the red bowl'] = "put_first_on_second('purple block', 'red bowl')"
    table = Table.with_objects(FOUR_OBJECTS)
    result = regenerating_engine(server, table).run('put the purple block in the red bowl')
    assert result.outcome is Outcome.ERROR and "no object called 'purple block'" in result.message
    assert len(server.requests) == 1


def test_the_table_top_says_what_each_planned_call_does():
    named = describe_call(PlannedCall('put_first_on_second', (['the Red block'], 'blue bowl')))
    assert (named.object_name, named.target_name, named.description) == (
        'red block', 'blue bowl', 'put the red block on the blue bowl')
    point = describe_call(PlannedCall('put_first_on_second', ('red block',), {'target': [0.1, -0.5]}))
    assert point.points == ((0.1, -0.5, 0.0),) and point.description == 'put the red block at (0.100, -0.500)'
    odd = describe_call(PlannedCall('put_first_on_second', ('red block', '<object>')))
    assert odd.target_name == '<object>'  # text the program passed is kept as text (the page shows it as text)
    assert describe_call(PlannedCall('wave', (3,))).description == 'wave(3)'
    assert plan_summary([named, point]) == ('1. put the red block on the blue bowl; '
                                            '2. put the red block at (0.100, -0.500)')
    assert plan_summary([]) == 'the plan-only run found no robot action'
