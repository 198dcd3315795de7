"""Who answers the prompts: the oracle (reference answers over a real HTTP server on loopback) or a model at an
OpenAI-compatible endpoint. Every report names it."""
from __future__ import annotations

import contextlib
from dataclasses import dataclass
from typing import Iterator, Sequence

from cap_lmp.llm import LLMClient, OpenAICompatibleClient
from cap_lmp.testing.openai_server import RecordedRequest, ScriptedOpenAIServer

ORACLE_MODEL = 'reference-answers'


@dataclass(frozen=True)
class PolicyOptions:
    policy: str = 'oracle'  # 'oracle' or 'llm'
    base_url: str = ''  # llm: empty means CAP_LLM_BASE_URL
    model: str = ''  # llm: empty means CAP_LLM_MODEL
    api: str = 'completions'  # 'completions' or 'chat'
    timeout_s: float = 120.0  # per HTTP attempt
    # chat API: 'project' sends the project's system prompt (cap_lmp.llm); 'model' sends none, so the model's chat
    # template puts in its own default, as the model's makers evaluate it
    chat_system: str = 'project'

    def describe(self, client: LLMClient | None = None) -> str:
        """A line for reports: which answers these are."""
        if self.policy == 'oracle':
            return 'oracle (reference answers served by a local OpenAI-protocol server)'
        model = getattr(client, 'model', None) or self.model or '(CAP_LLM_MODEL)'
        url = getattr(client, 'base_url', None) or self.base_url or '(CAP_LLM_BASE_URL)'
        system = ", the model's own system prompt" if self.api == 'chat' and self.chat_system == 'model' else ''
        return f'model {model} at {url}, {self.api} API{system}'


class SuffixOracle:
    """Answers a request with the answer whose marker the prompt ends with (the longest such marker wins)."""

    def __init__(self, answers: Sequence[tuple[str, str]]) -> None:
        self.answers = sorted(answers, key=lambda pair: len(pair[0]), reverse=True)

    def __call__(self, request: RecordedRequest) -> str | None:
        prompt = request.prompt
        for marker, answer in self.answers:
            if prompt.endswith(marker) or prompt.rstrip('\n').endswith(marker.rstrip('\n')):
                return answer
        return None


@contextlib.contextmanager
def open_client(options: PolicyOptions, oracle_answers: Sequence[tuple[str, str]] = ()) -> Iterator[LLMClient]:
    """The client of a run. For the oracle, a ScriptedOpenAIServer on 127.0.0.1 serves `oracle_answers`
    ((prompt suffix, answer) pairs) for as long as the run lasts, so the oracle takes the same path as a model."""
    if options.policy == 'oracle':
        with ScriptedOpenAIServer(responder=SuffixOracle(oracle_answers), model=ORACLE_MODEL,
                                  fence_chat=False) as server:
            yield OpenAICompatibleClient(server.base_url, ORACLE_MODEL, api=options.api, max_retries=0)
        return
    if options.policy != 'llm':
        raise ValueError(f"policy must be 'oracle' or 'llm', not {options.policy!r}")
    overrides: dict[str, object] = {'api': options.api, 'timeout_s': options.timeout_s}
    if options.chat_system == 'model':
        overrides['system_prompt'] = ''
    if options.base_url:
        overrides['base_url'] = options.base_url
    if options.model:
        overrides['model'] = options.model
    yield OpenAICompatibleClient.from_env(**overrides)
