"""One sandboxed evaluation session: the model's code runs in the project's sandbox process, judged on the host.

A benchmark item goes the way of a user's command: the model is asked through the project's engine (prompt
assembly, function generation, the sandbox's checks), its code runs in the sandbox process (IsolatedEngine: time
limit, memory limit, the jail), and then a trusted test program written here runs in the same session (in a copy of
its scope) and hands its observations to the host with `report(value)`. Where the benchmark compares outputs
(codegen, reasoning), the host decides pass or fail, where the program cannot reach; HumanEval's verdict is its own
test's assertions, run in that copy of the scope, after the host has refused completions that rebind what the test
relies on (humaneval/policy.py).

`report` takes values only while a test program runs, at most MAX_REPORTS of them and MAX_REPORTED_ITEMS items
(numbers, characters, array elements) in all: the model's own code cannot flood the host.

The test program travels as the answer of the LMP named HARNESS_LMP: HarnessClient answers that LMP itself with the
program queued by `run_program`, and sends every other request to the model's endpoint, recording each one (prompt,
answer, tokens, latency) for the per-item log.
"""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Mapping

import numpy as np

from cap_lmp.engine import CommandResult, LMPConfig
from cap_lmp.errors import LLMError
from cap_lmp.isolated_engine import IsolatedEngine
from cap_lmp.llm import Completion, CompletionRequest, LLMClient
from cap_lmp.sandbox import SandboxLimits

HARNESS_LMP = 'harness'  # the LMP whose "answer" is the host's own test program
REPORT_API = 'report'  # the function test programs hand their observations to the host with
MAX_REPORTS = 100  # per test program: codegen reports one output per case (at most 8)
MAX_REPORTED_ITEMS = 2_000_000  # numbers, characters and array elements of all reports of one test program


def reported_items(value: Any, budget: int) -> int:
    """How many items a reported value holds (stops counting past `budget`)."""
    if isinstance(value, (str, bytes)):
        return max(1, len(value))
    if isinstance(value, np.ndarray):
        return max(1, value.size)
    if isinstance(value, dict):
        value = list(value.values())
    if isinstance(value, (list, tuple)):
        total = 1
        for item in value:
            total += reported_items(item, budget - total)
            if total > budget:
                break
        return total
    return 1


@dataclass(frozen=True)
class ModelCall:
    """One request to the model's endpoint, as the per-item log keeps it."""

    lmp: str
    query: str
    prompt: str
    completion: str
    prompt_tokens: int
    completion_tokens: int
    latency_s: float
    error: str = ''

    def as_dict(self) -> dict[str, Any]:
        return {'lmp': self.lmp, 'query': self.query, 'prompt': self.prompt, 'completion': self.completion,
                'prompt_tokens': self.prompt_tokens, 'completion_tokens': self.completion_tokens,
                'latency_s': round(self.latency_s, 4), 'error': self.error}


class HarnessClient:
    """An LLMClient: the harness LMP gets the queued test program, every other LMP the model (recorded)."""

    def __init__(self, model: LLMClient) -> None:
        self.model = model
        self.program: str | None = None
        self.calls: list[ModelCall] = []
        self._lock = threading.Lock()

    def complete(self, request: CompletionRequest) -> Completion:
        if request.lmp == HARNESS_LMP:
            if self.program is None:
                raise LLMError('no test program is queued')
            return Completion(text=self.program, source='harness')
        started = time.monotonic()
        try:
            completion = self.model.complete(request)
        except Exception as error:
            self._record(ModelCall(request.lmp, request.query, request.prompt, '', 0, 0,
                                   time.monotonic() - started, f'{type(error).__name__}: {error}'))
            raise
        self._record(ModelCall(request.lmp, request.query, request.prompt, completion.text,
                               completion.prompt_tokens, completion.completion_tokens,
                               completion.latency_s or time.monotonic() - started))
        return completion

    def _record(self, call: ModelCall) -> None:
        with self._lock:
            self.calls.append(call)

    def take_calls(self) -> list[ModelCall]:
        with self._lock:
            calls, self.calls = self.calls, []
        return calls


class EvaluationSession:
    """A sandbox process with an engine built by `build_engine` (a module-level function, see IsolatedEngine),
    the `api` functions plus `report`, and the model behind HarnessClient."""

    def __init__(self, build_engine: Callable[..., Any], model: LLMClient, *,
                 api: Mapping[str, Callable[..., Any]] | None = None, limits: SandboxLimits | None = None,
                 engine_options: Mapping[str, Any] | None = None, model_time_limit_s: float = 600.0,
                 jail: str = 'required') -> None:
        self.client = HarnessClient(model)
        self.reports: list[Any] = []
        self._testing = False  # a test program is running: report() takes values
        self._reported = 0
        functions = {**(api or {}), REPORT_API: self._report}
        self.engine = IsolatedEngine(build_engine, functions, self.client, limits, engine_options=engine_options,
                                     model_time_limit_s=model_time_limit_s, jail=jail)

    def _report(self, value: Any = None) -> None:
        if not self._testing:
            raise ValueError('report() belongs to the test program')
        if len(self.reports) >= MAX_REPORTS:
            raise ValueError(f'more than {MAX_REPORTS} reports')
        self._reported += reported_items(value, MAX_REPORTED_ITEMS)
        if self._reported > MAX_REPORTED_ITEMS:
            raise ValueError(f'the reports hold more than {MAX_REPORTED_ITEMS:,} items')
        self.reports.append(value)

    def reset(self) -> None:
        """A new session: no variables or generated functions of the item before."""
        self.engine.reset()
        self.reports.clear()
        self.client.take_calls()

    def ask(self, query: str, lmp: str | None = None, context: str | None = None) -> CommandResult:
        """Ask the model (through `lmp`'s prompt, with `context` as the context line) and run its code, as a
        command is run."""
        return self.engine.run(query, lmp, context)

    def run_program(self, program: str) -> tuple[CommandResult, list[Any]]:
        """Run a trusted test program in the session; its result and what it reported."""
        self.reports.clear()
        self._reported = 0
        self.client.program = program
        self._testing = True
        try:
            result = self.engine.run('run the test program', HARNESS_LMP)
        finally:
            self._testing = False
            self.client.program = None
        return result, list(self.reports)

    @property
    def testing(self) -> bool:
        """Whether a test program is running (API functions of the harness accept calls only then)."""
        return self._testing

    def close(self) -> None:
        self.engine.close()

    def __enter__(self) -> 'EvaluationSession':
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


def harness_lmp() -> LMPConfig:
    """The LMP test programs run as: no prompt (HarnessClient answers it), no session of its own (a test program
    sees the names the model's code defined but leaves nothing behind), and no function generation (a test never
    asks the model for anything)."""
    return LMPConfig(HARNESS_LMP, '', stop=(), maintain_session=False, generate_functions=False)
