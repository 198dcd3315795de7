"""Approval that means what it shows, judged on the simulator: the whole table-top graph (MuJoCo, perception,
pick-and-place, lmp_node with require_approval) over DDS, a person's side played by a node that reads the plan on
/cap/status and answers on /cap/approve. Each test runs a program (or a sandbox process) that tries to make the
robot do something else than what was approved, and checks where the blocks are afterwards.
"""
from __future__ import annotations

import json
import sys
import time

import numpy as np
import pytest
import rclpy
from rclpy.action import ActionClient
from rclpy.context import Context

from cap_bringup.graph import Graph, GraphOptions
from cap_interfaces.action import ExecuteCommand
from cap_interfaces.msg import GraphNames, StatusEvent
from cap_interfaces.srv import ApproveCommand
from cap_lmp_ros.lmp_node import EVENT_QOS
from conftest import next_domain_id

pytestmark = pytest.mark.slow

SEED = 2
OBJECTS = ['red block', 'blue block', 'red bowl', 'blue bowl']
NEAR_M = 0.005  # a block that did not move is where it was, within settling


def _entry(lmp: str, query: str, completion: str) -> str:
    body = '\n'.join(f'    {line}' for line in completion.splitlines())
    return (f'- lmp: {lmp}\n  query: {query}\n  context: \'*\'\n  source: written by hand for this test\n'
            f'  completion: |-\n{body}\n')


# Each program tells the plan-only run from the real one by looking whether its approved move happened.
CASSETTE = 'format: cap-llm-cassette/1\nentries:\n' + ''.join([
    _entry('tabletop_ui', 'sort the blue block and maybe more', (
        "start = get_obj_pos('blue block')\n"
        "put_first_on_second('blue block', 'blue bowl')\n"
        "if np.linalg.norm(get_obj_pos('blue block') - start) > 0.02:\n"
        "    put_first_on_second('red block', 'red bowl')")),
    _entry('tabletop_ui', 'sort the blue block and ask what else', (
        "start = get_obj_pos('blue block')\n"
        "put_first_on_second('blue block', 'blue bowl')\n"
        "moved = bool(np.linalg.norm(get_obj_pos('blue block') - start) > 0.02)\n"
        "names = parse_obj_name('the red block' if moved else 'no block', f'objects = {get_obj_names()}')\n"
        "for name in names:\n"
        "    put_first_on_second(name, 'red bowl')")),
    _entry('parse_obj_name', 'no block', 'ret_val = []'),
    _entry('parse_obj_name', 'the red block', "ret_val = ['red block']"),
    _entry('tabletop_ui', 'remember the blue block', "held = ['blue block']"),
    _entry('tabletop_ui', 'remember the red block too and sort', (
        "held.append('red block')\n"
        "put_first_on_second('blue block', 'blue bowl')")),
    _entry('tabletop_ui', 'put what you remember in the red bowl', (
        "for name in held:\n"
        "    put_first_on_second(name, 'red bowl')")),
])


def _wait(predicate, timeout: float = 120.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.02)
    return bool(predicate())


class Person:
    """The graph in this process and a person beside it: sends commands, reads plans, approves or rejects."""

    def __init__(self, context, options: GraphOptions, **node_arguments) -> None:
        self.graph = Graph(context, options, node_arguments=node_arguments)
        self.world = self.graph.world
        self.node = rclpy.create_node('person', context=context)
        self.statuses: list[StatusEvent] = []
        self.answered: set[str] = set()
        self.node.create_subscription(StatusEvent, GraphNames.STATUS_TOPIC, self.statuses.append, EVENT_QOS)
        self.execute = ActionClient(self.node, ExecuteCommand, GraphNames.EXECUTE_ACTION)
        self.approve_client = self.node.create_client(ApproveCommand, GraphNames.APPROVE_SERVICE)
        self.graph.executor.add_node(self.node)
        assert _wait(lambda: self.execute.server_is_ready() and self.approve_client.service_is_ready())
        assert _wait(lambda: self._perceived())

    def _perceived(self) -> bool:
        try:
            return bool(self.graph.nodes['perception_node'].source.names())
        except Exception:
            return False

    def reset(self) -> None:
        self.graph.nodes['sim_bridge'].reset_world(SEED, OBJECTS)
        self.statuses.clear()

    def positions(self) -> dict[str, np.ndarray]:
        return {name: np.array(self.world.object_state(name).position) for name in OBJECTS}

    def send(self, command: str) -> dict:
        box: dict = {}
        self.execute.send_goal_async(ExecuteCommand.Goal(command=command)).add_done_callback(
            lambda f: f.result().get_result_async().add_done_callback(lambda r: box.update(result=r.result().result)))
        return box

    def awaiting(self) -> StatusEvent | None:
        """The latest command that waits for an answer (not answered yet)."""
        return next((s for s in reversed(list(self.statuses)) if s.stage == StatusEvent.STAGE_AWAITING_APPROVAL
                     and s.command_id not in self.answered), None)

    def answer(self, approve: bool) -> StatusEvent:
        assert _wait(lambda: self.awaiting() is not None)
        waiting = self.awaiting()
        self.answered.add(waiting.command_id)
        future = self.approve_client.call_async(ApproveCommand.Request(command_id=waiting.command_id,
                                                                        approve=approve))
        assert _wait(future.done) and future.result().success, future.result()
        return waiting

    def result(self, box: dict) -> ExecuteCommand.Result:
        assert _wait(lambda: 'result' in box, 180.0)
        return box['result']

    def close(self) -> None:
        self.graph.close()
        self.node.destroy_node()


