"""IsolatedEngine: the session runs in a sandbox process, the robot stays here.

The model is a real HTTP server on 127.0.0.1, asked by the node's side for the sandbox process (which sends its
requests as messages); the robot is the toy domain's world in memory, called through the message channel. The C-level
pathologies the in-process sandbox cannot bound (see sandbox.py, "What it does not guarantee") end the sandbox
process here, never the host.
"""
from __future__ import annotations

import os
import sys
import threading
import time

import numpy as np
import pytest

from cap_lmp import wire
from cap_lmp.engine import CODE, DONE, EXECUTING, GENERATING
from cap_lmp.errors import StoppedError
from cap_lmp.isolated_engine import IsolatedEngine
from cap_lmp.llm import OpenAICompatibleClient
from cap_lmp.sandbox import SandboxLimits
from cap_lmp.testing.openai_server import ScriptedOpenAIServer
from cap_lmp.testing.toy_domain import build_engine
from cap_lmp.testing.toy_world import ToyWorld

SCENE = {'red block': (-0.1, -0.4), 'blue block': (0.1, -0.45), 'red bowl': (-0.15, -0.65)}
PROGRAMS = {
    'put the red block in the red bowl': ("put_first_on_second('red block', 'red bowl')\n"
                                          "where = get_obj_pos('red block')\nsay(where)"),
    'say where it went': 'say(where * 2)',
    'move the purple block': "put_first_on_second('purple block', 'red bowl')",
    'hand the robot a function': "put_first_on_second('red block', say)",
    'count forever': 'n = 0\nwhile True:\n    n += 1',
    'grow past the address space': 'row = [0] * 10 ** 6\nrows = [row * 1 for i in range(200)]',
    'crash the interpreter': 't = ()\nfor i in range(300000):\n    t = (t,)\nh = hash(t)',
    'ask the blocks': "blocks = parse_obj_name('the blocks', f'objects = {get_obj_names()}')\nsay(blocks)",
    '# the blocks.': "ret_val = [name for name in objects if 'block' in name]",
    'move slowly': "slow_move()\nsay('after the move')",
    'ask with a list': "where = [0, 0]\nblocks = parse_obj_name([0, 0], [1, 1])",
}
# Quadratic C work on aliased data, each within the sandbox's size limits (test_sandbox_review.QUADRATIC_ATTEMPTS).
QUADRATIC = {
    'str of an aliased nested list': 'row = [0] * 10 ** 6\ns = str([row] * 1000)',
    'hash of an aliased nested tuple': 't = (0,) * 10 ** 6\nh = hash((t,) * 20000)',
    'list.count comparing long lists': 'a = [0] * 10 ** 6\nc = ([a] * 20000).count(list(a))',
    'set of integers with one hash': 'xs = [i * (2 ** 61 - 1) for i in range(60000)]\ns = set(xs)',
}


@pytest.fixture
def server():
    with ScriptedOpenAIServer({**PROGRAMS, **QUADRATIC}) as scripted:
        yield scripted


@pytest.fixture
def world() -> ToyWorld:
    return ToyWorld.with_objects(SCENE)


@pytest.fixture
def engine(server, world):
    client = OpenAICompatibleClient(server.base_url, 'scripted-model', timeout_s=10.0)
    isolated = IsolatedEngine(build_engine, world.api(), client,
                              SandboxLimits(time_limit_s=60.0), stall_limit_s=2.0,
                              address_space_extra_bytes=400 << 20)
    yield isolated
    isolated.close()


def test_robot_calls_cross_the_boundary_and_the_session_keeps_variables(engine, world):
    events = []
    engine.add_listener(events.append)
    first = engine.run('put the red block in the red bowl')
    assert first.success, first.message
    assert np.allclose(world.get_obj_pos('red block'), SCENE['red bowl'])
    assert [(e.stage, e.lmp) for e in events] == [(GENERATING, 'toy_ui'), (CODE, 'toy_ui'), (EXECUTING, 'toy_ui'),
                                                   (DONE, 'toy_ui')]
    second = engine.run('say where it went')  # `where` is an ndarray that lives in the sandbox process
    assert second.success, second.message
    assert world.said == ['[-0.15 -0.65]', '[-0.3 -1.3]']
    assert engine.pid != os.getpid()


def test_a_nested_lmp_call_runs_in_the_sandbox_process(engine, world):
    result = engine.run('ask the blocks')
    assert result.success, result.message
    assert world.said == ["['red block', 'blue block']"] and result.model_calls == 2


def test_an_lmp_asked_with_something_other_than_text_is_an_error_and_the_session_stays(engine):
    pid = engine.pid
    result = engine.run('ask with a list')
    assert not result.success and result.error_type == 'TypeError', result.message
    assert 'parse_obj_name() takes its description as text, not list' in result.message
    assert engine.pid == pid and engine.restarts == 0
    assert engine.run('put the red block in the red bowl').success


def test_robot_errors_reach_the_program_with_their_message(engine):
    unknown = engine.run('move the purple block')
    assert not unknown.success
    assert "'purple block'" in unknown.message and 'line 1' in unknown.message
    bad_value = engine.run('hand the robot a function')
    assert not bad_value.success
    assert bad_value.error_type == 'TypeError' and 'cannot be passed to the robot' in bad_value.message
    assert engine.run('put the red block in the red bowl').success


