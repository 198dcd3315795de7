"""Approval before a program runs (cap_lmp/approval.py): a plan-only run lists what the program would do, nothing
moves until the gate says yes, and a rejection, a cancel or a failed plan leaves the world and the session as they
were. Over the toy domain (its acting functions are recorded, its query functions read the world), in this process
and across the sandbox process, against a real OpenAI-protocol server on 127.0.0.1."""
from __future__ import annotations

import threading

import numpy as np
import pytest

from cap_lmp.approval import FUNCTION, MAX_PLAN_VALUES, PlanError, PlannedCall, plain, planned_call
from cap_lmp.engine import CODE, EXECUTING
from cap_lmp.errors import NotApproved
from cap_lmp.isolated_engine import IsolatedEngine
from cap_lmp.llm import OpenAICompatibleClient
from cap_lmp.outcome import Outcome
from cap_lmp.sandbox import SandboxLimits
from cap_lmp.testing.openai_server import ScriptedOpenAIServer
from cap_lmp.testing.toy_domain import ACTING_FUNCTIONS, build_engine
from cap_lmp.testing.toy_world import ToyWorld

SCENE = {'red block': (-0.1, -0.4), 'blue block': (0.1, -0.45), 'red bowl': (-0.15, -0.65),
         'blue bowl': (0.15, -0.3)}
PROGRAMS = {
    'put the blocks in the bowls of their colour': (
        "names = parse_obj_name('the blocks', f'objects = {get_obj_names()}')\n"
        "for name in names:\n"
        "    put_first_on_second(name, name.replace('block', 'bowl'))\n"
        "say('done sorting')\n"
        "sorted_count = len(names)"),
    '# the blocks.': "ret_val = [name for name in objects if 'block' in name]",
    'move the red block to the middle': "put_first_on_second('red block', np.array([0.0, -0.5]))",
    'move the purple block': "put_first_on_second('red block', 'red bowl')\nget_obj_pos('purple block')",
    'dance forever': "while True:\n    put_first_on_second('red block', 'red bowl')",
    # Tells the plan-only run from the real one (a recorded move changes nothing) and asks a nested LMP another
    # question then: its answer would move a block the plan never showed.
    'tidy up': (
        "start = get_obj_pos('red block')\n"
        "put_first_on_second('red block', 'red bowl')\n"
        "moved = bool(np.linalg.norm(get_obj_pos('red block') - start) > 0.01)\n"
        "names = parse_obj_name('the other block' if moved else 'nothing', f'objects = {get_obj_names()}')\n"
        "for name in names:\n"
        "    put_first_on_second(name, 'blue bowl')"),
    '# nothing.': 'ret_val = []',
    '# the other block.': "ret_val = ['blue block']",
    'start a list': 'marks = [1]\ntally = {"n": 0}\ndef count():\n    tally["n"] += 1\n    return tally["n"]',
    'mark and count': "marks.append(2)\ncount()\nput_first_on_second('red block', 'red bowl')",
    'report': "say(f'{len(marks)} marks, {tally[\"n\"]} counted')",
}


@pytest.fixture
def server():
    with ScriptedOpenAIServer(PROGRAMS) as scripted:
        yield scripted


@pytest.fixture
def world() -> ToyWorld:
    return ToyWorld.with_objects(SCENE)


class Gate:
    """An approval gate that records what it was shown and what the world looked like then, and answers as told."""

    def __init__(self, world: ToyWorld, answer: str = 'approve') -> None:
        self.world, self.answer = world, answer
        self.shown: list[tuple[str, list[PlannedCall]]] = []
        self.moves_when_asked: list[int] = []
        self.asked = threading.Event()
        self.release = threading.Event()

    def __call__(self, code: str, plan: list[PlannedCall]) -> None:
        self.shown.append((code, plan))
        self.moves_when_asked.append(len(self.world.moves))
        self.asked.set()
        if self.answer == 'wait':
            self.release.wait(10.0)
            return
        if self.answer == 'reject':
            raise NotApproved('rejected by the operator: not that one; nothing ran', 'rejected')


def _engine(server: ScriptedOpenAIServer, world: ToyWorld, isolated: bool):
    client = OpenAICompatibleClient(server.base_url, 'scripted-model', timeout_s=10.0)
    options = {'plan_functions': list(ACTING_FUNCTIONS)}
    if isolated:
        return IsolatedEngine(build_engine, world.api(), client, SandboxLimits(time_limit_s=5.0),
                              engine_options=options, address_space_extra_bytes=400 << 20)
    return build_engine(world.api(), client, SandboxLimits(time_limit_s=5.0), **options)


@pytest.fixture(params=['in process', 'sandbox process'])
def engine(request, server, world):
    built = _engine(server, world, request.param == 'sandbox process')
    yield built
    built.close()


