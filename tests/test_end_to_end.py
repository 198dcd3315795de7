"""The whole graph in simulation: lmp_node, perception, pick-and-place and the MuJoCo bridge over DDS."""
import threading
import time

import numpy as np
import pytest
from rclpy.action import ActionClient
from std_msgs.msg import Empty

from cap_interfaces.action import ExecuteCommand
from cap_interfaces.msg import GraphNames
from cap_bringup.demos.tabletop import STEPS, run_demo
from cap_bringup.graph import Graph, GraphOptions
from cap_lmp_ros.lmp_node import COMMAND_QOS
from cap_lmp.testing.openai_server import ScriptedOpenAIServer


def _wait(predicate, timeout=60.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.005)
    return predicate()


@pytest.mark.slow
def test_the_demo_sequence_ends_with_every_expected_outcome(ros_isolation, tmp_path):
    summary = run_demo(tmp_path / 'demo', log=lambda *_: None)
    failed = [(s['command'], s['problems']) for s in summary['steps'] if not s['as_expected']]
    assert failed == []
    assert len(summary['steps']) == len(STEPS) >= 10
    assert summary['video_frames'] > 0 and (tmp_path / 'demo' / 'demo.mp4').stat().st_size > 10_000
    for index in range(1, len(STEPS) + 1):
        assert (tmp_path / 'demo' / 'commands' / f'{index:02d}-before.png').is_file()
        assert (tmp_path / 'demo' / 'commands' / f'{index:02d}-after.png').is_file()


class _Graph:
    def __init__(self, context, options):
        import rclpy

        self.graph = Graph(context, options)
        self.user = rclpy.create_node('e2e_user', context=context)
        self.graph.executor.add_node(self.user)
        self.execute = ActionClient(self.user, ExecuteCommand, GraphNames.EXECUTE_ACTION)
        self.stop = self.user.create_publisher(Empty, GraphNames.STOP_TOPIC, COMMAND_QOS)
        assert _wait(lambda: self.execute.server_is_ready() and self.stop.get_subscription_count() >= 2)
        names = self.graph.nodes['perception_node'].source
        assert _wait(lambda: _known(names))

    def send(self, command):
        box = {}
        self.execute.send_goal_async(ExecuteCommand.Goal(command=command)).add_done_callback(
            lambda f: box.update(handle=f.result()))
        assert _wait(lambda: 'handle' in box)
        return box['handle'].get_result_async()

    def close(self):
        self.graph.close()
        self.user.destroy_node()


def _known(source):
    try:
        return bool(source.names())
    except Exception:
        return False


@pytest.mark.slow
def test_cap_stop_halts_the_arm_within_half_a_second_of_simulated_time(ros_context):
    graph = _Graph(ros_context, GraphOptions(seed=4, objects='red block, blue block, green block, yellow bowl'))
    world = graph.graph.world
    try:
        result = graph.send('stack all the blocks')
        # Stop as soon as the arm moves fast, in the middle of a motion of the program.
        assert _wait(lambda: np.max(np.abs(world.joint_velocities())) > 0.3)
        stop_time = world.time
        graph.stop.publish(Empty())
        halted = {}

        def watch():
            while 'at' not in halted and world.time < stop_time + 5.0:
                if np.max(np.abs(world.joint_velocities())) < 0.01:
                    halted['at'] = world.time
                time.sleep(0.001)
        watcher = threading.Thread(target=watch)
        watcher.start()
        assert _wait(result.done)
        watcher.join()
        assert not result.result().result.success
        assert 'stop' in result.result().result.message
        assert halted['at'] - stop_time <= 0.5
        # The arm stays where it stopped.
        held = world.joint_positions()
        time.sleep(0.5)
        assert np.allclose(world.joint_positions(), held, atol=1e-3)
        # Perception's answers reach every client of its services in the process; none of the graph's own
        # clients may sit on the multi-threaded executor, where each answer would cost a Python wait-set rebuild.
        # A client's srv_name is the name it was created with (relative, as GraphNames spells it).
        perception_services = {GraphNames.PERCEPTION_OBJECT_NAMES_SERVICE, GraphNames.PERCEPTION_OBJECT_STATE_SERVICE}
        executors = (graph.graph.executor, graph.graph.events_executor)
        clients = [(node.get_name(), client.srv_name) for executor in executors for node in executor.get_nodes()
                   for client in node.clients if client.srv_name in perception_services]
        assert clients, 'the graph has perception clients'
        assert [client for client in clients if client[0] in
                {node.get_name() for node in graph.graph.executor.get_nodes()}] == []
    finally:
        graph.close()


@pytest.mark.slow
def test_a_command_runs_end_to_end_against_an_openai_protocol_endpoint(ros_context):
    answers = {'put the red block on the blue bowl': "put_first_on_second('red block', 'blue bowl')"}
    with ScriptedOpenAIServer(answers) as server:
        graph = _Graph(ros_context, GraphOptions(
            seed=5, objects='red block, blue bowl, green bowl', llm_backend='http',
            extra={'lmp_node': {'base_url': server.base_url, 'model': server.model}}))
        try:
            result = graph.send('put the red block on the blue bowl')
            assert _wait(result.done, 120)
            assert result.result().result.success, result.result().result.message
            world = graph.graph.world
            red, bowl = world.object_state('red block').position, world.object_state('blue bowl').position
            assert np.linalg.norm(np.subtract(red[:2], bowl[:2])) <= 0.06
            assert any('put the red block on the blue bowl' in r.prompt for r in server.requests)
        finally:
            graph.close()


@pytest.mark.slow
def test_a_program_that_fails_after_a_move_is_finished_by_the_next_one_from_the_scene_as_it_is(ros_context):
    """Execution feedback (lmp_node's feedback_rounds) on the simulator: the first program puts the red block in its
    bowl and then sends the blue block off the table; the program the model writes after reading that moves only the
    blue block, and the command ends done with both blocks in their bowls."""
    from cap_lmp.testing.openai_server import last_query_line

    command = 'put each block in the bowl of its colour'
    first = ("put_first_on_second('red block', 'red bowl')\n"
             "put_first_on_second('blue block', [0.0, 1.5])")

    def respond(request):
        query = last_query_line(request.prompt)
        if 'finishing what the program above did not do' in query:
            return "put_first_on_second('blue block', 'blue bowl')"
        return first if command in query else None

    with ScriptedOpenAIServer(responder=respond) as server:
        graph = _Graph(ros_context, GraphOptions(
            seed=3, objects='red block, blue block, red bowl, blue bowl', llm_backend='http',
            extra={'lmp_node': {'base_url': server.base_url, 'model': server.model, 'feedback_rounds': 1}}))
        try:
            result = graph.send(command)
            assert _wait(result.done, 300)
            answer = result.result().result
            assert answer.success, answer.message
            world = graph.graph.world
            for colour in ('red', 'blue'):
                block = world.object_state(f'{colour} block').position
                bowl = world.object_state(f'{colour} bowl').position
                assert np.linalg.norm(np.subtract(block[:2], bowl[:2])) <= 0.06, colour
            feedback = server.requests[-1].prompt
            assert "# done before it stopped: put_first_on_second('red block', 'red bowl')" in feedback
            assert 'line 2' in feedback and len(server.requests) == 2
        finally:
            graph.close()
