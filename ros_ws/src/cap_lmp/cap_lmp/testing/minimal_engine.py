"""The smallest engine builder there is, for tests of the engines themselves: one LMP, no prompt, the API given.
A module-level function, so IsolatedEngine can build it in the sandbox process."""
from __future__ import annotations

from typing import Any, Callable, Mapping

from cap_lmp.engine import Engine, LMPConfig
from cap_lmp.llm import LLMClient
from cap_lmp.sandbox import SandboxLimits


def build_engine(api: Mapping[str, Callable[..., Any]], client: LLMClient, limits: SandboxLimits | None = None,
                 **engine_options: Any) -> Engine:
    """An Engine with one LMP, 'main', over `api`, without function generation."""
    return Engine([LMPConfig('main', '')], client, dict(api), limits=limits, fgen_lmp=None, **engine_options)
