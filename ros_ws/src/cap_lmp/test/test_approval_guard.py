"""The node's side of approval (cap_lmp.approval.ApprovalGuard, guarded_functions, GuardedClient): before approval
no acting call goes through, after it exactly the approved calls in their order, no model request, and a violation
is final for the command. Plain Python: the robot functions here only count their calls."""
from __future__ import annotations

import numpy as np
import pytest

from cap_lmp.approval import (FUNCTION, MATCH_TOLERANCE, ApprovalGuard, GuardedClient, PlannedCall, guarded_functions,
                              same_value, session_copy)
from cap_lmp.errors import NotApproved, UnapprovedAction
from cap_lmp.llm import Completion, CompletionRequest
from cap_lmp.wire import CallableHandle

ACTING = ('put_first_on_second', 'say', 'run_controller')


class Robot:
    def __init__(self) -> None:
        self.calls: list[tuple] = []

    def functions(self) -> dict:
        def act(name):
            return lambda *args, **kwargs: self.calls.append((name, args, kwargs))
        return {'put_first_on_second': act('put_first_on_second'), 'say': act('say'),
                'run_controller': act('run_controller'), 'get_obj_pos': lambda name: np.array([0.1, -0.5])}


@pytest.fixture
def rig():
    guard, robot, refusals = ApprovalGuard(ACTING), Robot(), []
    api = guarded_functions(robot.functions(), guard, lambda: refusals.append(guard.violation))
    return guard, robot, api, refusals


def test_without_approval_required_every_call_goes_through(rig):
    guard, robot, api, refusals = rig
    guard.begin(False)
    api['put_first_on_second']('red block', 'red bowl')
    assert robot.calls == [('put_first_on_second', ('red block', 'red bowl'), {})] and refusals == []


def test_no_acting_call_before_approval_and_a_violation_is_final(rig):
    guard, robot, api, refusals = rig
    guard.begin(True)
    assert np.allclose(api['get_obj_pos']('red block'), [0.1, -0.5])  # reading the world is never held back
    with pytest.raises(UnapprovedAction, match=r"called put_first_on_second\('blue block', 'blue bowl'\) before "
                                               r'it was approved'):
        api['put_first_on_second']('blue block', 'blue bowl')
    assert robot.calls == [] and len(refusals) == 1
    with pytest.raises(NotApproved, match='before it was approved'):
        guard.approve([PlannedCall('say', ('hi',))])  # a program that acted first is not run on
    with pytest.raises(UnapprovedAction):
        api['say']('hi')
    assert robot.calls == []
    guard.begin(True)  # the next command starts clean
    assert guard.violation == ''


def test_after_approval_exactly_the_planned_calls_in_their_order(rig):
    guard, robot, api, refusals = rig
    guard.begin(True)
    guard.approve([PlannedCall('put_first_on_second', ('red block', [0.0, -0.5])),
                   PlannedCall('say', ('done',))])
    # The real run reads perception again: numbers within the tolerance are the planned ones.
    api['put_first_on_second']('red block', np.array([0.0 + MATCH_TOLERANCE / 2, -0.5]))
    with pytest.raises(UnapprovedAction, match=r"called say\('finished'\) where the approved plan's action 2 is "
                                               r"say\('done'\)"):
        api['say']('finished')
    with pytest.raises(UnapprovedAction):
        api['say']('done')  # too late: the program is being stopped
    assert [call[0] for call in robot.calls] == ['put_first_on_second'] and len(set(refusals)) == 1


def test_a_command_is_approved_once(rig):
    guard, robot, api, _ = rig
    guard.begin(True)
    guard.may_ask()
    guard.approve([PlannedCall('say', ('hi',))])
    with pytest.raises(NotApproved, match='asked for approval a second time'):
        guard.may_ask()  # a second plan would be shown but not held: nobody is asked
    with pytest.raises(UnapprovedAction):
        api['say']('hi')
    assert robot.calls == []


def test_a_call_beyond_the_plan_or_elsewhere_is_refused(rig):
    guard, robot, api, _ = rig
    guard.begin(True)
    guard.approve([PlannedCall('put_first_on_second', ('red block', 'red bowl'))])
    api['put_first_on_second']('red block', 'red bowl')
    with pytest.raises(UnapprovedAction, match=r'after the 1 action\(s\) of the approved plan'):
        api['put_first_on_second']('blue block', 'blue bowl')
    guard.begin(True)
    guard.approve([PlannedCall('put_first_on_second', ('red block', [0.0, -0.5]))])
    with pytest.raises(UnapprovedAction):
        api['put_first_on_second']('red block', [0.0, -0.5 + 3 * MATCH_TOLERANCE])
    guard.begin(True)
    guard.approve([PlannedCall('put_first_on_second', ('red block', 'red bowl'))])
    with pytest.raises(UnapprovedAction):  # the same values, passed another way
        api['put_first_on_second']('red block', target='red bowl')
    assert len(robot.calls) == 1


def test_a_function_of_the_program_matches_its_planned_token(rig):
    guard, robot, api, _ = rig
    guard.begin(True)
    guard.approve([PlannedCall('run_controller', (FUNCTION, 5.0))])
    api['run_controller'](CallableHandle(3, 'balance'), 5.0)  # as the node receives it from the sandbox process
    assert len(robot.calls) == 1


def test_no_model_request_once_the_program_runs_approved():
    guard, asked, refusals = ApprovalGuard(ACTING), [], []

    class Client:
        model = 'scripted'

        def complete(self, request):
            asked.append(request.query)
            return Completion(text='ret_val = 1')

    client = GuardedClient(Client(), guard, lambda: refusals.append(True))
    request = CompletionRequest(lmp='parse_obj_name', prompt='p', query='the blocks')
    guard.begin(True)
    client.complete(request)  # while planning, nested LMPs are asked as usual
    guard.approve([])
    with pytest.raises(UnapprovedAction, match="asked the model for new code \\(parse_obj_name: 'the blocks'\\)"):
        client.complete(request)
    assert asked == ['the blocks'] and refusals == [True] and client.model == 'scripted'


def test_values_compare_by_kind_and_numbers_within_the_tolerance():
    assert same_value([1, 'a', None, True, {'x': 0.5}], [1.001, 'a', None, True, {'x': 0.5}])
    for planned, actual in ((True, 1), (None, 0), ('1', 1), ([1], [1, 2]), ({'x': 1}, {'y': 1}), (1, 1.1)):
        assert not same_value(planned, actual)


def test_the_session_copy_for_a_plan_shares_nothing_a_program_can_change():
    scope: dict = {'np': np, 'marks': [1], '__builtins__': {}, 'limit': np.array([1.0])}
    exec('def add(x):\n    marks.append(x)\n    return len(marks)', scope)
    robot = scope['say'] = lambda text: None
    copied = session_copy(scope, shared=[robot])
    assert copied['add'](2) == 2 and scope['marks'] == [1]  # the copied function works on the copy
    copied['limit'][0] = 5.0
    assert scope['limit'][0] == 1.0 and copied['np'] is np and copied['say'] is robot
    scope['numbers'] = (n for n in range(3))
    with pytest.raises(Exception, match='variable numbers .* cannot be copied'):
        session_copy(scope)
