"""Rehearsal on a twin (cap_lmp/rehearsal.py): while a command is rehearsed, the program's robot calls go to the
twin, the acting ones recorded; harm the twin saw stops the program at that call; nothing reaches the robot until
the rehearsal ended clean; the real run is then held to what the twin received. Over the toy domain, with a second
toy world as the twin, in this process and across the sandbox process, against a real OpenAI-protocol server on
127.0.0.1; and the prediction-versus-outcome comparison."""
from __future__ import annotations

import pytest

from cap_lmp.approval import ApprovalGuard, PlannedCall, guarded_functions
from cap_lmp.errors import NotApproved, UnapprovedAction
from cap_lmp.isolated_engine import IsolatedEngine
from cap_lmp.llm import OpenAICompatibleClient
from cap_lmp.outcome import Outcome
from cap_lmp.rehearsal import (REHEARSAL_TOLERANCE, RESTART_REHEARSAL, UNHELD_WHEN_REHEARSED, PredictionMiss,
                               Rehearsal, TwinHarm, harm_text, prediction_misses, prediction_text, rehearses)
from cap_lmp.sandbox import SandboxLimits
from cap_lmp.testing.openai_server import ScriptedOpenAIServer
from cap_lmp.testing.toy_domain import ACTING_FUNCTIONS, build_engine
from cap_lmp.testing.toy_world import ToyWorld

SCENE = {'red block': (-0.1, -0.4), 'blue block': (0.1, -0.45), 'red bowl': (-0.15, -0.65),
         'blue bowl': (0.15, -0.3)}
PROGRAMS = {
    'sort the blocks': (
        "names = parse_obj_name('the blocks', f'objects = {get_obj_names()}')\n"
        "for name in names:\n"
        "    put_first_on_second(name, name.replace('block', 'bowl'))\n"
        "say('sorted')"),
    '# the blocks.': "ret_val = [name for name in objects if 'block' in name]",
    'put the red block in the blue bowl, then fail': (
        "put_first_on_second('red block', 'blue bowl')\n"
        "x = 1 / 0"),
    'knock the blue bowl over': "put_first_on_second('blue block', 'red bowl')\nsay('never said')",
    'knock the blue bowl over, finishing what the program above did not do': (
        "put_first_on_second('blue block', 'blue bowl')\nsay('done, the other way')"),
    'ignore the harm': (
        "try:\n"
        "    put_first_on_second('blue block', 'red bowl')\n"
        "except Exception:\n"
        "    pass"),
}


class Node:
    """lmp_node's side of a rehearsed command, in small: the router, the guard, the twin's judgement, the gate."""

    def __init__(self, robot: ToyWorld, twin: ToyWorld, harmful: set[tuple[str, str]] = frozenset()) -> None:
        self.robot, self.twin, self.harmful = robot, twin, harmful
        self.guard = ApprovalGuard(ACTING_FUNCTIONS)
        self.rehearsal = Rehearsal(ACTING_FUNCTIONS)
        self.findings: list[str] = []
        self.refusals = 0
        robot_api = guarded_functions(robot.api(), self.guard, self._refused)
        self.api = self.rehearsal.routed(robot_api, twin.api(), self.check_harm)
        self.api[RESTART_REHEARSAL] = self.restart
        self.rehearsed: list[PlannedCall] = []
        self.restarts = 0

    def restart(self) -> None:
        """The twin built again from the robot's world (which the rehearsal never touched)."""
        self.twin.positions = {name: xy.copy() for name, xy in self.robot.positions.items()}
        self.twin.moves.clear()
        self.twin.said.clear()
        self.findings = []
        self.restarts += 1
        self.rehearsal.begin()

    def _refused(self) -> None:
        self.refusals += 1

    def check_harm(self, function: str) -> None:
        """The twin 'sees' harm when one of `harmful` moves happened on it."""
        self.findings = [f'the {obj} knocked the {target} over' for obj, target in self.twin.moves
                         if (obj, target) in self.harmful]
        if self.findings:
            raise TwinHarm(harm_text(self.findings, function))

    def begin(self) -> None:
        self.guard.begin(True, REHEARSAL_TOLERANCE, 'the rehearsed plan')
        self.rehearsal.begin()

    def gate(self, code: str, calls: list[PlannedCall]) -> None:
        self.rehearsed = self.rehearsal.end()
        if self.findings:
            raise NotApproved(f'on the twin: {"; ".join(self.findings)}; the robot did not move', 'rehearsal')
        self.guard.approve(self.rehearsed)


