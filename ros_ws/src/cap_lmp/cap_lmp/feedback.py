"""Execution feedback: what the model is told when a command's program failed while running, so that its next
program finishes the command from the world as it is now instead of starting again.

The engine (Engine._execute_with_feedback) decides when; this module says what: which failures are worth a new
program, what the model reads (its failed program, the error and its line, the robot actions that completed, the
scene now) and how the completed actions are recorded. Plain Python: no model, no robot.
"""
from __future__ import annotations

import reprlib
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from cap_lmp.errors import CapLLMError, GenerationError, RobotApiError, StoppedError

MAX_ERROR_CHARS = 300  # of the error's message in the feedback
MAX_ACTION_CHARS = 160  # of one completed action's description
MAX_ACTIONS = 20  # the last ones, when a program did more before it failed

_short = reprlib.Repr()
_short.maxstring, _short.maxlist, _short.maxtuple, _short.maxother = 40, 6, 6, 40


def worth_feedback(error: BaseException) -> bool:
    """A failure another program may get past: a robot call's error (an object that is not there, a target out of
    reach) or a Python error of the program. Not a stop (the person's, a limit's), a refusal of the sandbox, an
    approval's end, the model's own failure or running out of memory: those end the command."""
    if isinstance(error, StoppedError):
        return False
    if isinstance(error, (RobotApiError, GenerationError)):
        return True
    if isinstance(error, (CapLLMError, MemoryError, RecursionError)):
        return False
    return isinstance(error, Exception)


def describe_value(value: Any) -> str:
    """A value as the model reads it in code: short, positions rounded to the millimetre."""
    try:
        if isinstance(value, np.ndarray) and value.size <= 6 and value.dtype.kind in 'fiu':
            return repr([round(float(v), 3) for v in value.ravel()])
        if isinstance(value, float):
            return repr(round(value, 3))
        return _short.repr(value)
    except Exception:  # a program's object whose repr fails: named by its type
        return f'<{type(value).__name__}>'


def describe_call(name: str, args: Sequence[Any], kwargs: Mapping[str, Any]) -> str:
    parts = [describe_value(value) for value in args]
    parts += [f'{key}={describe_value(value)}' for key, value in kwargs.items()]
    text = f"{name}({', '.join(parts)})"
    return text if len(text) <= MAX_ACTION_CHARS else text[:MAX_ACTION_CHARS - 4] + '...)'


def action_recorders(functions: Mapping[str, Callable[..., Any]], names: Sequence[str],
                     done: list[str]) -> dict[str, Callable[..., Any]]:
    """The robot functions `names` (those that act on the world), each appending its call to `done` once it returned:
    what the program had completed when it failed."""
    def recorder(name: str, function: Callable[..., Any]) -> Callable[..., Any]:
        def act(*args: Any, **kwargs: Any) -> Any:
            value = function(*args, **kwargs)
            done.append(describe_call(name, args, kwargs))
            return value
        act.__name__ = name
        act.__doc__ = function.__doc__
        return act
    return {name: recorder(name, functions[name]) for name in names if name in functions}


def failure_lines(error: BaseException, line: int | None, source_line: str | None, done: Sequence[str]) -> list[str]:
    """Comment lines for the model: where and why the program stopped, and what it had done by then."""
    try:
        message = str(error)
    except Exception:  # an exception whose text cannot be built
        message = ''
    message = ' '.join(message.split())[:MAX_ERROR_CHARS]
    where = f'at line {line} (`{source_line}`)' if line is not None and source_line else 'while it ran'
    lines = [f'# the program above stopped {where}: {type(error).__name__}: {message}'.rstrip(': ')]
    if done:
        shown = list(done[-MAX_ACTIONS:])
        more = f' (and {len(done) - len(shown)} earlier)' if len(done) > len(shown) else ''
        lines.append(f"# done before it stopped{more}: {'; '.join(shown)}")
    else:
        lines.append('# nothing was done before it stopped')
    return lines


def feedback_block(query_prefix: str, query_suffix: str, context: str, command: str, code: str,
                   what: Sequence[str]) -> str:
    """The failed attempt as the model sees it before the new query: the scene then, the command, the program and
    what happened."""
    parts = [context, f'{query_prefix}{command}{query_suffix}', code.rstrip(), *what]
    return '\n'.join(part for part in parts if part)


def continue_query(command: str) -> str:
    """The query of a feedback round: the command, to be finished from where the last program stopped."""
    return f'{command.rstrip(" .")}, finishing what the program above did not do'


__all__ = ['action_recorders', 'continue_query', 'describe_call', 'describe_value', 'failure_lines',
           'feedback_block', 'worth_feedback']
