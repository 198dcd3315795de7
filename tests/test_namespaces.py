"""Two whole graphs side by side in one ROS domain, under two namespaces, each commanding its own simulated arm.

The graph's names are relative, so `GraphOptions(namespace='robot1')` (`cap up --namespace robot1`) puts every
topic, service and action under /robot1; each graph's simulator publishes its own clock on <namespace>/clock, and
the nodes that take their time from it stamp their status events with that graph's simulated time.
"""
from __future__ import annotations

import time

import numpy as np
import pytest
import rclpy
from rclpy.action import ActionClient

from cap_bringup.graph import Graph, GraphOptions
from cap_interfaces.action import ExecuteCommand
from cap_interfaces.msg import GraphNames, StatusEvent
from cap_lmp.cassette import ANY_CONTEXT, Cassette, CassetteEntry
from cap_lmp_ros.lmp_node import EVENT_QOS
from cap_perception.sources import NoObservationError

OBJECTS = 'red block, blue block, green bowl, yellow bowl'
PROGRAMS = {
    'put the red block in the green bowl': 'put_first_on_second("red block", "green bowl")',
    'put the blue block in the yellow bowl': 'put_first_on_second("blue block", "yellow bowl")',
}


def _wait(predicate, timeout=60.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.01)
    return predicate()


def _seen(graph: Graph) -> list[str]:
    """The names perception serves; none before its first observation of the simulator."""
    try:
        return graph.nodes['perception_node'].source.names()
    except NoObservationError:
        return []


def _xy(graph: Graph, name: str) -> np.ndarray:
    return np.array(graph.world.object_state(name).position[:2])


@pytest.mark.slow
def test_two_namespaced_graphs_each_move_their_own_arm(ros_context, tmp_path):
    cassette = Cassette(tmp_path / 'two.yaml', [
        CassetteEntry(lmp='tabletop_ui', query=query, context=ANY_CONTEXT, completion=code,
                      source='written by hand for the namespace test') for query, code in PROGRAMS.items()])
    cassette.save()
    options = dict(seed=2, objects=OBJECTS, cassette=str(cassette.path))
    graphs = {name: Graph(ros_context, GraphOptions(namespace=name, **options)) for name in ('robot1', 'robot2')}
    user = rclpy.create_node('namespaces_user', context=ros_context)
    graphs['robot1'].executor.add_node(user)
    try:
        execute = {name: ActionClient(user, ExecuteCommand, f'/{name}/{GraphNames.EXECUTE_ACTION}')
                   for name in graphs}
        statuses = {name: [] for name in graphs}
        for name in graphs:
            user.create_subscription(StatusEvent, f'/{name}/{GraphNames.STATUS_TOPIC}',
                                     lambda message, n=name: statuses[n].append(message), EVENT_QOS)
        assert _wait(lambda: all(client.server_is_ready() for client in execute.values()))
        # Every name of the graph lives under its namespace; nothing of it on the plain names.
        topics = {topic for topic, _types in user.get_topic_names_and_types()}
        for name in graphs:
            assert {f'/{name}/cap/command', f'/{name}/cap/status', f'/{name}/joint_states', f'/{name}/clock',
                    f'/{name}/cap/sim/objects'} <= topics
        assert not {'/cap/command', '/joint_states', '/clock'} & topics
        assert _wait(lambda: all(_seen(graph) for graph in graphs.values()))

        start = {name: {obj: _xy(graph, obj) for obj in ('red block', 'blue block')} for name, graph in graphs.items()}
        bowls = {name: {bowl: _xy(graph, bowl) for bowl in ('green bowl', 'yellow bowl')}
                 for name, graph in graphs.items()}

        def run(name: str, command: str):
            box = {}
            execute[name].send_goal_async(ExecuteCommand.Goal(command=command)).add_done_callback(
                lambda future: box.update(handle=future.result()))
            assert _wait(lambda: 'handle' in box)
            result = box['handle'].get_result_async()
            assert _wait(result.done, 300)
            return result.result().result

        first = run('robot1', 'put the red block in the green bowl')
        assert first.outcome == ExecuteCommand.Result.OUTCOME_DONE, first.message
        assert np.linalg.norm(_xy(graphs['robot1'], 'red block') - bowls['robot1']['green bowl']) < 0.05
        # The other robot did not move, and its blocks are where they were.
        assert np.linalg.norm(_xy(graphs['robot2'], 'red block') - start['robot2']['red block']) < 0.005
        assert np.max(np.abs(graphs['robot2'].world.joint_velocities())) < 0.01

        second = run('robot2', 'put the blue block in the yellow bowl')
        assert second.outcome == ExecuteCommand.Result.OUTCOME_DONE, second.message
        assert np.linalg.norm(_xy(graphs['robot2'], 'blue block') - bowls['robot2']['yellow bowl']) < 0.05
        assert np.linalg.norm(_xy(graphs['robot1'], 'blue block') - start['robot1']['blue block']) < 0.005

        # Status events carry each graph's own simulated time (use_sim_time), not the wall clock.
        for name, graph in graphs.items():
            done = [event for event in statuses[name] if event.stage == StatusEvent.STAGE_DONE]
            assert done, statuses[name]
            stamp = done[-1].header.stamp.sec + done[-1].header.stamp.nanosec * 1e-9
            assert 0.0 < stamp <= graph.world.time + 1e-6  # (the clock message rounds to nanoseconds)
    finally:
        user.destroy_node()
        for graph in graphs.values():
            graph.close()
