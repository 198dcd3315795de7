"""Rehearsal on a twin, judged on the simulator: the whole graph of a domain with lmp_node's rehearse=always (the twin's
simulator, perception and control nodes under /twin) over DDS. Programs written for this test to do harm (off the
table, onto another block, a step that fails after a first move, the base into furniture or a wall, a place against
a bottle after a pick, a wipe through a lemon, ...) are refused by the twin: the graph's own simulator shows that
the arm and the base never moved and no object moved. A harmless program runs on the robot after its rehearsal, and
the result compares the world with the twin's prediction; with approval on as well, the person is shown the twin's
picture.
"""
from __future__ import annotations

import time

import numpy as np
import pytest
import rclpy
from rclpy.action import ActionClient
from rclpy.context import Context
from rcl_interfaces.msg import Parameter as ParameterMsg, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters

from cap_bringup.graph import Graph, GraphOptions
from cap_interfaces.action import ExecuteCommand
from cap_interfaces.msg import GraphNames, StatusEvent
from cap_interfaces.srv import ApproveCommand
from cap_lmp.cassette import Cassette, CassetteEntry
from cap_lmp_ros.lmp_node import EVENT_QOS
from cap_lmp_ros.testing.lmp_graph import wait_for
from conftest import next_domain_id

pytestmark = pytest.mark.slow

STILL_M = 0.003  # an object the robot did not touch is where it was, within settling
STILL_RAD = 1e-3

TABLETOP = {
    'lmp': 'tabletop_ui', 'objects': 'red block, blue block, green block, red bowl, blue bowl',
    'harmful': {
        # the controller's own checks, now met on the twin before anything moves
        'the red block off the table': "put_first_on_second('red block', [0.0, -0.95])",
        'the red block beside the blue block': (
            "put_first_on_second('red block', get_obj_pos('blue block') + np.array([0.035, 0.0]))"),
        'the red block half on the blue block': (
            "put_first_on_second('red block', get_obj_pos('blue block') + np.array([0.02, 0.0]))"),
        'the red block on the rim of the blue bowl': (
            "put_first_on_second('red block', get_obj_pos('blue bowl') + np.array([0.065, 0.0]))"),
        # a first step that would have moved the robot, then one that fails
        'stack two blocks, then the third over the edge': (
            "put_first_on_second('red block', 'blue block')\n"
            "put_first_on_second('green block', get_obj_pos('blue block') + np.array([0.025, 0.0]))"),
        'sort the red block, then divide by zero': "put_first_on_second('red block', 'red bowl')\nx = 1 / 0",
    },
    'good': ('put the red block in the red bowl', "put_first_on_second('red block', 'red bowl')"),
}
MOBILE = {
    'lmp': 'mobile_ui', 'objects': '',
    'harmful': {
        'drive into the table': 'goto_pos([2.0, 1.0])',
        'drive through the table': 'follow_traj(np.array([[0.0, 0.0], [2.0, 0.5], [2.0, 1.5]]))',
        'drive into the wall': 'goto_pos([0.0, 3.4])',
        'pick the apple, then put it against the water bottle': (
            "pick_obj('apple')\nplace_at_pos(get_obj_pos('water bottle') + np.array([0.055, 0.0]))"),
    },
}
WHITEBOARD = {
    'lmp': 'whiteboard_ui', 'objects': '',
    'harmful': {
        'wipe through the lemon': (
            "p = get_obj_pos('lemon')\nerase(np.array([p - np.array([0.06, 0.0]), p + np.array([0.06, 0.0])]))"),
        'draw a line through the apple': (
            "p = get_obj_pos('apple')\ndraw(np.array([p - np.array([0.06, 0.0]), p + np.array([0.06, 0.0])]))"),
        'draw off the board': 'draw(np.array([[0.0, -0.45], [0.0, -1.2]]))',
    },
}


class Rehearsed:
    """A domain's graph with rehearsal on, and a client that resets the scene and sends commands."""

    def __init__(self, tmp_path, domain: str, spec: dict) -> None:
        self.context = Context()
        rclpy.init(context=self.context, domain_id=next_domain_id())
        programs = dict(spec['harmful'])
        if 'good' in spec:
            programs[spec['good'][0]] = spec['good'][1]
        cassette = tmp_path / f'{domain}.yaml'
        Cassette(cassette, [CassetteEntry(spec['lmp'], query, '*', code, 'written by hand for this test')
                            for query, code in programs.items()]).save()
        self.objects = [name.strip() for name in spec['objects'].split(',') if name.strip()] or None
        self.graph = Graph(self.context, GraphOptions(domain=domain, seed=0, objects=spec['objects'],
                                                      cassette=str(cassette), rehearse='always'))
        self.world = self.graph.world
        self.node = rclpy.create_node('rehearsal_test', context=self.context)
        self.statuses: list[StatusEvent] = []
        self.node.create_subscription(StatusEvent, GraphNames.STATUS_TOPIC, self.statuses.append, EVENT_QOS)
        self.execute = ActionClient(self.node, ExecuteCommand, GraphNames.EXECUTE_ACTION)
        self.approve = self.node.create_client(ApproveCommand, GraphNames.APPROVE_SERVICE)
        self.parameters = self.node.create_client(SetParameters, '/lmp_node/set_parameters')
        self.graph.executor.add_node(self.node)
        assert wait_for(lambda: self.execute.server_is_ready() and self.parameters.service_is_ready(), 120.0)

    def reset(self) -> None:
        self.graph.nodes['sim_bridge'].reset_world(0, self.objects)
        mobile = self.graph.nodes.get('mobile_pick_place')
        if mobile is not None:
            mobile.executor_.held = None
        self.statuses.clear()
        time.sleep(0.5)  # perception's next answer is from the reset scene

    def state(self) -> tuple[np.ndarray, np.ndarray | None, dict[str, np.ndarray]]:
        with self.world.lock:
            base = self.world.base_pose().copy() if self.world.base is not None else None
            return (self.world.joint_positions().copy(), base,
                    {s.name: np.array(s.position) for s in self.world.object_states()})

    def send(self, command: str) -> ExecuteCommand.Result:
        box: dict = {}
        self.execute.send_goal_async(ExecuteCommand.Goal(command=command)).add_done_callback(
            lambda f: f.result().get_result_async().add_done_callback(lambda r: box.update(r=r.result().result)))
        assert wait_for(lambda: 'r' in box, 300.0), f'no result for {command!r}'
        return box['r']

    def require_approval(self, required: bool) -> None:
        value = ParameterValue(type=ParameterType.PARAMETER_BOOL, bool_value=required)
        future = self.parameters.call_async(SetParameters.Request(parameters=[
            ParameterMsg(name='require_approval', value=value)]))
        assert wait_for(future.done, 60.0) and future.result().results[0].successful

    def close(self) -> None:
        self.graph.close()
        self.node.destroy_node()
        self.context.try_shutdown()


