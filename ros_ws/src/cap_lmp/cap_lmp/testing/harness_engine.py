"""An engine builder with the options benchmark harnesses use, for the engines' own tests: a session-keeping LMP
with function generation, an LMP whose answer continues its query, and a test LMP that generates nothing."""
from __future__ import annotations

from typing import Any, Callable, Mapping

from cap_lmp.engine import Engine, LMPConfig
from cap_lmp.llm import LLMClient
from cap_lmp.sandbox import SandboxLimits


def upper_names(source: str) -> str:
    """A harness rule for the tests: the word `UPPER` in a program stands for a provided function."""
    return source.replace('UPPER', 'shout')


def build_engine(api: Mapping[str, Callable[..., Any]], client: LLMClient, limits: SandboxLimits | None = None,
                 **engine_options: Any) -> Engine:
    lmps = [LMPConfig('main', '', maintain_session=True, stop=('\n#',)),
            LMPConfig('fgen', '', stop=('\n#',)),
            LMPConfig('continue', '', query_prefix='', query_suffix='', stop=('\ndef ',), maintain_session=True,
                      answer_continues_query=True, prepare_source=upper_names),
            LMPConfig('test', '', generate_functions=False),
            LMPConfig('answer', '', context_var='objects', maintain_session=True)]
    return Engine(lmps, client, dict(api), limits=limits, default_lmp='main', **engine_options)