def test_an_approved_program_runs_what_its_plan_showed_after_the_gate(engine, server, world):
    gate = Gate(world)
    engine.approval = gate
    events = []
    engine.add_listener(events.append)
    result = engine.run('put the blocks in the bowls of their colour')
    assert result.success, result.message
    code, plan = gate.shown[0]
    # All the code that runs is shown: the program, then each nested LMP's answer with its query.
    assert code.startswith(result.code) and 'put_first_on_second' in code
    assert "# parse_obj_name('the blocks'):\nret_val = [name for name in objects if 'block' in name]" in code
    assert [(call.function, call.args) for call in plan] == [
        ('put_first_on_second', ('red block', 'red bowl')), ('put_first_on_second', ('blue block', 'blue bowl')),
        ('say', ('done sorting',))]
    assert gate.moves_when_asked == [0]  # nothing moved before the approval
    assert world.moves == [('red block', 'red bowl'), ('blue block', 'blue bowl')]
    assert world.said == ['done sorting']  # said once, when it ran, not while it was planned
    nested = [r for r in server.requests if r.prompt.rstrip().endswith('# the blocks.')]
    assert len(nested) == 1  # the nested LMP's planned answer is the one that ran
    stages = [event.stage for event in events if event.lmp == 'toy_ui']
    assert stages.index(CODE) < stages.index(EXECUTING)


def test_a_rejected_program_moves_nothing_and_leaves_the_session_as_it_was(engine, world):
    engine.approval = Gate(world, 'reject')
    result = engine.run('put the blocks in the bowls of their colour')
    assert result.outcome is Outcome.REFUSED and not result.success
    assert 'rejected by the operator: not that one' in result.message
    assert world.moves == [] and world.said == []
    engine.approval = None
    after = engine.run('say sorted_count')  # the plan-only run bound it in a copy of the scope only
    assert not after.success and 'sorted_count' in after.message


def test_a_rejected_plan_changes_no_object_of_the_session(engine, world):
    assert engine.run('start a list').success  # a list, a dict and a function that changes it, in the session
    engine.approval = Gate(world, 'reject')
    result = engine.run('mark and count')  # its plan-only run appended to the list and called the function
    assert result.outcome is Outcome.REFUSED and world.moves == []
    engine.approval = None
    assert engine.run('report').success
    assert world.said == ['1 marks, 0 counted']  # what the session held before the rejected command


def test_a_nested_query_that_differs_after_approval_is_not_asked_and_stops_the_program(engine, server, world):
    gate = Gate(world)
    engine.approval = gate
    result = engine.run('tidy up')
    code, plan = gate.shown[0]
    assert "# parse_obj_name('nothing'):\nret_val = []" in code
    assert [call.args for call in plan] == [('red block', 'red bowl')]
    assert result.outcome is Outcome.REFUSED and result.stop_reason == 'unapproved', result.message
    assert "asked parse_obj_name for code with a query the approved plan did not ask ('the other block')" \
        in result.message
    assert world.moves == [('red block', 'red bowl')]  # the approved move; the blue block stays where it was
    assert not [r for r in server.requests if r.prompt.rstrip().endswith('# the other block.')]


def test_a_failing_plan_is_reported_before_anything_moves(engine, world):
    gate = Gate(world)
    engine.approval = gate
    result = engine.run('move the purple block')
    assert result.outcome is Outcome.ERROR
    assert 'the plan-only run failed, so nothing moved' in result.message and 'purple block' in result.message
    assert gate.shown == [] and world.moves == []


def test_a_point_target_is_planned_as_plain_numbers(engine, world):
    gate = Gate(world)
    engine.approval = gate
    assert engine.run('move the red block to the middle').success
    (call,) = gate.shown[0][1]
    assert call.args[0] == 'red block' and np.allclose(call.args[1], [0.0, -0.5])
    assert all(isinstance(value, float) for value in call.args[1])


def test_a_cancel_while_waiting_for_approval_cancels_the_command(engine, world):
    gate = Gate(world, 'wait')
    engine.approval = gate
    box = {}
    worker = threading.Thread(target=lambda: box.update(result=engine.run('move the red block to the middle')))
    worker.start()
    assert gate.asked.wait(10.0)
    engine.cancel()
    gate.release.set()  # a gate that says yes after the cancel (too late): the program still does not run
    worker.join(10.0)
    assert box['result'].outcome is Outcome.CANCELLED and world.moves == []


def test_a_program_with_too_many_actions_is_not_planned(engine, world):
    engine.approval = Gate(world)
    result = engine.run('dance forever')
    assert not result.success and 'more than 200 robot actions' in result.message and world.moves == []


def test_plain_values_and_the_wire_form_of_a_planned_call():
    assert plain(np.array([0.1, 0.2])) == [0.1, 0.2] and plain(np.array([[1, 2]])) == [[1, 2]]
    assert plain(np.float32(0.5)) == 0.5 and plain(float('nan')) == 'nan' and plain(len) == FUNCTION
    # In full, as the real run will be held to it: no text or list is cut short.
    assert plain('x' * 1000) == 'x' * 1000 and len(plain(list(range(5000)))) == 5000
    for unshowable in (object(), 10 ** 30, [[[[[[[[[[1]]]]]]]]]], np.zeros(MAX_PLAN_VALUES + 1)):
        with pytest.raises(PlanError):
            plain(unshowable)
    call = PlannedCall('put_first_on_second', ('red block', [0.0, -0.5]))
    assert planned_call(call.to_wire()) == call
    for bad in ({'function': 'os.system'}, {'function': 'f', 'args': 'x'}, ['f'], {'function': 3},
                {'function': 'f', 'args': [{'deep': [[[[[[[[[1]]]]]]]]]}]}):
        with pytest.raises(ValueError):
            planned_call(bad)