def _refused_without_moving(rehearsed: Rehearsed, command: str) -> str:
    rehearsed.reset()
    joints, base, objects = rehearsed.state()
    result = rehearsed.send(command)
    assert result.outcome == ExecuteCommand.Result.OUTCOME_REFUSED, (command, result.message)
    assert result.rehearsed and 'the robot did not move' in result.message, result.message
    time.sleep(0.3)
    joints_after, base_after, objects_after = rehearsed.state()
    assert np.abs(joints_after - joints).max() < STILL_RAD, command
    if base is not None:
        assert np.abs(base_after - base).max() < STILL_M, command
    moved = {name for name in objects if np.linalg.norm(objects_after[name] - objects[name]) > STILL_M}
    assert not moved, (command, moved)
    return result.message


@pytest.fixture(scope='module')
def tabletop(tmp_path_factory):
    rehearsed = Rehearsed(tmp_path_factory.mktemp('tabletop'), 'tabletop', TABLETOP)
    yield rehearsed
    rehearsed.close()


@pytest.mark.parametrize('command', list(TABLETOP['harmful']))
def test_a_harmful_table_top_program_is_refused_by_the_twin(tabletop, command):
    message = _refused_without_moving(tabletop, command)
    assert 'line ' in message  # where on the twin it failed


def test_a_program_that_fails_after_a_first_move_does_not_start(tabletop):
    message = _refused_without_moving(tabletop, 'sort the red block, then divide by zero')
    assert 'ZeroDivisionError' in message and 'line 2' in message


def test_a_harmless_program_runs_after_its_rehearsal_as_the_twin_predicted(tabletop):
    tabletop.reset()
    result = tabletop.send('put the red block in the red bowl')
    assert result.outcome == ExecuteCommand.Result.OUTCOME_DONE, result.message
    assert result.rehearsed and result.prediction_misses == []
    assert result.prediction.startswith('as the twin predicted: all 5 object(s) within 3 cm'), result.prediction
    _, _, objects = tabletop.state()
    assert np.linalg.norm(objects['red block'][:2] - objects['red bowl'][:2]) < 0.03
    summaries = [s.message for s in tabletop.statuses if s.message.startswith('rehearsed on the twin')]
    assert summaries and 'nothing went wrong; it moves the red block' in summaries[-1], summaries


def test_approval_shows_the_rehearsal_and_the_twin_picture(tabletop):
    tabletop.reset()
    tabletop.require_approval(True)
    try:
        box: dict = {}
        tabletop.execute.send_goal_async(ExecuteCommand.Goal(command='put the red block in the red bowl')) \
            .add_done_callback(lambda f: f.result().get_result_async().add_done_callback(
                lambda r: box.update(r=r.result().result)))
        assert wait_for(lambda: any(s.stage == StatusEvent.STAGE_AWAITING_APPROVAL for s in tabletop.statuses),
                        120.0)
        waiting = next(s for s in tabletop.statuses if s.stage == StatusEvent.STAGE_AWAITING_APPROVAL)
        assert 'rehearsed on the twin (1 action(s)' in waiting.message, waiting.message
        assert waiting.twin_image.format == 'png' and bytes(waiting.twin_image.data[:4]) == b'\x89PNG'
        joints, _, objects = tabletop.state()  # rehearsed, not yet approved: nothing moved
        future = tabletop.approve.call_async(ApproveCommand.Request(command_id=waiting.command_id, approve=True))
        assert wait_for(future.done, 60.0) and future.result().success
        assert wait_for(lambda: 'r' in box, 120.0)
        assert box['r'].outcome == ExecuteCommand.Result.OUTCOME_DONE, box['r'].message
    finally:
        tabletop.require_approval(False)


@pytest.mark.parametrize('domain, spec', [('mobile', MOBILE), ('whiteboard', WHITEBOARD)])
def test_harmful_programs_elsewhere_are_refused_by_the_twin(tmp_path, domain, spec):
    rehearsed = Rehearsed(tmp_path, domain, spec)
    try:
        messages = {command: _refused_without_moving(rehearsed, command) for command in spec['harmful']}
    finally:
        rehearsed.close()
    if domain == 'mobile':  # the pick would have happened: the place is what fails, on the twin
        assert 'the water bottle at' in messages['pick the apple, then put it against the water bottle']
    else:  # what only the twin's physics could tell: the lemon wiped away, the marker pressed into the apple
        assert 'the lemon ' in messages['wipe through the lemon']
        assert 'the marker pressed the board too hard' in messages['draw a line through the apple']
