"""Typed outcomes: every CommandResult says how the command ended, in this process and across the sandbox process;
Engine and IsolatedEngine both satisfy the CommandEngine protocol."""
from __future__ import annotations

import inspect

import pytest

from cap_lmp.engine import CommandResult, Engine
from cap_lmp.engine_protocol import CommandEngine
from cap_lmp.errors import (CassetteMissError, CodeRejected, ExecutionStopped, GenerationError, LLMError,
                            RobotApiError, SandboxProcessLost, StoppedError)
from cap_lmp.isolated_engine import IsolatedEngine, builder_reference
from cap_lmp.llm import Completion, CompletionRequest
from cap_lmp.outcome import Outcome, outcome_of
from cap_lmp.sandbox import SandboxLimits
from cap_lmp.testing.minimal_engine import build_engine


class ScriptedClient:
    """An LLMClient fake: the answer (or the exception) for each query."""

    def __init__(self, answers: dict[str, object]) -> None:
        self.answers = answers

    def complete(self, request: CompletionRequest) -> Completion:
        answer = self.answers[request.query]
        if isinstance(answer, BaseException):
            raise answer
        return Completion(text=str(answer))


def _stop_robot() -> None:
    raise StoppedError('stopped while waiting for the robot')


ANSWERS = {'fine': 'x = 1', 'import': 'import os', 'broken': 'x = (', 'no model': LLMError('endpoint down'),
           'undefined': 'make_tea()', 'fails': 'x = 1 / 0', 'stopped': 'stop_robot()'}
EXPECTED = {'fine': Outcome.DONE, 'import': Outcome.REFUSED, 'broken': Outcome.REFUSED,
            'no model': Outcome.MODEL_ERROR, 'undefined': Outcome.MODEL_ERROR, 'fails': Outcome.ERROR,
            'stopped': Outcome.CANCELLED}


@pytest.mark.parametrize('error, outcome', [
    (CodeRejected('no'), Outcome.REFUSED), (SyntaxError('bad'), Outcome.REFUSED),
    (ExecutionStopped('stop', 'cancelled'), Outcome.CANCELLED), (StoppedError('stop'), Outcome.CANCELLED),
    (ExecutionStopped('slow', 'timeout'), Outcome.ERROR), (ExecutionStopped('model', 'model_timeout'),
                                                           Outcome.MODEL_ERROR),
    (LLMError('down'), Outcome.MODEL_ERROR), (CassetteMissError('a', 'b', 'c'), Outcome.MODEL_ERROR),
    (GenerationError('wrong function'), Outcome.MODEL_ERROR), (RobotApiError('unreachable'), Outcome.ERROR),
    (SandboxProcessLost('gone', 'crashed'), Outcome.ERROR), (SandboxProcessLost('gone', 'cancelled'),
                                                             Outcome.CANCELLED),
    (ZeroDivisionError('x'), Outcome.ERROR)])
def test_an_error_names_its_outcome(error, outcome):
    assert outcome_of(error) is outcome


def test_the_engine_sets_the_outcome_of_every_result():
    engine = build_engine({'stop_robot': _stop_robot}, ScriptedClient(ANSWERS))
    for command, expected in EXPECTED.items():
        result = engine.run(command)
        assert result.outcome is expected, (command, result.message)
        assert result.success == (expected is Outcome.DONE)


def test_the_isolated_engine_carries_the_outcome_over_the_wire():
    engine = IsolatedEngine(build_engine, {'stop_robot': _stop_robot}, ScriptedClient(ANSWERS),
                            SandboxLimits(time_limit_s=10.0), jail='off')
    try:
        for command, expected in EXPECTED.items():
            result = engine.run(command)
            assert result.outcome is expected, (command, result.message)
    finally:
        engine.close()
    closed = engine.run('fine')
    assert closed.error_type == 'SandboxProcessLost' and closed.outcome is Outcome.ERROR


def test_the_builder_travels_by_name_and_must_be_found_there():
    assert builder_reference(build_engine) == 'cap_lmp.testing.minimal_engine:build_engine'
    with pytest.raises(ValueError, match='top level of a module'):
        IsolatedEngine(lambda api, client, limits: None, {}, ScriptedClient({}))


def test_both_engines_satisfy_the_command_engine_protocol():
    engine = build_engine({}, ScriptedClient(ANSWERS))
    assert isinstance(engine, CommandEngine)
    isolated = IsolatedEngine(build_engine, {}, ScriptedClient(ANSWERS), jail='off')
    try:
        assert isinstance(isolated, CommandEngine)
        assert isolated.default_lmp == engine.default_lmp == 'main'
    finally:
        isolated.close()
    # The signatures too: each protocol method can be called as the protocol declares it.
    for name in ('run', 'cancel', 'reset', 'add_listener', 'close'):
        declared = inspect.signature(getattr(CommandEngine, name))
        for implementation in (Engine, IsolatedEngine):
            actual = inspect.signature(getattr(implementation, name))
            actual.bind(*declared.parameters)  # the protocol's positional parameters fit
    assert inspect.signature(Engine.run).return_annotation in (CommandResult, 'CommandResult')
