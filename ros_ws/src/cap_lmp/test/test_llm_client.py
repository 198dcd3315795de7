"""The OpenAI-compatible HTTP client against a real local server speaking the protocol."""
from __future__ import annotations

import dataclasses
import time

import pytest

from cap_lmp.errors import LLMError
from cap_lmp.llm import (CompletionRequest, OpenAICompatibleClient, clean_chat_answer, strip_code_fences,
                         truncate_at_stop)
from cap_lmp.testing.openai_server import ScriptedOpenAIServer, ScriptedReply


def request(query: str = 'say hello', stop: tuple[str, ...] = ('#',)) -> CompletionRequest:
    return CompletionRequest(lmp='tabletop_ui', prompt=f'# hints\n# {query}.\n', query=query, stop=stop)


@pytest.fixture
def server():
    with ScriptedOpenAIServer({'say hello': "say('hello')"}) as scripted:
        yield scripted


def test_chat_completion_strips_fences_and_records_usage(server):
    client = OpenAICompatibleClient(server.base_url, 'my-model', api_key='secret-key', backoff_s=0.01)
    completion = client.complete(request())
    assert completion.text == "say('hello')"
    assert completion.model == 'my-model' and completion.source == 'http' and completion.attempts == 1
    assert completion.prompt_tokens > 0 and completion.completion_tokens == 1
    assert completion.latency_s > 0
    sent = server.requests[0]
    assert sent.path == '/v1/chat/completions'
    assert sent.headers['authorization'] == 'Bearer secret-key'
    assert sent.body['temperature'] == 0 and 'stop' not in sent.body  # applied by the client, see below
    assert sent.body['messages'][-1] == {'role': 'user', 'content': '# hints\n# say hello.\n'}


def test_legacy_completions_cut_at_stop_tokens_even_if_the_server_ignores_them(server):
    server.answers['say hello'] = "say('hello')\n# next instruction.\nsay('more')"
    client = OpenAICompatibleClient(server.base_url, 'my-model', api='completions', backoff_s=0.01)
    completion = client.complete(request())
    assert completion.text == "say('hello')"
    assert server.requests[0].body['prompt'] == '# hints\n# say hello.\n'


def test_configuration_from_the_environment(server, monkeypatch):
    monkeypatch.setenv('CAP_LLM_BASE_URL', server.base_url)
    monkeypatch.setenv('CAP_LLM_MODEL', 'env-model')
    monkeypatch.delenv('CAP_LLM_API_KEY', raising=False)
    monkeypatch.setenv('OPENAI_API_KEY', 'openai-key')
    monkeypatch.setenv('CAP_LLM_API', 'completions')
    client = OpenAICompatibleClient.from_env(backoff_s=0.01)
    assert client.complete(request()).text == "say('hello')"
    sent = server.requests[0]
    assert sent.body['model'] == 'env-model' and sent.headers['authorization'] == 'Bearer openai-key'
    assert sent.path == '/v1/completions'


def test_no_model_configured_is_a_clear_error(monkeypatch):
    monkeypatch.delenv('CAP_LLM_MODEL', raising=False)
    with pytest.raises(LLMError, match='CAP_LLM_MODEL'):
        OpenAICompatibleClient.from_env()


def test_server_errors_and_timeouts_are_retried(server):
    server.push(ScriptedReply(status=500), ScriptedReply(status=503), ScriptedReply(delay_s=1.0))
    client = OpenAICompatibleClient(server.base_url, 'm', backoff_s=0.01, timeout_s=0.3, max_retries=3)
    completion = client.complete(request())
    assert completion.text == "say('hello')" and completion.attempts == 4


def test_a_connection_closed_mid_answer_is_retried(server):
    server.push(ScriptedReply(close_after_bytes=20), ScriptedReply(close_after_bytes=0))
    client = OpenAICompatibleClient(server.base_url, 'm', backoff_s=0.01, max_retries=2)
    completion = client.complete(request())
    assert completion.text == "say('hello')" and completion.attempts == 3


def test_a_connection_closed_mid_answer_every_time_names_the_cause(server):
    server.push(*[ScriptedReply(close_after_bytes=20) for _ in range(2)])
    client = OpenAICompatibleClient(server.base_url, 'm', backoff_s=0.01, max_retries=1)
    with pytest.raises(LLMError, match=r'no answer after 2 attempts; last: the connection closed mid-answer'):
        client.complete(request())