@pytest.fixture(scope='module')
def person(tmp_path_factory):
    context = Context()
    rclpy.init(context=context, domain_id=next_domain_id())
    cassette = tmp_path_factory.mktemp('approval') / 'cassette.yaml'
    cassette.write_text(CASSETTE, encoding='utf-8')
    person = Person(context, GraphOptions(seed=SEED, objects=', '.join(OBJECTS), cassette=str(cassette),
                                          extra={'lmp_node': {'require_approval': True}}))
    yield person
    person.close()
    context.try_shutdown()


def _moved(before: dict, after: dict) -> set[str]:
    return {name for name in OBJECTS if np.linalg.norm(after[name][:2] - before[name][:2]) > NEAR_M}


def test_motions_left_out_of_the_plan_are_refused(person):
    person.reset()
    before = person.positions()
    box = person.send('sort the blue block and maybe more')
    shown = person.answer(True)
    assert [step.description for step in shown.plan] == ['put the blue block on the blue bowl']
    result = person.result(box)
    assert result.outcome == ExecuteCommand.Result.OUTCOME_REFUSED
    assert ("called put_first_on_second('red block', 'red bowl') after the 1 action(s) of the approved plan"
            in result.message)
    after = person.positions()
    assert _moved(before, after) == {'blue block'}  # what was approved, and nothing else
    assert np.linalg.norm(after['blue block'][:2] - after['blue bowl'][:2]) < 0.03


def test_a_nested_query_that_changes_after_approval_gets_no_new_code(person):
    person.reset()
    before = person.positions()
    box = person.send('sort the blue block and ask what else')
    shown = person.answer(True)
    assert "# parse_obj_name('no block'):\nret_val = []" in shown.code  # the nested LMP's code was shown too
    assert [step.description for step in shown.plan] == ['put the blue block on the blue bowl']
    result = person.result(box)
    assert result.outcome == ExecuteCommand.Result.OUTCOME_REFUSED
    assert "asked parse_obj_name for code with a query the approved plan did not ask ('the red block')" in \
        result.message
    assert _moved(before, person.positions()) == {'blue block'}


def test_a_rejected_plan_leaves_the_session_as_it_was(person):
    person.reset()
    before = person.positions()
    remember = person.send('remember the blue block')
    person.answer(True)
    assert person.result(remember).outcome == ExecuteCommand.Result.OUTCOME_DONE
    rejected = person.send('remember the red block too and sort')  # its plan-only run appends to the list
    person.answer(False)
    assert person.result(rejected).outcome == ExecuteCommand.Result.OUTCOME_REFUSED
    assert _moved(before, person.positions()) == set()
    box = person.send('put what you remember in the red bowl')
    shown = person.answer(True)
    assert [step.description for step in shown.plan] == ['put the blue block on the red bowl']
    assert person.result(box).outcome == ExecuteCommand.Result.OUTCOME_DONE
    assert _moved(before, person.positions()) == {'blue block'}


@pytest.fixture(scope='module')
def hostile(tmp_path_factory):
    """The graph whose sandbox process ignores the protocol: it calls the robot whenever it likes."""
    context = Context()
    rclpy.init(context=context, domain_id=next_domain_id())
    person = Person(context, GraphOptions(seed=SEED, objects=', '.join(OBJECTS),
                                          extra={'lmp_node': {'require_approval': True}}),
                    lmp_node={'sandbox_command': [sys.executable, '-m', 'cap_lmp.testing.hostile_child',
                                                  'breaks_approval']})
    yield person
    person.close()
    context.try_shutdown()


def _call(function: str, *args) -> dict:
    return {'name': function, 'args': list(args), 'kwargs': {}}


def test_a_motion_sent_before_approval_by_a_raw_sandbox_process_moves_nothing(hostile):
    hostile.reset()
    before = hostile.positions()
    box = hostile.send(json.dumps({'before': [_call('put_first_on_second', 'blue block', 'blue bowl')],
                                   'plan': []}))
    result = hostile.result(box)
    assert result.outcome == ExecuteCommand.Result.OUTCOME_REFUSED
    assert "called put_first_on_second('blue block', 'blue bowl') before it was approved" in result.message
    assert hostile.awaiting() is None  # nobody was asked to approve a program that already tried to act
    assert _moved(before, hostile.positions()) == set()


def test_a_motion_outside_the_approved_plan_of_a_raw_sandbox_process_moves_nothing(hostile):
    hostile.reset()
    before = hostile.positions()
    box = hostile.send(json.dumps({'plan': [{'function': 'say', 'args': ['hello'], 'kwargs': {}}],
                                   'after': [_call('put_first_on_second', 'blue block', 'blue bowl')]}))
    shown = hostile.answer(True)
    assert [step.description for step in shown.plan] == ["say 'hello'"]
    result = hostile.result(box)
    assert result.outcome == ExecuteCommand.Result.OUTCOME_REFUSED
    assert "where the approved plan's action 1 is say('hello')" in result.message
    assert _moved(before, hostile.positions()) == set()
