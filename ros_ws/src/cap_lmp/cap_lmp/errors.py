"""Exceptions of the LMP engine. Every message is written for the person who sent the command."""
from __future__ import annotations


class CapLLMError(Exception):
    """Base of every error the engine reports."""


class SandboxError(CapLLMError):
    """Generated code was refused or stopped by the sandbox: its message says what and why."""


class CodeRejected(SandboxError):
    """The code failed the checks before it ran (syntax, imports, dunder access, forbidden names...)."""

    def __init__(self, message: str, line: int | None = None, source_line: str | None = None) -> None:
        super().__init__(message)
        self.line = line
        self.source_line = source_line


class UndefinedName(CodeRejected):
    """The code reads a name that nothing defines (a NameError found before it ran, so nothing ran)."""

    def __init__(self, name: str, line: int, source_line: str | None, origin: str) -> None:
        where = f' (line {line} of {origin}: `{source_line}`)' if source_line else ''
        super().__init__(f'NameError: name {name!r} is not defined{where}; found before the code ran, so nothing '
                         'ran', line, source_line)
        self.name = name


class ExecutionStopped(SandboxError):
    """The running program was stopped: time limit, cancellation, memory or recursion limit, model deadline.

    `reason` is one of 'timeout', 'cancelled', 'memory', 'recursion', 'unapproved' (the approved run reached a step
    its approval did not cover), 'model_timeout' (the command's model requests took their overall deadline,
    Engine's `model_time_limit_s`).
    """

    def __init__(self, message: str, reason: str) -> None:
        super().__init__(message)
        self.reason = reason


class ResourceLimitError(SandboxError):
    """An operation would have built a value larger than the sandbox allows (raised before the work is done)."""


class OperationRefused(SandboxError):
    """An operation the sandbox does not allow at run time (e.g. a format field that looks up an attribute)."""


class NotApproved(CapLLMError):
    """The generated code was not approved to run: a person rejected it, or nobody approved it in time (see
    approval.py). Nothing of it ran; `reason` is 'rejected' or 'timeout'."""

    def __init__(self, message: str, reason: str) -> None:
        super().__init__(message)
        self.reason = reason


class GenerationError(CapLLMError):
    """Code generation failed: the model defined the wrong function, a depth or cycle limit was hit, ..."""


class UnusableAnswer(GenerationError):
    """The model's answer cannot be used as it is (e.g. asked for a function, it defined another one); another
    answer may do. Limits of generation (depth, count) are plain GenerationErrors: final."""


class LLMError(CapLLMError):
    """The language model endpoint could not give an answer (HTTP errors after retries, bad responses)."""


class CassetteMissError(LLMError):
    """A replay cassette has no entry for the LMP and query that were asked."""

    def __init__(self, lmp: str, query: str, path: str) -> None:
        super().__init__(f'the cassette {path} has no answer for LMP {lmp!r} and query {query!r}')
        self.lmp = lmp
        self.query = query


class RobotApiError(RuntimeError):
    """A robot API call failed: unknown object, unreachable target, a service that does not answer..."""


class StoppedError(RobotApiError):
    """The program was stopped (/cap/stop or a cancelled /cap/execute goal) while it waited for the robot."""


class UnapprovedAction(StoppedError):
    """A robot call or model request that approval does not allow (approval.ApprovalGuard): refused, and the
    program is stopped."""


class SandboxProcessLost(SandboxError):
    """The process that ran the session's programs died or was killed; the session is lost.

    `reason`: 'crashed' (the interpreter died, e.g. a C stack overflow), 'stalled' (one operation held the
    interpreter past the stall limit), 'memory' (the address-space limit was hit), 'cancelled' (a stop was not
    honoured within the grace period), 'timeout' (the program ran past its time limit plus the kill margin and did
    not stop), 'protocol' (a malformed message) or
    'closed' (the node is shutting down).
    """

    def __init__(self, message: str, reason: str) -> None:
        super().__init__(message)
        self.reason = reason