def test_the_time_budget_bounds_a_slow_model_retries_included(server):
    """Each slow failure alone is within its timeout (10 s), but two do not fit the 1.5 s budget."""
    server.push(*[ScriptedReply(status=503, delay_s=1.0) for _ in range(3)])
    client = OpenAICompatibleClient(server.base_url, 'm', backoff_s=0.01, timeout_s=10.0, max_retries=4)
    started = time.monotonic()
    with pytest.raises(LLMError, match=r'no answer within the time budget of 1\.5 s \(2 attempts'):
        client.complete(dataclasses.replace(request(), time_budget_s=1.5))
    assert time.monotonic() - started < 1.5 + 0.5


def test_the_time_budget_bounds_an_answer_trickled_byte_by_byte(server):
    server.push(ScriptedReply(trickle_s=0.05))  # some 300 bytes: 15 s, each read well within its timeout
    client = OpenAICompatibleClient(server.base_url, 'm', backoff_s=0.01, timeout_s=10.0)
    started = time.monotonic()
    with pytest.raises(LLMError, match=r'time budget of 1 s \(1 attempt; last: an answer still under way\)'):
        client.complete(dataclasses.replace(request(), time_budget_s=1.0))
    assert time.monotonic() - started < 1.0 + 0.5


def test_no_backoff_sleep_past_the_budget(server):
    server.push(ScriptedReply(status=503, headers={'Retry-After': '20'}))
    slept = []
    client = OpenAICompatibleClient(server.base_url, 'm', sleep=slept.append, max_retries=3)
    with pytest.raises(LLMError, match=r'time budget of 5 s \(1 attempt; last: HTTP 503'):
        client.complete(dataclasses.replace(request(), time_budget_s=5.0))
    assert slept == [] and len(server.requests) == 1


def test_a_budget_that_suffices_changes_nothing(server):
    server.push(ScriptedReply(status=500))
    client = OpenAICompatibleClient(server.base_url, 'm', backoff_s=0.01)
    completion = client.complete(dataclasses.replace(request(), time_budget_s=30.0))
    assert completion.text == "say('hello')" and completion.attempts == 2


def test_retries_are_bounded(server):
    server.push(*[ScriptedReply(status=429) for _ in range(5)])
    client = OpenAICompatibleClient(server.base_url, 'm', backoff_s=0.01, max_retries=2)
    with pytest.raises(LLMError, match='no answer after 3 attempts; last: HTTP 429'):
        client.complete(request())
    assert len(server.requests) == 3


def test_client_errors_are_not_retried(server):
    client = OpenAICompatibleClient(server.base_url, 'm', backoff_s=0.01)
    with pytest.raises(LLMError, match='refused the request: HTTP 400: no scripted answer'):
        client.complete(request('something unscripted'))
    assert len(server.requests) == 1


def test_unreachable_server_is_reported():
    client = OpenAICompatibleClient('http://127.0.0.1:9/v1', 'm', backoff_s=0.01, max_retries=1, timeout_s=1)
    with pytest.raises(LLMError, match='connection failed'):
        client.complete(request())


def test_answer_cleaning():
    assert strip_code_fences('Here:\n```python\nx = 1\n```\nand\n```\ny = 2\n```') == 'x = 1\ny = 2'
    assert strip_code_fences('x = 1') == 'x = 1'
    assert strip_code_fences('def f():\n    return 1\n```\n') == 'def f():\n    return 1'  # a fence never opened


def test_an_empty_system_prompt_leaves_the_models_own_default_to_its_chat_template(server):
    client = OpenAICompatibleClient(server.base_url, 'my-model', system_prompt='', backoff_s=0.01)
    assert client.complete(request()).text == "say('hello')"
    assert server.requests[0].body['messages'] == [{'role': 'user', 'content': '# hints\n# say hello.\n'}]
    assert truncate_at_stop('a = 1\n# b\nobjects = [', ('#', 'objects = [')) == 'a = 1\n'
    assert clean_chat_answer("```python\n# put it there.\nput(1)\n# done\n```", ('#',)) == 'put(1)'
    assert clean_chat_answer("```python\nx = 1  # metres\nsay(x)\n# next.\nmore()\n```", ('#',)) == \
        'x = 1  # metres\nsay(x)'