@pytest.fixture
def server():
    with ScriptedOpenAIServer(PROGRAMS) as scripted:
        yield scripted


def _engine(server: ScriptedOpenAIServer, node: Node, isolated: bool, feedback_rounds: int = 0):
    client = OpenAICompatibleClient(server.base_url, 'scripted-model', timeout_s=10.0)
    options = {'plan_functions': list(ACTING_FUNCTIONS), 'feedback_rounds': feedback_rounds}
    if isolated:
        engine = IsolatedEngine(build_engine, node.api, client, SandboxLimits(time_limit_s=5.0),
                                engine_options=options, address_space_extra_bytes=400 << 20)
    else:
        engine = build_engine(node.api, client, SandboxLimits(time_limit_s=5.0), **options)
    engine.approval, engine.rehearse = node.gate, True
    return engine


@pytest.fixture(params=['in process', 'sandbox process'])
def isolated(request) -> bool:
    return request.param == 'sandbox process'


def _run(server, node: Node, isolated: bool, command: str, feedback_rounds: int = 0):
    engine = _engine(server, node, isolated, feedback_rounds)
    try:
        node.begin()
        result = engine.run(command)
        node.rehearsal.end()
        return result
    finally:
        engine.close()


def test_a_clean_rehearsal_runs_on_the_twin_first_then_the_same_on_the_robot(server, isolated):
    robot, twin = ToyWorld.with_objects(SCENE), ToyWorld.with_objects(SCENE)
    node = Node(robot, twin)
    result = _run(server, node, isolated, 'sort the blocks')
    assert result.success, result.message
    # The twin received every call of the rehearsal, nested LMP's answer included; `say` was spoken to the twin.
    assert twin.moves == [('red block', 'red bowl'), ('blue block', 'blue bowl')] and twin.said == ['sorted']
    assert robot.moves == twin.moves and robot.said == ['sorted']
    assert [(c.function, c.args) for c in node.rehearsed] == [
        ('put_first_on_second', ('red block', 'red bowl')), ('put_first_on_second', ('blue block', 'blue bowl')),
        ('say', ('sorted',))]
    nested = [r for r in server.requests if r.prompt.rstrip().endswith('# the blocks.')]
    assert len(nested) == 1  # the real run executed the rehearsed nested answer, no second request


def test_a_program_that_fails_on_the_twin_never_moves_the_robot(server, isolated):
    robot, twin = ToyWorld.with_objects(SCENE), ToyWorld.with_objects(SCENE)
    result = _run(server, Node(robot, twin), isolated, 'put the red block in the blue bowl, then fail')
    assert result.outcome is Outcome.REFUSED and not result.success
    assert result.message.startswith('the rehearsal on the twin failed, so the robot did not move: ZeroDivisionError')
    assert 'line 2' in result.message
    assert twin.moves == [('red block', 'blue bowl')] and robot.moves == []  # half done on the twin only


def test_harm_the_twin_saw_stops_the_program_at_that_line(server, isolated):
    robot, twin = ToyWorld.with_objects(SCENE), ToyWorld.with_objects(SCENE)
    node = Node(robot, twin, harmful={('blue block', 'red bowl')})
    result = _run(server, node, isolated, 'knock the blue bowl over')
    assert result.outcome is Outcome.REFUSED
    assert 'on the twin, put_first_on_second() did harm: the blue block knocked the red bowl over' in result.message
    assert 'line 1' in result.message
    assert robot.moves == [] and robot.said == [] and twin.said == []  # stopped there: the say never came


def test_with_feedback_rounds_what_the_twin_saw_brings_a_new_program_rehearsed_on_a_new_twin(server, isolated):
    robot, twin = ToyWorld.with_objects(SCENE), ToyWorld.with_objects(SCENE)
    node = Node(robot, twin, harmful={('blue block', 'red bowl')})
    result = _run(server, node, isolated, 'knock the blue bowl over', feedback_rounds=1)
    assert result.success, result.message
    assert node.restarts == 1  # the twin was built again for the second program
    assert robot.moves == [('blue block', 'blue bowl')] and robot.said == ['done, the other way']
    assert [(c.function, c.args) for c in node.rehearsed] == [('put_first_on_second', ('blue block', 'blue bowl')),
                                                              ('say', ('done, the other way',))]
    asked = [r.prompt for r in server.requests if 'finishing what the program above did not do' in r.prompt]
    assert len(asked) == 1
    assert "# rehearsed on a twin, the program above stopped at line 1 (`put_first_on_second('blue block', " \
        "'red bowl')`): " in asked[0]  # TwinHarm here, RobotApiError across the sandbox process
    assert 'on the twin, put_first_on_second() did harm: the blue block knocked the red bowl over' in asked[0]
    assert '# rehearsal round 1, after: rehearsed on a twin' in result.code


