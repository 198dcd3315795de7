"""Running one program in a Sandbox the way the sandbox tests do: what it says is collected, its scope returned."""
from __future__ import annotations

from cap_lmp.sandbox import Sandbox, SandboxLimits

# Tight limits, so that the escape and exhaustion attempts end quickly.
TEST_LIMITS = SandboxLimits(time_limit_s=1.0, max_memory_growth_bytes=256 << 20)


def run_program(sandbox: Sandbox, source: str, **names: object) -> dict:
    """Compile and run `source` with `say` and `names` bound; the scope afterwards, with `said` added."""
    said: list[str] = []
    scope = sandbox.new_scope({'say': lambda text: said.append(str(text)), **names})
    sandbox.execute(sandbox.compile(source), scope)
    scope['said'] = said
    return scope
