"""lmp_node's require_approval over DDS: the code and its plan on /cap/status, nothing done before /cap/approve says
yes, and a rejection, no answer in time or a stop reported as outcomes like any other."""
from __future__ import annotations

import pytest
import yaml
from rclpy.parameter import Parameter
from std_msgs.msg import Empty

from cap_interfaces.action import ExecuteCommand
from cap_interfaces.msg import GraphNames, StatusEvent
from cap_interfaces.srv import ApproveCommand
from cap_lmp.cassette import FORMAT as CASSETTE_FORMAT
from cap_lmp_ros.testing.lmp_graph import LmpGraph, wait_for

PROGRAMS = {'greet': "say('hello ' + get_obj_names()[0])", 'wave': "say('bye')"}


@pytest.fixture
def graph(ros_context, tmp_path):
    cassette = tmp_path / 'cassette.yaml'
    cassette.write_text(yaml.safe_dump({'format': CASSETTE_FORMAT, 'entries': [
        {'lmp': 'tabletop_ui', 'query': query, 'context': '*', 'completion': code, 'source': 'written for this test'}
        for query, code in PROGRAMS.items()]}))
    graph = LmpGraph(ros_context, tmp_path, [Parameter('cassette', value=str(cassette)),
                                             Parameter('require_approval', value=True)])
    graph.approve = graph.user.create_client(ApproveCommand, GraphNames.APPROVE_SERVICE)
    assert wait_for(graph.approve.service_is_ready)
    yield graph
    graph.close()


def _awaiting(graph) -> StatusEvent | None:
    return next((s for s in reversed(list(graph.statuses)) if s.stage == StatusEvent.STAGE_AWAITING_APPROVAL), None)


def _answer(graph, command_id: str, approve: bool, reason: str = '') -> ApproveCommand.Response:
    future = graph.approve.call_async(ApproveCommand.Request(command_id=command_id, approve=approve, reason=reason))
    assert wait_for(future.done)
    return future.result()


def _send(graph, command: str) -> dict:
    box: dict = {}
    graph.execute.send_goal_async(ExecuteCommand.Goal(command=command)).add_done_callback(
        lambda f: f.result().get_result_async().add_done_callback(lambda r: box.update(result=r.result().result)))
    return box


def test_a_program_waits_with_its_code_and_plan_until_approved(graph):
    box = _send(graph, 'greet')
    assert wait_for(lambda: _awaiting(graph))
    waiting = _awaiting(graph)
    assert waiting.code == "say('hello ' + get_obj_names()[0])"
    assert [(step.function, step.description) for step in waiting.plan] == [('say', "say 'hello blue block'")]
    assert 'waiting for approval on /cap/approve' in waiting.message and graph.said == []  # planned, not said

    wrong = _answer(graph, 'cmd-999', True)
    assert not wrong.success and f'{waiting.command_id} waits' in wrong.message
    assert _answer(graph, waiting.command_id, True).success
    assert wait_for(lambda: 'result' in box)
    assert box['result'].outcome == ExecuteCommand.Result.OUTCOME_DONE and graph.said == ['hello blue block']
    assert not _answer(graph, waiting.command_id, True).success  # it no longer waits


def test_a_rejected_or_unanswered_program_is_refused_and_a_stop_cancels_one(graph):
    box = _send(graph, 'greet')
    assert wait_for(lambda: _awaiting(graph))
    assert _answer(graph, _awaiting(graph).command_id, False, 'not now').success
    assert wait_for(lambda: 'result' in box)
    assert box['result'].outcome == ExecuteCommand.Result.OUTCOME_REFUSED
    assert box['result'].message.startswith('rejected: not now; nothing ran') and graph.said == []

    assert graph.set_parameter('approval_timeout_s', 0.5).successful
    late = _send(graph, 'greet')
    assert wait_for(lambda: 'result' in late)
    assert late['result'].outcome == ExecuteCommand.Result.OUTCOME_REFUSED
    assert 'not approved within 0.5 s (approval_timeout_s), so nothing ran' in late['result'].message

    assert graph.set_parameter('approval_timeout_s', 60.0).successful
    stopped = _send(graph, 'wave')
    assert wait_for(lambda: _awaiting(graph) and _awaiting(graph).command == 'wave')
    graph.stop.publish(Empty())
    assert wait_for(lambda: 'result' in stopped)
    assert stopped['result'].outcome == ExecuteCommand.Result.OUTCOME_CANCELLED

    assert not graph.set_parameter('require_approval', 1.0).successful  # true or false only
    assert graph.set_parameter('require_approval', False).successful
    free = _send(graph, 'greet')
    assert wait_for(lambda: 'result' in free)
    assert free['result'].outcome == ExecuteCommand.Result.OUTCOME_DONE