def test_an_endless_loop_is_stopped_by_the_sandbox_and_the_process_stays(server, world):
    quick = IsolatedEngine(build_engine, world.api(), OpenAICompatibleClient(server.base_url, 'scripted-model'),
                           SandboxLimits(time_limit_s=1.0))
    try:
        pid = quick.pid
        result = quick.run('count forever')
        assert not result.success and result.stop_reason == 'timeout', result.message
        assert quick.pid == pid and quick.restarts == 0
        assert quick.run('put the red block in the red bowl').success
    finally:
        quick.close()


def test_a_robot_call_that_outlasts_the_time_limit_is_ended_by_stopping_the_robot(server, world):
    stopped = threading.Event()

    def slow_move() -> str:  # a motion of 30 s, unless the robot is stopped
        if stopped.wait(30.0):
            raise StoppedError('the motion was stopped')
        return 'arrived'

    limited = IsolatedEngine(build_engine, {**world.api(), 'slow_move': slow_move},
                             OpenAICompatibleClient(server.base_url, 'scripted-model'), SandboxLimits(time_limit_s=1.0),
                             on_deadline=stopped.set)
    try:
        result = limited.run('move slowly')
        assert stopped.is_set() and not result.success, result.message
        assert result.stop_reason == 'timeout', result.message  # the run's stop: no program can catch it
        assert result.message.startswith('the time limit of 1 s passed during slow_move(), so the robot was stopped')
        assert world.said == [] and limited.restarts == 0  # the program went no further, and the session stays
    finally:
        limited.close()


def test_cancel_stops_a_running_program(engine):
    timer = threading.Timer(1.0, engine.cancel)
    timer.start()
    result = engine.run('count forever')
    timer.join()
    assert not result.success and result.stop_reason == 'cancelled'
    assert engine.run('put the red block in the red bowl').success


def test_running_out_of_address_space_is_a_memory_error_of_the_program(engine):
    result = engine.run('grow past the address space')
    assert not result.success
    assert result.error_type == 'MemoryError' or result.stop_reason == 'memory', result.message
    assert engine.run('put the red block in the red bowl').success


def test_a_c_stack_overflow_costs_the_session_not_the_host(engine, world):
    assert engine.run('put the red block in the red bowl').success
    pid = engine.pid
    crashed = engine.run('crash the interpreter')
    assert not crashed.success and crashed.error_type == 'SandboxProcessLost' and crashed.stop_reason == 'crashed'
    assert 'SIGSEGV' in crashed.message and 'session was lost' in crashed.message
    assert engine.pid != pid and engine.restarts == 1
    forgotten = engine.run('say where it went')
    assert not forgotten.success and forgotten.error_type == 'NameError'
    assert engine.run('put the red block in the red bowl').success


@pytest.mark.parametrize('command', QUADRATIC)
def test_quadratic_c_work_is_killed_as_a_stall(engine, command):
    result = engine.run(command)
    assert not result.success
    assert result.stop_reason == 'stalled' and 'stopped responding' in result.message
    assert engine.run('put the red block in the red bowl').success


def test_reset_forgets_the_session(engine):
    assert engine.run('put the red block in the red bowl').success
    engine.reset()
    assert engine.run('say where it went').error_type == 'NameError'


def test_a_closed_engine_refuses_to_run(engine):
    engine.close()
    result = engine.run('put the red block in the red bowl')
    assert not result.success and 'closed' in result.message


@pytest.mark.parametrize('document', [
    b'[1, 2]', b'{"op": ', b'\xff\xfe', b'{"x": {"__ndarray__": [[2], "|O", [1, 2]]}}',
    b'{"x": {"__ndarray__": [[3], "<f8", [1, 2]]}}', b'{"x": {"__ndarray__": [[-1], "<f8", []]}}',
    b'[' * 100000 + b']' * 100000,
])
def test_the_wire_refuses_anything_but_json_objects_and_numeric_arrays(document):
    with pytest.raises(wire.WireError):
        wire.decode(document)


def test_the_wire_round_trips_arrays_and_bounds_what_it_sends():
    message = wire.decode(wire.encode({'value': np.arange(6.0).reshape(2, 3), 'names': ('a', 'b'), 'n': np.int64(3)}))
    assert message['value'].shape == (2, 3) and message['names'] == ['a', 'b'] and message['n'] == 3
    row = list(range(1000))
    with pytest.raises(wire.WireError):
        wire.encode({'args': [row] * 1000})  # aliased: a million items to write
    with pytest.raises(wire.WireError):
        wire.encode({'args': [np.array(['text'])]})


# -------------------------------------------------------------------------------------------------------------------
# A sandbox process whose code escaped the in-process checks is hostile: it may send anything or nothing. The node's
# side must return a clear result within its limits, kill the process, and keep working.

