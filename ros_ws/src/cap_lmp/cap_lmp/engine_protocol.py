"""What a front end needs of an engine: Engine (in this process) and IsolatedEngine (in a sandbox process) both
provide it, so the ROS node (lmp_node) can take either."""
from __future__ import annotations

from typing import Callable, Protocol, runtime_checkable

from cap_lmp.approval import ApprovalGate
from cap_lmp.engine import CommandResult, EngineEvent


@runtime_checkable
class CommandEngine(Protocol):
    """Runs one command at a time in a session; `cancel` may be called from any thread."""

    default_lmp: str  # the LMP a command goes to; events of other LMPs are nested calls
    approval: ApprovalGate | None  # set: each program is planned and runs only once this gate returns (approval.py)

    def run(self, command: str) -> CommandResult:
        """Run one command end to end; never raises for problems of the generated code."""
        ...

    def cancel(self) -> None:
        """Stop the running command soon (thread-safe; no effect when idle)."""
        ...

    def reset(self) -> None:
        """Start a new session: earlier variables and generated functions are forgotten."""
        ...

    def add_listener(self, listener: Callable[[EngineEvent], None]) -> None:
        """Receive an EngineEvent for every stage of every command."""
        ...

    def close(self) -> None:
        """Release what the engine holds (a sandbox process); later commands fail."""
        ...


__all__ = ['CommandEngine']
