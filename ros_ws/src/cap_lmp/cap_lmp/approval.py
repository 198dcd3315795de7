"""Approval before a program runs: a plan-only run of it, then a gate a person answers.

With an approval gate set (`Engine.approval`), a command's checked code is first run in plan-only mode, in the same
sandbox with the same limits, over a copy of the session's scope in which each of the engine's `plan_functions`
(the robot API functions that move the robot or speak) records its call instead of making it. Everything else runs
as usual: the program reads the world as it is now (perception), and nested LMPs are asked as usual, their answers
kept for the command, so that the run after approval executes the code that was planned. The gate is then called
with the code and the recorded calls; it returns once a person approved, and raises NotApproved (rejected, not
approved in time) or ExecutionStopped (cancelled) otherwise. Only then does the program run for real.

A plan is no simulation: a recorded motion moves nothing, so a program whose later steps read where an earlier step
put something plans them from the world as it was.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable

import numpy as np

from cap_lmp.errors import RobotApiError

MAX_PLANNED_CALLS = 200  # a program that would make more motions than this is not planned (nor run)
_MAX_ITEMS = 100  # of one list in a recorded argument
_MAX_TEXT = 500  # characters of one recorded text
_MAX_DEPTH = 3


@dataclass(frozen=True)
class PlannedCall:
    """One call a program would make of a function that acts (moves the robot, speaks), with plain arguments."""

    function: str
    args: tuple[Any, ...] = ()
    kwargs: dict[str, Any] = field(default_factory=dict)

    def to_wire(self) -> dict[str, Any]:
        return {'function': self.function, 'args': list(self.args), 'kwargs': dict(self.kwargs)}


# gate(code, plan): returns when the code may run; raises NotApproved or ExecutionStopped when it must not.
ApprovalGate = Callable[[str, list[PlannedCall]], None]


def plain(value: Any, depth: int = 0) -> Any:
    """`value` as small JSON-like data for a plan (numbers, text, lists, dicts); anything else as bounded text.

    A plan travels to the node and on to people: arrays become lists of floats, texts and lists are cut short.
    """
    if value is None or isinstance(value, (bool, int)) and abs(value) < 2 ** 53:
        return value
    if isinstance(value, (float, np.floating)):
        number = float(value)
        return number if math.isfinite(number) else str(number)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, str):
        return value[:_MAX_TEXT]
    if depth < _MAX_DEPTH and isinstance(value, np.ndarray) and value.dtype.kind in 'biuf':
        return [plain(item, depth + 1) for item in value.reshape(-1)[:_MAX_ITEMS].tolist()] if value.ndim <= 1 \
            else [plain(row, depth + 1) for row in value[:_MAX_ITEMS]]
    if depth < _MAX_DEPTH and isinstance(value, (list, tuple)):
        return [plain(item, depth + 1) for item in value[:_MAX_ITEMS]]
    if depth < _MAX_DEPTH and isinstance(value, dict):
        return {str(key)[:_MAX_TEXT]: plain(item, depth + 1) for key, item in list(value.items())[:_MAX_ITEMS]}
    return f'<{type(value).__name__}>'


def recorders(names: Iterable[str], plan: list[PlannedCall]) -> dict[str, Callable[..., None]]:
    """Stand-ins for the functions `names` that append each call to `plan` (plain arguments) and return None."""

    def recorder(name: str) -> Callable[..., None]:
        def record(*args: Any, **kwargs: Any) -> None:
            if len(plan) >= MAX_PLANNED_CALLS:
                raise RobotApiError(f'the program would make more than {MAX_PLANNED_CALLS} robot actions; it was '
                                    'not run')
            plan.append(PlannedCall(name, tuple(plain(arg) for arg in args),
                                    {str(key): plain(item) for key, item in kwargs.items()}))
        record.__name__ = name
        return record

    return {name: recorder(name) for name in names}


def planned_call(values: Any) -> PlannedCall:
    """A PlannedCall from its wire form (a dict from the sandbox process), every field checked (ValueError)."""
    if not isinstance(values, dict):
        raise ValueError('a planned call is not an object')
    function, args, kwargs = values.get('function'), values.get('args', []), values.get('kwargs', {})
    if not isinstance(function, str) or not function.isidentifier() or len(function) > 100:
        raise ValueError('a planned call names no function')
    if not isinstance(args, list) or not isinstance(kwargs, dict) or len(args) > 20 or len(kwargs) > 20:
        raise ValueError('malformed arguments of a planned call')
    return PlannedCall(function, tuple(plain(arg) for arg in args),
                       {str(key)[:100]: plain(item) for key, item in kwargs.items()})


__all__ = ['MAX_PLANNED_CALLS', 'ApprovalGate', 'PlannedCall', 'plain', 'planned_call', 'recorders']
