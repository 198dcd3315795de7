"""Language model clients: one small interface, an OpenAI-compatible HTTP backend over `requests`.

The HTTP backend speaks the chat-completions protocol (`POST {base_url}/chat/completions`) or the legacy completions
protocol (`POST {base_url}/completions`), which OpenAI, vLLM, Ollama, llama.cpp's server and others implement.
Configuration comes from arguments or the environment:

    CAP_LLM_BASE_URL   e.g. http://127.0.0.1:8000/v1 (default https://api.openai.com/v1)
    CAP_LLM_MODEL      model name sent with every request
    CAP_LLM_API_KEY    bearer token; OPENAI_API_KEY is used when unset
    CAP_LLM_API        'chat' (default) or 'completions'
    CAP_LLM_TIMEOUT_S  seconds per HTTP attempt (default 60)

Transient failures are retried with exponential backoff: HTTP 408/409/429/5xx, timeouts, refused connections and
connections closed mid-answer. A request's `time_budget_s` bounds all of it, retries and backoff included: each
attempt gets at most what is left of the budget, and when the budget is spent the request fails with an LLMError
naming it (the answer of an attempt still under way is then abandoned).
"""
from __future__ import annotations

import os
import random
import re
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Protocol

import requests

from cap_lmp.errors import LLMError


@dataclass(frozen=True)
class CompletionRequest:
    """What an LMP asks for: the full prompt, plus the parts cassettes and logs key on."""

    lmp: str
    prompt: str
    query: str
    context: str = ''
    stop: tuple[str, ...] = ()
    max_tokens: int = 512
    temperature: float = 0.0
    seed: int | None = None  # for temperature > 0: the sampler's seed, so that a run can be repeated
    time_budget_s: float | None = None  # the most this request may take, retries included; None: no bound


@dataclass(frozen=True)
class Completion:
    """The model's answer and what it cost."""

    text: str
    model: str = ''
    prompt_tokens: int = 0
    completion_tokens: int = 0
    latency_s: float = 0.0
    source: str = ''  # 'http', or the provenance of a cassette entry
    attempts: int = 1


class LLMClient(Protocol):
    """Anything that turns a CompletionRequest into a Completion (HTTP endpoint, cassette, ...)."""

    def complete(self, request: CompletionRequest) -> Completion:
        ...


_FENCE = re.compile(r'```[ \t]*[\w+-]*[ \t]*\n(.*?)(?:\n[ \t]*```|\Z)', re.DOTALL)


def strip_code_fences(text: str) -> str:
    """The code inside Markdown fences (all fenced blocks joined), or the text unchanged if it has none."""
    blocks = [block for block in _FENCE.findall(text) if block.strip()]
    if not blocks:  # a closing fence alone at the end (the model never opened one) is not code either
        return re.sub(r'(?:\A|\n)[ \t]*```[ \t]*\s*\Z', '', text)
    return '\n'.join(block.rstrip() for block in blocks)


def truncate_at_stop(text: str, stop: tuple[str, ...]) -> str:
    """Cut the text at the first stop sequence (some servers ignore `stop`; the result must not depend on it)."""
    cut = len(text)
    for token in stop:
        if token:
            index = text.find(token)
            if index != -1:
                cut = min(cut, index)
    return text[:cut]


def truncate_at_line_stop(text: str, stop: tuple[str, ...]) -> str:
    """Cut the text where a line starts with a stop sequence (an inline `# comment` is not the next instruction)."""
    lines = text.split('\n')
    for index, line in enumerate(lines):
        if any(token and line.startswith(token) for token in stop):
            return '\n'.join(lines[:index])
    return text


def clean_chat_answer(text: str, stop: tuple[str, ...]) -> str:
    """Chat models wrap code in fences and often echo the query as a comment first: keep the code only."""
    code = strip_code_fences(text).strip('\n')
    lines = code.split('\n')
    while lines and (not lines[0].strip() or lines[0].lstrip().startswith('#')):
        lines.pop(0)
    return truncate_at_line_stop('\n'.join(lines), stop).rstrip()


DEFAULT_SYSTEM_PROMPT = ('You continue Python programs. Reply with the Python code that follows the last comment of '
                         'the user message, and nothing else: no explanations, no comments.')