def living_processes_in_group(group: int) -> list[int]:
    """Pids of processes in process group `group` that are not zombies (a killed orphan waits to be reaped)."""
    living = []
    for entry in os.listdir('/proc'):
        if entry.isdigit():
            try:
                with open(f'/proc/{entry}/stat', encoding='ascii', errors='replace') as stat:
                    fields = stat.read().rsplit(')', 1)[1].split()
            except OSError:
                continue
            if int(fields[2]) == group and fields[0] not in 'ZX':
                living.append(int(entry))
    return living


def hostile_engine(mode: str, api=None, **options) -> IsolatedEngine:
    options = {'stall_limit_s': 1.0, 'cancel_grace_s': 0.5, 'start_timeout_s': 10.0, 'send_timeout_s': 1.0,
               **options}
    return IsolatedEngine(build_engine, api or {'where': lambda: 'here', 'slow': lambda: time.sleep(2.0)},
                          OpenAICompatibleClient('http://127.0.0.1:9', 'no-model'),
                          options.pop('limits', SandboxLimits(time_limit_s=2.0)),
                          child_command=[sys.executable, '-m', 'cap_lmp.testing.hostile_child', mode], **options)


@pytest.mark.parametrize('mode, reason', [
    ('half_message', 'stalled'),  # a frame that never completes must not block the node
    ('flood', 'timeout'),  # heartbeats forever: the command's deadline still ends it
    ('calls_without_reading', 'protocol'),  # the node's replies fill the socket: its send times out
    ('huge_integer', 'protocol'),
    ('result_of_wrong_shape', 'protocol'),
    ('result_of_wrong_types', 'protocol'),
    ('unknown_outcome', 'protocol'),
    ('outcome_against_success', 'protocol'),  # 'done' with success false
    ('empty_event', 'protocol'),
    ('realtime_signal', 'crashed'),
    ('grandchild_keeps_the_socket', 'crashed'),  # the child died; its grandchild must not keep the run alive
])
def test_a_hostile_sandbox_process_is_killed_with_a_clear_result(mode, reason):
    engine = hostile_engine(mode)
    try:
        first_pid = engine.pid
        result = engine.run('cmd')
        assert not result.success and result.error_type == 'SandboxProcessLost'
        assert result.stop_reason == reason, result.message
        assert 'session was lost' in result.message
        assert engine.pid != first_pid and engine.restarts == 1
        deadline = time.monotonic() + 2.0  # SIGKILL was sent to the group; the kernel ends them within moments
        while living_processes_in_group(first_pid) and time.monotonic() < deadline:
            time.sleep(0.02)
        assert living_processes_in_group(first_pid) == []  # grandchildren included
        again = engine.run('cmd')  # the new process misbehaves the same way: still a result, never an exception
        assert not again.success and again.stop_reason == reason
    finally:
        engine.close()


def test_a_hostile_process_that_never_gets_ready_fails_the_start_in_time():
    with pytest.raises(RuntimeError, match='did not start'):
        hostile_engine('never_ready', start_timeout_s=1.0)


def test_a_flood_does_not_hide_a_cancel():
    engine = hostile_engine('flood', limits=SandboxLimits(time_limit_s=600.0))
    try:
        threading.Timer(0.3, engine.cancel).start()
        result = engine.run('cmd')
        assert result.stop_reason == 'cancelled' and 'did not stop within' in result.message
    finally:
        engine.close()


def test_the_cancel_grace_starts_after_the_robot_call_that_was_running():
    # A stop arrives during a 2 s robot call; the program answers 0.1 s after the call returns: not a failure to stop.
    engine = hostile_engine('slow_robot_then_result', stall_limit_s=5.0)
    try:
        threading.Timer(0.3, engine.cancel).start()
        result = engine.run('cmd')
        assert result.error_type == 'StoppedError' and engine.restarts == 0
    finally:
        engine.close()


def test_close_during_a_run_ends_the_run_with_a_result():
    engine = hostile_engine('flood', limits=SandboxLimits(time_limit_s=600.0))
    threading.Timer(0.3, engine.close).start()
    result = engine.run('cmd')
    assert not result.success and 'shutting down' in result.message
    assert engine.run('cmd').message.startswith('the sandbox process was closed')


def test_the_node_checks_the_model_requests_of_a_hostile_process():
    """Malformed model requests get an error reply and never reach the model; a well-formed one is answered."""
    import json
    with ScriptedOpenAIServer({'the blocks': 'ret_val = 1'}) as scripted:
        client = OpenAICompatibleClient(scripted.base_url, 'scripted-model', max_retries=0)
        engine = IsolatedEngine(build_engine, {}, client,
                                SandboxLimits(time_limit_s=5.0), model_time_limit_s=3.0,
                                child_command=[sys.executable, '-m', 'cap_lmp.testing.hostile_child',
                                               'asks_the_model_badly'])
        try:
            result = engine.run('cmd')
        finally:
            engine.close()
        replies = json.loads(result.message)
        assert all('malformed model request' in reply['error']['message'] for reply in replies[:3]), replies
        assert replies[3]['completion']['text'] == 'ret_val = 1', replies[3]
        assert len(scripted.requests) == 1  # only the well-formed request reached the model
        assert 0 < result.timings['model_s'] < 3.0
