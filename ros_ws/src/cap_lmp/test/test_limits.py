"""The limits of a command, enforced by the node where the program cannot reach them (IsolatedEngine).

Each attack program runs in a real sandbox process; the model is a real HTTP server on 127.0.0.1, asked by the node
for the sandbox process; the robot is the toy domain's world in memory. Every test checks what a user notices: the
command ended within the limit's margin, the message names the cause, and the next command in the same engine moves
the block.
"""
from __future__ import annotations

import time

import numpy as np
import pytest

from cap_lmp.cassette import Cassette, CassetteClient
from cap_lmp.engine import check_program_size
from cap_lmp.errors import CodeRejected
from cap_lmp.isolated_engine import IsolatedEngine
from cap_lmp.llm import OpenAICompatibleClient
from cap_lmp.sandbox import SandboxLimits
from cap_lmp.testing.attack_programs import MOVE, PROGRAMS, SCENE, TIME_ATTACKS
from cap_lmp.testing.openai_server import ScriptedOpenAIServer, ScriptedReply
from cap_lmp.testing.toy_domain import build_engine
from cap_lmp.testing.toy_world import ToyWorld
from cap_lmp.wire import MAX_PROGRAM_CHARS

TIME_LIMIT_S = 2.0


@pytest.fixture
def server():
    with ScriptedOpenAIServer(PROGRAMS) as scripted:
        yield scripted


@pytest.fixture
def world() -> ToyWorld:
    return ToyWorld.with_objects(SCENE)


def make_engine(server, world, **options) -> IsolatedEngine:
    options = {'stall_limit_s': 30.0, 'model_time_limit_s': 30.0, 'address_space_extra_bytes': 700 << 20,
               **options}
    limits = options.pop('limits', SandboxLimits(time_limit_s=TIME_LIMIT_S, max_memory_growth_bytes=256 << 20))
    client = OpenAICompatibleClient(server.base_url, 'scripted-model', timeout_s=30.0, max_retries=0)
    return IsolatedEngine(build_engine, world.api(), client, limits, **options)


@pytest.fixture
def engine(server, world):
    isolated = make_engine(server, world)
    yield isolated
    isolated.close()


def assert_next_command_moves_the_block(engine: IsolatedEngine, world: ToyWorld) -> None:
    world.put_first_on_second('red block', SCENE['red block'])
    result = engine.run(MOVE)
    assert result.success, result.message
    assert np.allclose(world.get_obj_pos('red block'), SCENE['red bowl'])


@pytest.mark.parametrize('command', TIME_ATTACKS)
def test_the_time_limit_holds_for_any_program(engine, world, command):
    started = time.monotonic()
    result = engine.run(command)
    elapsed = time.monotonic() - started
    assert not result.success
    assert elapsed < TIME_LIMIT_S + 1.0, (elapsed, result.message)
    assert result.stop_reason in ('timeout', 'recursion'), result.message
    assert ('time limit' in result.message or 'nested calls deeper' in result.message), result.message
    assert_next_command_moves_the_block(engine, world)


def test_a_heartbeat_is_not_progress(engine, world):
    """GEOS runs without the interpreter, so the heartbeat goes on: the deadline kills it all the same."""
    pid = engine.pid
    result = engine.run('GEOS without the interpreter: buffer of a 30,000-point line')
    assert result.stop_reason == 'timeout' and result.error_type == 'SandboxProcessLost', result.message
    assert f'time limit of {TIME_LIMIT_S:g} s' in result.message and 'session was lost' in result.message
    assert engine.pid != pid
    assert result.timings['total_s'] < TIME_LIMIT_S + 1.0  # the kill comes KILL_MARGIN_S after the limit
    assert_next_command_moves_the_block(engine, world)


def test_the_model_is_asked_by_the_node_and_its_time_is_reported(engine, world, server):
    result = engine.run('ask once')
    assert result.success, result.message
    assert world.said == ["['red block', 'blue block']"]
    assert len(server.requests) == 2 and result.model_calls == 2
    assert 0 < result.timings['model_s'] < result.timings['total_s']


def test_a_slow_model_in_a_loop_meets_the_model_deadline(server, world):
    engine = make_engine(server, world, model_time_limit_s=2.0)
    try:
        server.push(ScriptedReply(), *[ScriptedReply(delay_s=0.4) for _ in range(20)])
        started = time.monotonic()
        result = engine.run('ask forever')  # the program catches every Exception: the deadline is not one
        elapsed = time.monotonic() - started
        assert not result.success and result.stop_reason == 'model_timeout', result.message
        assert 'model deadline of 2 s' in result.message
        assert 1.9 < result.timings['model_s'] < 3.0 and elapsed < 2.0 + TIME_LIMIT_S + 1.0
        assert engine.restarts == 0  # a friendly stop: the session stays
        server._queue.clear()
        assert_next_command_moves_the_block(engine, world)
    finally:
        engine.close()


