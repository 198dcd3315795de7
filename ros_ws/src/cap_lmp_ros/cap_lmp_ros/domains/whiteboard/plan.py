"""The whiteboard's plan steps: what a recorded draw or erase means, in words and points (for approval)."""
from __future__ import annotations

from cap_lmp.approval import PlannedCall
from cap_lmp_ros.plan_steps import PlanStep, describe_as_call, point_of

MAX_SHOWN_POINTS = 200  # of one stroke, on the console and in RViz


def describe_call(call: PlannedCall) -> PlanStep:
    """draw(pts) / erase(pts): the stroke's points and its extent; say(text): the text."""
    if call.function in ('draw', 'erase') and call.args and isinstance(call.args[0], list):
        points = [p for p in (point_of(value) for value in call.args[0][:MAX_SHOWN_POINTS]) if p is not None]
        if points:
            xs, ys = [p[0] for p in points], [p[1] for p in points]
            verb = 'draw' if call.function == 'draw' else 'erase'
            return PlanStep(call.function, f'{verb} a stroke of {len(call.args[0])} points over x '
                            f'{min(xs):.3f}..{max(xs):.3f}, y {min(ys):.3f}..{max(ys):.3f}', points=tuple(points))
    if call.function == 'say' and call.args:
        return PlanStep('say', f'say {str(call.args[0])[:200]!r}')
    return describe_as_call(call)