def test_a_program_that_swallows_the_harm_is_still_refused(server, isolated):
    robot, twin = ToyWorld.with_objects(SCENE), ToyWorld.with_objects(SCENE)
    node = Node(robot, twin, harmful={('blue block', 'red bowl')})
    result = _run(server, node, isolated, 'ignore the harm')
    assert result.outcome is Outcome.REFUSED
    assert 'on the twin: the blue block knocked the red bowl over; the robot did not move' in result.message
    assert robot.moves == []


def test_the_router_sends_calls_to_the_robot_when_no_rehearsal_runs():
    robot, twin = ToyWorld.with_objects(SCENE), ToyWorld.with_objects(SCENE)
    rehearsal = Rehearsal(ACTING_FUNCTIONS)
    harm_checks: list[str] = []
    api = rehearsal.routed(robot.api(), twin.api(), harm_checks.append)
    api['put_first_on_second']('red block', 'red bowl')
    assert robot.moves == [('red block', 'red bowl')] and twin.moves == [] and harm_checks == []
    rehearsal.begin()
    api['get_obj_names']()  # a query goes to the twin, unrecorded and unchecked
    api['put_first_on_second']('blue block', 'blue bowl')
    assert twin.moves == [('blue block', 'blue bowl')] and harm_checks == ['put_first_on_second']
    assert rehearsal.end() == [PlannedCall('put_first_on_second', ('blue block', 'blue bowl'))]
    assert robot.moves == [('red block', 'red bowl')]


def test_the_modes_say_which_commands_are_rehearsed():
    assert rehearses('always', False) and rehearses('always', True)
    assert rehearses('on_approval', True) and not rehearses('on_approval', False)
    assert not rehearses('off', True)


def test_prediction_misses_name_objects_off_the_prediction_and_those_that_moved_unasked():
    start = {'red block': (0.0, -0.4, 0.02), 'blue block': (0.1, -0.4, 0.02), 'red bowl': (0.0, -0.6, 0.02)}
    predicted = {'red block': (0.0, -0.6, 0.03), 'blue block': (0.1, -0.4, 0.02), 'red bowl': (0.0, -0.6, 0.02)}
    assert prediction_misses(start, predicted, {'red block': (0.01, -0.61, 0.03), 'blue block': (0.1, -0.4, 0.02),
                                                'red bowl': (0.0, -0.6, 0.02)}) == []
    observed = {'red block': (0.0, -0.5, 0.02), 'blue block': (0.15, -0.4, 0.02), 'green block': (0.2, -0.3, 0.02)}
    misses = prediction_misses(start, predicted, observed)
    assert [(m.name, round(m.distance, 3), m.unexpected) for m in misses] == [('blue block', 0.05, True),
                                                                              ('red block', 0.1, False)]
    text = prediction_text(misses, 2)
    assert text.startswith('2 of 2 object(s) not where the twin predicted')
    assert 'the blue block is 5.0 cm from where the twin left it (the twin did not move it)' in text
    assert prediction_text([], 3) == 'as the twin predicted: all 3 object(s) within 3 cm of where it left them'
    assert isinstance(misses[0], PredictionMiss)


def test_a_rehearsed_run_is_held_to_its_motions_and_says_what_it_finds():
    guard = ApprovalGuard(ACTING_FUNCTIONS)
    guard.begin(True, REHEARSAL_TOLERANCE, 'the rehearsed plan', unheld=UNHELD_WHEN_REHEARSED)
    guard.approve([PlannedCall('say', ('3 blocks are in bowls',)),
                   PlannedCall('put_first_on_second', ('red block', [0.1, -0.5]))])
    guard.check_call('say', ('4 blocks are in bowls',), {})  # the real count, not the twin's
    guard.check_call('put_first_on_second', ('red block', [0.12, -0.5]), {})  # within REHEARSAL_TOLERANCE
    with pytest.raises(UnapprovedAction, match="after the 1 action\\(s\\) of the rehearsed plan"):
        guard.check_call('put_first_on_second', ('blue block', 'red bowl'), {})
