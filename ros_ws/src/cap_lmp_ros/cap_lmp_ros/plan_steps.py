"""A program's plan in the words and places a person (the console, RViz) shows: one PlanStep per recorded call.

The plan-only run (cap_lmp.approval) records calls of the robot API's acting functions with plain arguments; the
domain says what each means (Domain.describe_call): which object moves where. Plain Python, no rclpy.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from cap_lmp.approval import PlannedCall

_SHOWN_CHARS = 300  # of one step's description


@dataclass(frozen=True)
class PlanStep:
    """One step of a plan: the function, the object it moves, its target (a named object or points) in words."""

    function: str
    description: str
    object_name: str = ''
    target_name: str = ''
    points: tuple[tuple[float, float, float], ...] = field(default_factory=tuple)


def call_text(call: PlannedCall) -> str:
    """The call as code, bounded: `ring_bell(3)`."""
    arguments = [repr(arg) for arg in call.args] + [f'{key}={value!r}' for key, value in call.kwargs.items()]
    text = f'{call.function}({", ".join(arguments)})'
    return text if len(text) <= _SHOWN_CHARS else text[:_SHOWN_CHARS - 3] + '...'


def describe_as_call(call: PlannedCall) -> PlanStep:
    """The step of a domain that says nothing more about its calls: the call itself."""
    return PlanStep(call.function, call_text(call))


def point_of(value: object) -> tuple[float, float, float] | None:
    """An [x, y] or [x, y, z] list of numbers as a point (z 0 when not given), else None."""
    if not isinstance(value, list) or len(value) not in (2, 3):
        return None
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        return None
    x, y, *z = (float(v) for v in value)
    return (x, y, z[0] if z else 0.0)


def plan_summary(steps: list[PlanStep]) -> str:
    """The plan on one line: '1. put the red block on the red bowl; 2. say "done"', or that it does nothing."""
    if not steps:
        return 'the plan-only run found no robot action'
    return '; '.join(f'{number}. {step.description}' for number, step in enumerate(steps, 1))


__all__ = ['PlanStep', 'call_text', 'describe_as_call', 'plan_summary', 'point_of']
