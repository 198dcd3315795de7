"""The engine's options for benchmark harnesses, in process and through the sandbox process: an answer that
continues its query, a harness's source rule, an LMP that generates no functions, and running a chosen LMP with a
given context line."""
from __future__ import annotations

import os
import threading

import pytest

from cap_lmp.isolated_engine import IsolatedEngine
from cap_lmp.llm import OpenAICompatibleClient
from cap_lmp.testing.harness_engine import build_engine
from cap_lmp.testing.openai_server import ScriptedOpenAIServer

SIGNATURE = 'def twice(x):\n    """Twice x."""\n'
ANSWERS = {
    '"""Twice x."""': '    return UPPER(x) * 2',
    '# use a helper': 'y = helper_value(3)',
    '# define function: y = helper_value(3).': 'def helper_value(n):\n    return n + 1',
    '# report twice': 'report(twice(4))',
    '# report a missing function': 'report(not_there(4))',
    '# the first object': 'ret_val = sorted(objects)[0]',
    '# report the answer': 'report(ret_val)',
}


@pytest.fixture
def server():
    with ScriptedOpenAIServer(ANSWERS, fence_chat=False) as scripted:
        yield scripted


def _client(server: ScriptedOpenAIServer) -> OpenAICompatibleClient:
    return OpenAICompatibleClient(server.base_url, server.model, api='completions', max_retries=0)


def test_an_answer_that_continues_its_query_runs_as_one_program(server):
    reports = []
    engine = build_engine({'shout': lambda x: x, 'report': reports.append}, _client(server))
    done = engine.run(SIGNATURE, 'continue')
    assert done.success, done.message
    assert done.code.startswith('def twice(x):') and 'shout(x)' in done.code  # the harness rule applied
    prompt = server.requests[-1].prompt
    assert prompt == SIGNATURE  # the prompt ends where the answer continues: no newline added
    assert engine.run('report twice', 'main').success
    assert reports == [8]


def test_an_lmp_without_function_generation_refuses_undefined_calls(server):
    engine = build_engine({'report': print}, _client(server))
    result = engine.run('report a missing function', 'test')
    assert not result.success and 'not_there' in result.message
    assert not any('define function' in request.prompt for request in server.requests)
    generated = engine.run('use a helper', 'main')  # the session's main LMP does generate
    assert generated.success and generated.generated_functions == ['helper_value']


def test_the_sandbox_process_runs_the_lmp_and_context_it_is_given(server):
    reports = []
    engine = IsolatedEngine(build_engine, {'shout': lambda x: x, 'report': reports.append}, _client(server))
    try:
        assert engine.run(SIGNATURE, 'continue').success
        assert engine.run('report twice', 'main').success
        answered = engine.run('the first object', 'answer', context="objects = ['red block', 'blue bowl']")
        assert answered.success, answered.message
        assert "objects = ['red block', 'blue bowl']" in server.requests[-1].prompt
        assert engine.run('report the answer', 'test').success
        unknown = engine.run('anything', 'no such lmp')
        assert not unknown.success and 'no LMP named' in unknown.message
        assert engine.run('report twice').success  # the session lives on
    finally:
        engine.close()
    assert reports == [8, 'blue bowl', 8]


@pytest.mark.skipif(not hasattr(os, 'sched_setaffinity') or (os.cpu_count() or 1) < 2,
                    reason='needs two CPUs to pin to one')
def test_the_sandbox_process_is_not_held_to_the_cpu_its_parent_is_pinned_to(server):
    # A benchmark graph pins its threads to one CPU; the sandbox process it starts must not stay on it.
    box = {}

    def start_pinned() -> None:  # affinity is per thread on Linux: only this thread (and its children) are pinned
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
        box['engine'] = IsolatedEngine(build_engine, {'report': print}, _client(server))

    thread = threading.Thread(target=start_pinned)
    thread.start()
    thread.join()
    engine = box['engine']
    try:
        assert len(os.sched_getaffinity(engine.pid)) >= 2
    finally:
        engine.close()