_RETRY_STATUS = frozenset({408, 409, 429, 500, 502, 503, 504})
_CLOSED_MID_ANSWER = (requests.exceptions.ChunkedEncodingError, requests.exceptions.ContentDecodingError)
NO_MODEL_CONFIGURED = ('no model configured for the http backend: set CAP_LLM_MODEL (parameter model) and '
                       'CAP_LLM_BASE_URL (parameter base_url) to your OpenAI-compatible endpoint')


class _BudgetSpent(Exception):
    """Internal: the request's time budget ran out while an attempt was under way."""
_MAX_STOP_SEQUENCES = 4  # the OpenAI API accepts at most four


class OpenAICompatibleClient:
    """Chat or legacy completions over HTTP with a timeout and bounded retries (429, 5xx, timeouts)."""

    def __init__(self, base_url: str, model: str, api_key: str | None = None, *, api: str = 'chat',
                 timeout_s: float = 60.0, max_retries: int = 4, backoff_s: float = 1.0, backoff_max_s: float = 30.0,
                 system_prompt: str = DEFAULT_SYSTEM_PROMPT, sleep: Callable[[float], None] = time.sleep,
                 session: requests.Session | None = None) -> None:
        if api not in ('chat', 'completions'):
            raise ValueError(f"api must be 'chat' or 'completions', not {api!r}")
        self.base_url = base_url.rstrip('/')
        self.model = model
        self.api_key = api_key
        self.api = api
        self.timeout_s = timeout_s
        self.max_retries = max_retries
        self.backoff_s = backoff_s
        self.backoff_max_s = backoff_max_s
        self.system_prompt = system_prompt
        self._sleep = sleep
        self._session = session or requests.Session()

    @classmethod
    def from_env(cls, **overrides: Any) -> 'OpenAICompatibleClient':
        """Build from CAP_LLM_* variables (see the module docstring); keyword arguments override them."""
        settings: dict[str, Any] = {
            'base_url': os.environ.get('CAP_LLM_BASE_URL', 'https://api.openai.com/v1'),
            'model': os.environ.get('CAP_LLM_MODEL', ''),
            'api_key': os.environ.get('CAP_LLM_API_KEY') or os.environ.get('OPENAI_API_KEY'),
            'api': os.environ.get('CAP_LLM_API', 'chat'),
            'timeout_s': float(os.environ.get('CAP_LLM_TIMEOUT_S', '60')),
        }
        settings.update(overrides)
        if not settings['model']:
            raise LLMError(NO_MODEL_CONFIGURED)
        return cls(**settings)

    # -- protocol ------------------------------------------------------------------------------------------
    def _payload(self, request: CompletionRequest) -> tuple[str, dict[str, Any]]:
        payload: dict[str, Any] = {'model': self.model, 'temperature': request.temperature,
                                   'max_tokens': request.max_tokens}
        if request.seed is not None:
            payload['seed'] = request.seed
        # Chat models tend to open with a comment echoing the query, so a stop of '#' sent to the server would end
        # the answer before any code: for chat the stop sequences are applied here, at line starts, instead.
        if request.stop and self.api == 'completions':
            payload['stop'] = list(request.stop[:_MAX_STOP_SEQUENCES])
        if self.api == 'chat':
            # No system prompt (''): the model's chat template puts its own default in, as its makers evaluate it.
            system = [{'role': 'system', 'content': self.system_prompt}] if self.system_prompt else []
            payload['messages'] = system + [{'role': 'user', 'content': request.prompt}]
            return f'{self.base_url}/chat/completions', payload
        payload['prompt'] = request.prompt
        return f'{self.base_url}/completions', payload

    def _text(self, body: dict[str, Any], request: CompletionRequest) -> str:
        try:
            choice = body['choices'][0]
            if self.api == 'chat':
                return clean_chat_answer(choice['message']['content'] or '', request.stop)
            return truncate_at_stop(choice['text'], request.stop).rstrip()
        except (KeyError, IndexError, TypeError) as error:
            raise LLMError(f'the model server answered without a completion ({error!r}): {str(body)[:200]}') from None

    def _delay(self, attempt: int, response: requests.Response | None) -> float:
        delay = self.backoff_s * (2 ** attempt) * (0.75 + 0.5 * random.random())
        if response is not None:
            retry_after = response.headers.get('Retry-After')
            if retry_after:
                try:
                    delay = max(delay, float(retry_after))
                except ValueError:
                    pass
        return min(delay, self.backoff_max_s)

    def _post(self, url: str, payload: dict[str, Any], headers: dict[str, str], timeout_s: float,
              deadline: float | None) -> requests.Response:
        """One attempt. Without a deadline, in this thread; with one, waited for no longer than the deadline.

        `timeout_s` bounds each socket operation, not the whole answer (a server may trickle it), so a request with a
        budget runs its attempt on a helper thread and abandons it when the budget is spent.
        """
        if deadline is None:
            return self._session.post(url, json=payload, headers=headers, timeout=timeout_s)
        outcome: dict[str, Any] = {}

        def attempt() -> None:
            try:
                outcome['response'] = self._session.post(url, json=payload, headers=headers, timeout=timeout_s)
            except BaseException as error:  # handed to the waiting thread, which raises it there
                outcome['error'] = error

        worker = threading.Thread(target=attempt, name='llm-request', daemon=True)
        worker.start()
        worker.join(max(0.0, deadline - time.monotonic()))
        if worker.is_alive():
            raise _BudgetSpent()
        if 'error' in outcome:
            raise outcome['error']
        return outcome['response']

    def complete(self, request: CompletionRequest) -> Completion:
        url, payload = self._payload(request)
        headers = {'Content-Type': 'application/json'}
        if self.api_key:
            headers['Authorization'] = f'Bearer {self.api_key}'
        started = time.monotonic()
        budget = request.time_budget_s
        deadline = None if budget is None else started + max(0.0, budget)
        last_problem = ''
        attempts = 0

        def budget_spent() -> LLMError:
            detail = f'; last: {last_problem}' if last_problem else ''
            return LLMError(f'the model server at {url} gave no answer within the time budget of {budget:g} s '
                            f'({attempts} attempt{"s" if attempts != 1 else ""}{detail})')

        for attempt in range(self.max_retries + 1):
            timeout_s = self.timeout_s
            if deadline is not None:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise budget_spent()
                timeout_s = min(timeout_s, left)
            attempts += 1
            response = None
            try:
                response = self._post(url, payload, headers, timeout_s, deadline)
            except _BudgetSpent:
                last_problem = 'an answer still under way'
                raise budget_spent() from None
            except requests.Timeout:
                last_problem = f'no answer within {timeout_s:g} s'
            except _CLOSED_MID_ANSWER as error:
                last_problem = f'the connection closed mid-answer ({error.__class__.__name__})'
            except requests.ConnectionError as error:
                last_problem = f'connection failed ({error.__class__.__name__})'
            if response is not None:
                if response.status_code == 200:
                    try:
                        body = response.json()
                    except ValueError:
                        raise LLMError(f'the model server at {url} sent a response that is not JSON') from None
                    usage = body.get('usage') or {}
                    return Completion(text=self._text(body, request), model=body.get('model') or self.model,
                                      prompt_tokens=int(usage.get('prompt_tokens') or 0),
                                      completion_tokens=int(usage.get('completion_tokens') or 0),
                                      latency_s=time.monotonic() - started, source='http', attempts=attempt + 1)
                last_problem = f'HTTP {response.status_code}: {_error_text(response)}'
                if response.status_code not in _RETRY_STATUS:
                    raise LLMError(f'the model server at {url} refused the request: {last_problem}')
            if attempt < self.max_retries:
                delay = self._delay(attempt, response)
                if deadline is not None and time.monotonic() + delay >= deadline:
                    raise budget_spent()  # the next attempt could not start within the budget
                self._sleep(delay)
        raise LLMError(f'the model server at {url} gave no answer after {self.max_retries + 1} attempts; '
                       f'last: {last_problem}')


def _error_text(response: requests.Response) -> str:
    try:
        error = response.json().get('error')
        if isinstance(error, dict):
            return str(error.get('message', error))[:300]
        if error:
            return str(error)[:300]
    except (ValueError, AttributeError):
        pass
    return response.text[:300]
