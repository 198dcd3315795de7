"""Execution feedback: a program that fails while running is followed by one that finishes the command from the
world as it is now, written by a real OpenAI-protocol server on loopback that serves scripted answers."""
from __future__ import annotations

import numpy as np
import pytest

from cap_lmp.engine import GENERATING
from cap_lmp.feedback import describe_call, worth_feedback
from cap_lmp.errors import CodeRejected, ExecutionStopped, RobotApiError, StoppedError
from cap_lmp.isolated_engine import IsolatedEngine
from cap_lmp.llm import OpenAICompatibleClient
from cap_lmp.outcome import Outcome
from cap_lmp.sandbox import SandboxLimits
from cap_lmp.testing.openai_server import last_query_line
from cap_lmp.testing.toy_domain import ACTING_FUNCTIONS, build_engine
from cap_lmp.testing.toy_world import ToyWorld

SCENE = {'red block': (-0.1, -0.4), 'blue block': (0.1, -0.45), 'red bowl': (-0.15, -0.65),
         'blue bowl': (0.15, -0.3)}
COMMAND = 'put each block in the bowl of its colour'
# The first program moves the red block, then names a bowl that is not there.
FIRST = ("put_first_on_second('red block', 'red bowl')\n"
         "put_first_on_second('blue block', 'navy bowl')")
FINISH = "put_first_on_second('blue block', 'blue bowl')"


@pytest.fixture
def world() -> ToyWorld:
    return ToyWorld.with_objects(SCENE)


def make_engine(server, world, **options):
    client = OpenAICompatibleClient(server.base_url, model='scripted-model', api='completions', backoff_s=0.01,
                                    timeout_s=5.0)
    return build_engine(world.api(), client, limits=SandboxLimits(time_limit_s=2.0),
                        plan_functions=ACTING_FUNCTIONS, **options)


def script(server, first: str = FIRST, finish: str | None = FINISH) -> None:
    def respond(request):
        query = last_query_line(request.prompt)
        if 'finishing what the program above did not do' in query:
            return finish
        return first if COMMAND in query else None
    server.responder = respond


def test_a_failed_program_is_followed_by_one_that_finishes_the_command_from_where_it_stopped(server, world):
    script(server)
    engine = make_engine(server, world, feedback_rounds=1)
    events = []
    engine.add_listener(events.append)
    result = engine.run(COMMAND)
    assert result.success and result.outcome is Outcome.DONE, result.message
    # each block once: the red one by the first program, the blue one by the second; nothing repeated
    assert world.moves == [('red block', 'red bowl'), ('blue block', 'blue bowl')]
    assert np.allclose(world.get_obj_pos('blue block'), SCENE['blue bowl'])
    second = server.requests[1].body['prompt']
    # the model read its failed program, where and why it stopped, what it had done, and the scene now
    assert FIRST in second
    assert ("# the program above stopped at line 2 (`put_first_on_second('blue block', 'navy bowl')`): "
            "UnknownObjectError: there is no object called 'navy bowl'") in second
    assert "# done before it stopped: put_first_on_second('red block', 'red bowl')" in second
    assert second.rstrip().endswith(f'# {COMMAND}, finishing what the program above did not do.')
    assert any(e.stage == GENERATING and 'round 1 of 1 after the program failed' in e.message for e in events)
    assert FINISH in result.code and FIRST in result.code  # the command's code shows every round
    assert result.model_calls == 2


def test_without_feedback_rounds_one_program_is_all_a_command_gets(server, world):
    script(server)
    result = make_engine(server, world).run(COMMAND)
    assert not result.success and "there is no object called 'navy bowl'" in result.message
    assert len(server.requests) == 1 and world.moves == [('red block', 'red bowl')]


def test_a_finishing_program_that_fails_too_ends_the_command_saying_so(server, world):
    script(server, finish="put_first_on_second('blue block', 'teal bowl')")
    result = make_engine(server, world, feedback_rounds=1).run(COMMAND)
    assert not result.success and result.outcome is Outcome.ERROR
    assert "'teal bowl'" in result.message and '(the program of feedback round 1 of 1)' in result.message
    assert len(server.requests) == 2


@pytest.mark.parametrize('finish', ['put_first_on_second(', '# nothing left to do'])  # not Python; no code
def test_when_the_model_gives_nothing_to_continue_with_the_first_failure_is_reported(server, world, finish):
    script(server, finish=finish)
    result = make_engine(server, world, feedback_rounds=1).run(COMMAND)
    assert not result.success and "there is no object called 'navy bowl'" in result.message
    assert 'asked to finish the command after that, the model gave no program that could run' in result.message


@pytest.mark.parametrize('first, reason', [
    ('while True:\n    pass', 'timeout'),  # a stop: the time limit
    ("put_first_on_second('red block', 'red bowl')\nx = (1).__class__", 'refused'),  # the sandbox refuses it
])
def test_stops_and_refusals_are_final(server, world, first, reason):
    script(server, first=first)
    result = make_engine(server, world, feedback_rounds=2).run(COMMAND)
    assert not result.success
    assert result.stop_reason == reason or result.outcome is Outcome.REFUSED, result.message
    assert len(server.requests) == 1


def test_with_approval_the_approved_program_is_all_that_runs(server, world):
    script(server)
    engine = make_engine(server, world, feedback_rounds=1)
    engine.approval = lambda code, plan: None  # approves everything
    result = engine.run(COMMAND)
    assert not result.success and len(server.requests) == 1


def test_in_the_sandbox_process_the_rounds_share_the_commands_clock(server, world):
    script(server)
    client = OpenAICompatibleClient(server.base_url, 'scripted-model', api='completions', timeout_s=10.0)
    engine = IsolatedEngine(build_engine, world.api(), client, SandboxLimits(time_limit_s=10.0),
                            engine_options={'feedback_rounds': 1, 'plan_functions': list(ACTING_FUNCTIONS)})
    try:
        result = engine.run(COMMAND)
        assert result.success, result.message
        assert world.moves == [('red block', 'red bowl'), ('blue block', 'blue bowl')]
        assert "# done before it stopped: put_first_on_second('red block', 'red bowl')" in \
            server.requests[1].body['prompt']
    finally:
        engine.close()


def test_which_failures_are_fed_back():
    assert worth_feedback(RobotApiError('no path')) and worth_feedback(KeyError('x'))
    assert not worth_feedback(StoppedError('stopped')) and not worth_feedback(CodeRejected('no'))
    assert not worth_feedback(ExecutionStopped('limit', 'timeout')) and not worth_feedback(MemoryError())
    assert describe_call('put_first_on_second', ('red block', np.array([0.12345, -0.5])), {}) == \
        "put_first_on_second('red block', [0.123, -0.5])"


def test_a_finishing_program_that_repeats_the_failed_one_is_asked_for_once_more_sampled(server, world):
    def respond(request):
        query = last_query_line(request.prompt)
        if 'finishing what the program above did not do' in query:
            return FINISH if request.body.get('seed') is not None else FIRST  # greedy: the same program again
        return FIRST if COMMAND in query else None
    server.responder = respond
    result = make_engine(server, world, feedback_rounds=1, regeneration_temperature=0.7).run(COMMAND)
    assert result.success, result.message
    assert world.moves == [('red block', 'red bowl'), ('blue block', 'blue bowl')]
    sampled = server.requests[2].body
    assert len(server.requests) == 3 and sampled['temperature'] == 0.7 and sampled['seed'] == 1
