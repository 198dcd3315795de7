"""How a command ended, as one typed value a front end can act on without reading messages.

`outcome_of(error)` names the outcome of a command that failed with `error`; the engines set it on every
CommandResult, so the ROS node, the CLI and the benchmark all classify a failure the same way.
"""
from __future__ import annotations

import enum

from cap_lmp.errors import (CodeRejected, ExecutionStopped, GenerationError, LLMError, NotApproved, SandboxProcessLost,
                            StoppedError)


class Outcome(str, enum.Enum):
    """DONE: the program ran to its end. REFUSED: the code was refused before it ran, by the checks or by the
    person who was asked to approve it (nothing moved), or its approved run was stopped at a step the approval did
    not cover (what was approved before it ran).
    CANCELLED: a stop or cancel ended it. MODEL_ERROR: the model gave no usable code (an endpoint failure, wrong
    function generated, the model deadline). ERROR: anything else (the program raised, a limit stopped it)."""

    DONE = 'done'
    ERROR = 'error'
    CANCELLED = 'cancelled'
    REFUSED = 'refused'
    MODEL_ERROR = 'model_error'


def outcome_of(error: BaseException) -> Outcome:
    """The outcome of a command that ended with `error` (raised by the engine, the sandbox or the robot API)."""
    if isinstance(error, (CodeRejected, SyntaxError, NotApproved)):
        return Outcome.REFUSED
    if isinstance(error, StoppedError):
        return Outcome.CANCELLED
    if isinstance(error, (ExecutionStopped, SandboxProcessLost)):
        if error.reason == 'cancelled':
            return Outcome.CANCELLED
        if error.reason == 'unapproved':  # the approved run reached a step its approval did not cover
            return Outcome.REFUSED
        return Outcome.MODEL_ERROR if error.reason == 'model_timeout' else Outcome.ERROR
    if isinstance(error, (LLMError, GenerationError)):
        return Outcome.MODEL_ERROR
    return Outcome.ERROR


__all__ = ['Outcome', 'outcome_of']
