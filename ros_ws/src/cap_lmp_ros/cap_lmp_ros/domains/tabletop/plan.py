"""The table top's plan steps: what a recorded put_first_on_second or say means, in words and places."""
from __future__ import annotations

from cap_lmp.approval import PlannedCall
from cap_lmp_ros.domains.tabletop.lmps import object_name_candidate
from cap_lmp_ros.plan_steps import PlanStep, describe_as_call, point_of


def describe_call(call: PlannedCall) -> PlanStep:
    """put_first_on_second(object, target): the object, and the target object or point; say(text): the text."""
    args = list(call.args) + [call.kwargs[key] for key in ('obj_name', 'target') if key in call.kwargs]
    if call.function == 'put_first_on_second' and len(args) >= 2:
        obj = object_name_candidate(args[0]) or str(args[0])[:100]
        target_name = object_name_candidate(args[1])
        if target_name is not None:
            return PlanStep(call.function, f'put the {obj} on the {target_name}', obj, target_name)
        point = point_of(args[1])
        if point is not None:
            return PlanStep(call.function, f'put the {obj} at ({point[0]:.3f}, {point[1]:.3f})', obj,
                            points=(point,))
    if call.function == 'say' and call.args:
        return PlanStep('say', f'say {str(call.args[0])[:200]!r}')
    return describe_as_call(call)
