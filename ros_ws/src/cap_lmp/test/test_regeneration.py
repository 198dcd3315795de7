"""An answer that cannot run is found before anything moves, and (if the engine may) asked for again, sampled."""
from __future__ import annotations

import numpy as np
import pytest

from cap_lmp.engine import GENERATING
from cap_lmp.llm import OpenAICompatibleClient
from cap_lmp.outcome import Outcome
from cap_lmp.sandbox import SandboxLimits
from cap_lmp.testing.openai_server import by_attempt
from cap_lmp.testing.toy_domain import build_engine
from cap_lmp.testing.toy_world import ToyWorld

SCENE = {'red block': (-0.1, -0.4), 'blue block': (0.1, -0.45), 'red bowl': (-0.15, -0.65),
         'blue bowl': (0.15, -0.3)}


@pytest.fixture
def world() -> ToyWorld:
    return ToyWorld.with_objects(SCENE)


def make_engine(server, world, **options):
    client = OpenAICompatibleClient(server.base_url, model='scripted-model', api='completions', backoff_s=0.01,
                                    timeout_s=5.0)
    return build_engine(world.api(), client, limits=SandboxLimits(time_limit_s=1.0), **options)


def test_a_name_nothing_defines_stops_the_command_before_anything_moves(server, world):
    server.answers['put both blocks away'] = ("put_first_on_second('red block', 'red bowl')\n"
                                              "put_first_on_second('blue block', blue_target)")
    result = make_engine(server, world).run('put both blocks away')
    assert not result.success and result.outcome is Outcome.REFUSED and result.error_type == 'NameError'
    assert "name 'blue_target' is not defined (line 2 of the generated program" in result.message
    assert 'nothing ran' in result.message
    assert world.moves == [] and np.allclose(world.get_obj_pos('red block'), SCENE['red block'])
    assert len(server.requests) == 1  # regenerations are off by default (the paper's engine)


def test_an_answer_that_cannot_run_is_sampled_again_and_the_second_one_runs(server, world):
    server.responder = by_attempt({'put the red block in its bowl': (
        "put_first_on_second('red block', red_bowl)", "put_first_on_second('red block', 'red bowl')")})
    engine = make_engine(server, world, regenerations=1, regeneration_temperature=0.5)
    events = []
    engine.add_listener(events.append)
    result = engine.run('put the red block in its bowl')
    assert result.success, result.message
    assert np.allclose(world.get_obj_pos('red block'), SCENE['red bowl'])
    first, second = (request.body for request in server.requests)
    assert first['temperature'] == 0.0 and 'seed' not in first
    assert second['temperature'] == 0.5 and second['seed'] == 1
    assert any(e.stage == GENERATING and 'asking again' in e.message and 'red_bowl' in e.message for e in events)
    assert result.model_calls == 2


def test_a_nested_lmp_answer_is_asked_again_too(server, world):
    server.responder = by_attempt({
        'put the block nearest the blue bowl in it': (
            "name = parse_obj_name('the block nearest the blue bowl', f'objects = {get_obj_names()}')\n"
            "put_first_on_second(name, 'blue bowl')",) * 2,
        'the block nearest the blue bowl': (
            "ret_val = min(block_names, key=lambda n: np.linalg.norm(get_obj_pos(n) - get_obj_pos('blue bowl')))",
            "ret_val = 'blue block'")})
    result = make_engine(server, world, regenerations=1).run('put the block nearest the blue bowl in it')
    assert result.success, result.message
    assert world.moves == [('blue block', 'blue bowl')]


def test_refusals_and_answers_that_stay_unusable_are_final(server, world):
    server.answers['look around'] = 'import os\nsay(os.getcwd())'
    engine = make_engine(server, world, regenerations=2)
    refused = engine.run('look around')
    assert refused.outcome is Outcome.REFUSED and len(server.requests) == 1  # the sandbox's refusal is final

    server.answers['move it'] = "put_first_on_second('red block', somewhere)"
    broken = engine.run('move it')
    assert broken.error_type == 'NameError' and len(server.requests) == 1 + 3  # asked, then twice again
    assert world.moves == []


def test_variables_passed_to_an_lmp_and_its_context_are_defined(server, world):
    server.answers.update({
        'make the square bigger': ("pts = np.array([[0, 0], [0.1, 0], [0.1, 0.1], [0, 0.1]])\n"
                                   "big = transform_shape_pts('scale it up by 2', shape_pts=pts)\n"
                                   "say(str(len(big)) + ' ' + str(len(objects)))"),
        'scale it up by 2': 'new_shape_pts = shape_pts * 2'})
    result = make_engine(server, world).run('make the square bigger')
    assert result.success, result.message
    assert world.said == ['4 4']


def test_in_the_sandbox_process_the_second_answer_is_sampled_with_its_seed(server, world):
    from cap_lmp.isolated_engine import IsolatedEngine
    server.responder = by_attempt({'put the red block in its bowl': (
        "put_first_on_second('red block', red_bowl)", "put_first_on_second('red block', 'red bowl')")})
    client = OpenAICompatibleClient(server.base_url, 'scripted-model', api='completions', timeout_s=10.0)
    engine = IsolatedEngine(build_engine, world.api(), client, SandboxLimits(time_limit_s=10.0),
                            engine_options={'regenerations': 1})
    try:
        result = engine.run('put the red block in its bowl')
    finally:
        engine.close()
    assert result.success, result.message
    assert [request.body.get('seed') for request in server.requests] == [None, 1]
    assert world.moves == [('red block', 'red bowl')]