def test_the_model_deadline_holds_in_process_too(server, world):
    """sandbox_process:=false: the engine gives each request the budget left, and stops the loop itself."""
    engine = build_engine(world.api(), OpenAICompatibleClient(server.base_url, 'scripted-model', max_retries=0),
                          SandboxLimits(time_limit_s=TIME_LIMIT_S), model_time_limit_s=2.0)
    server.push(ScriptedReply(), *[ScriptedReply(delay_s=0.4) for _ in range(20)])
    started = time.monotonic()
    result = engine.run('ask forever')
    assert result.stop_reason == 'model_timeout' and 'model deadline of 2 s' in result.message, result.message
    assert time.monotonic() - started < 2.0 + TIME_LIMIT_S + 1.0
    server._queue.clear()
    assert engine.run(MOVE).success and np.allclose(world.get_obj_pos('red block'), SCENE['red bowl'])


def test_a_model_that_hangs_costs_the_model_deadline_only(server, world):
    engine = make_engine(server, world, model_time_limit_s=2.0)
    try:
        server.push(ScriptedReply(delay_s=20.0))
        started = time.monotonic()
        result = engine.run(MOVE)
        assert not result.success and 'model deadline of 2 s' in result.message, result.message
        assert time.monotonic() - started < 2.0 + 1.5
        assert_next_command_moves_the_block(engine, world)
    finally:
        engine.close()


def test_cancel_while_the_model_is_asked_ends_within_the_grace(engine, world, server):
    server.push(ScriptedReply(), ScriptedReply(delay_s=20.0))
    cancel = __import__('threading').Timer(0.5, engine.cancel)
    cancel.start()
    started = time.monotonic()
    result = engine.run('ask once')
    cancel.join()
    assert not result.success and result.stop_reason == 'cancelled', result.message
    assert time.monotonic() - started < 0.5 + 2.0
    assert_next_command_moves_the_block(engine, world)


def test_the_cassette_records_in_the_node(server, world, tmp_path):
    path = tmp_path / 'recorded.yaml'
    backend = OpenAICompatibleClient(server.base_url, 'scripted-model')
    engine = IsolatedEngine(build_engine, world.api(), CassetteClient(path, mode='record', backend=backend),
                            SandboxLimits(time_limit_s=TIME_LIMIT_S))
    try:
        assert engine.run(MOVE).success
    finally:
        engine.close()
    entries = Cassette.load(path).entries()
    assert [(e.lmp, e.query) for e in entries] == [('toy_ui', MOVE)]


def test_a_memory_limit_hit_costs_that_command_only(engine, world):
    assert engine.run('remember seven').success
    full = engine.run('keep filling the memory')
    assert not full.success and full.stop_reason == 'memory', full.message
    assert 'MiB of memory' in full.message and 'were dropped' in full.message, full.message
    again = engine.run('use 100 MB')  # the stopped command's 256 MiB are gone
    assert again.success, again.message
    recalled = engine.run('recall seven')  # the session's own variables stay
    assert recalled.success and world.said[-1] == '7', recalled.message
    assert engine.restarts == 0
    assert_next_command_moves_the_block(engine, world)


def test_the_address_space_cap_stays_and_the_next_command_works(engine, world):
    result = engine.run('fill the address space')
    assert not result.success
    assert result.error_type == 'MemoryError' or result.stop_reason == 'memory', result.message
    assert engine.run('use 100 MB').success
    assert_next_command_moves_the_block(engine, world)


def test_a_program_over_the_size_limit_is_refused_before_it_runs(engine, world):
    result = engine.run('move in a long program')
    assert not result.success and result.error_type == 'CodeRejected', result.message
    assert f'{MAX_PROGRAM_CHARS:,} characters' in result.message and 'not run' in result.message
    assert np.allclose(world.get_obj_pos('red block'), SCENE['red block'])  # nothing of it ran
    assert_next_command_moves_the_block(engine, world)


def test_the_size_limit_is_one_constant():
    check_program_size('x = 1\n' * (MAX_PROGRAM_CHARS // 6))
    with pytest.raises(CodeRejected):
        check_program_size('x' * (MAX_PROGRAM_CHARS + 1))


# -------------------------------------------------------------------------------------------------------------------
# Single C calls the in-process sandbox refuses before they start (the first line; the kill above bounds the rest).
SINGLE_CALLS = {
    'np.repeat of a zero-width array': 'a = np.repeat(np.zeros((10, 0)), 10 ** 12, axis=0)',
    'ndarray.repeat of a zero-width array': 'a = np.zeros((10, 0)).repeat(10 ** 12, axis=0)',
    'np.maximum broadcasting an array and a list': 'a = np.maximum(np.zeros((10 ** 4, 1)), [0.0] * 10 ** 4)',
    'np.minimum broadcasting two arrays': 'a = np.minimum(np.zeros((10 ** 4, 1)), np.zeros(10 ** 4))',
    'np.percentile broadcasting its quantiles': 'a = np.percentile(np.zeros((10 ** 6, 1)), np.zeros(1000), axis=1)',
    'np.sum of an aliased nested list': 'row = [0.0] * 10 ** 6\ns = np.sum([row] * 1000)',
    'an object array of huge integers': 'a = np.array([10 ** 5000] * 1000)\nb = np.prod(a)',
    'np.full making an object array': 'a = np.full(10, 10 ** 40)',
    'sorted over aliased lists': 'a = [0] * 10 ** 6\nb = sorted([a] * 20000)',
    'list.sort over aliased lists': 'a = [0] * 10 ** 6\nb = [a] * 20000\nb.sort()',
    'max over aliased lists': 'a = [0] * 10 ** 6\nb = max([a] * 20000)',
    'np.linspace with a long string dtype': "a = np.linspace(0, 1, 1000, dtype='U1000000')",
    'np.linspace with a positional string dtype': "a = np.linspace(0, 1, 1000, True, False, 'U1000000')",
    'np.linspace with an object dtype': "a = np.linspace(0, 10 ** 6, 10 ** 6, dtype='O')",
    'Shapely buffer of a 100,000-point line': 'l = LineString(np.random.rand(100000, 2))\nb = l.buffer(0.5)',
}


@pytest.fixture(scope='module')
def sandbox():
    from cap_lmp.sandbox import Sandbox
    return Sandbox(SandboxLimits(time_limit_s=TIME_LIMIT_S))


@pytest.mark.parametrize('source', SINGLE_CALLS.values(), ids=list(SINGLE_CALLS))
def test_single_c_calls_are_refused_before_they_start(sandbox, source):
    from cap_lmp.errors import OperationRefused, ResourceLimitError
    from cap_lmp.testing.sandbox_programs import run_program
    started = time.monotonic()
    with pytest.raises((ResourceLimitError, OperationRefused)) as refused:
        run_program(sandbox, source)
    assert time.monotonic() - started < 1.0
    assert 'sandbox' in str(refused.value)
    assert run_program(sandbox, "say([sorted([3, 1, 2]), max([1, 4]), list(np.repeat(np.arange(2), 2))])")["said"]


def test_the_checked_builtins_keep_their_meaning(sandbox):
    from cap_lmp.testing.sandbox_programs import run_program
    said = run_program(sandbox, "a = [3, 1]\na.sort(reverse=True)\nsay([sorted(['bb', 'a'], key=len), a, "
                                "max([[1, 2], [3]], key=len), min([], default=7), min(3, 4), "
                                "list(np.percentile(np.arange(11), [10, 90])), "
                                "list(np.median(np.ones((2, 3)), axis=0))])")
    assert said['said'] == ["[['a', 'bb'], [3, 1], [1, 2], 7, 3, [np.float64(1.0), np.float64(9.0)], "
                            "[np.float64(1.0), np.float64(1.0), np.float64(1.0)]]"]


# -------------------------------------------------------------------------------------------------------------------
# A program's exception can carry anything: its report is bounded and the session goes on.
EXCEPTIONS = {
    'raise a 5,000-digit integer': 'raise ValueError(10 ** 5000)',
    'raise a list holding a 5,000-digit integer': 'raise KeyError([10 ** 5000])',
    'raise a thousand long texts': "raise ValueError(*(['a' * 10 ** 6] * 1000))",
    'raise an aliased nested list': 'row = [0] * 10 ** 6\nraise RuntimeError([row] * 1000)',
}


@pytest.mark.parametrize('isolated', [False, True], ids=['Engine', 'IsolatedEngine'])
def test_an_enormous_exception_is_reported_bounded(world, isolated):
    with ScriptedOpenAIServer({**EXCEPTIONS, MOVE: PROGRAMS[MOVE]}) as server:
        client = OpenAICompatibleClient(server.base_url, 'scripted-model', max_retries=0)
        limits = SandboxLimits(time_limit_s=TIME_LIMIT_S)
        engine = (IsolatedEngine(build_engine, world.api(), client, limits) if isolated
                  else build_engine(world.api(), client, limits))
        try:
            for command in EXCEPTIONS:
                started = time.monotonic()
                result = engine.run(command)
                assert not result.success and time.monotonic() - started < TIME_LIMIT_S
                assert result.error_type in ('ValueError', 'KeyError', 'RuntimeError'), result.message
                assert result.message.startswith(result.error_type) and len(result.message) < 12_000
                assert 'line 1' in result.message or 'line 2' in result.message, result.message[:300]
            if isolated:
                assert engine.restarts == 0
            assert_next_command_moves_the_block(engine, world)
        finally:
            if isolated:
                engine.close()


def test_the_sandbox_process_holds_no_model_credentials(server, world, monkeypatch):
    monkeypatch.setenv('CAP_LLM_API_KEY', 'secret-key')
    monkeypatch.setenv('OPENAI_API_KEY', 'secret-key')
    engine = make_engine(server, world)
    try:
        with open(f'/proc/{engine.pid}/environ', 'rb') as environ:
            assert b'secret-key' not in environ.read()
        assert engine.run('ask once').success  # the node asks the model for it
    finally:
        engine.close()
