"""Latency figures of the running graph (sim bridge, perception, pick-and-place, lmp_node in one process).

Prints one JSON object with:
- pick_place_cycle: simulated and wall seconds per pick-and-place (block onto a bowl), simulator as fast as possible;
- perception_round_trip_ms: GetObjectState service round trip from a client node, p50/p99;
- api_call_round_trip_ms: robot API calls (get_obj_pos) made by generated code, p50/p99, timed where the program
  runs: in lmp_node's sandbox process, so the socket to the node and the node's service call are both included
  (with --in-process-sandbox, lmp_node runs programs in its own process and the two figures are the same);
- api_call_ros_round_trip_ms: the same calls timed inside lmp_node (the perception service round trip alone);
- command_to_first_motion_ms: from publishing on /cap/command to the pick-and-place goal being accepted, minus the
  time lmp_node spent waiting for the model (a replay cassette here, so close to zero).

Run: source scripts/env.sh && ROS_DOMAIN_ID=90 python benchmarks/graph_latency.py [--cycles 10]
"""
from __future__ import annotations

import argparse
import json
import os
import pathlib
import tempfile
import threading
import time

import numpy as np
import yaml

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

import rclpy  # noqa: E402  (after the environment is set)
from action_msgs.msg import GoalStatus, GoalStatusArray  # noqa: E402
from rclpy.action import ActionClient  # noqa: E402
from rclpy.context import Context  # noqa: E402
from std_msgs.msg import String  # noqa: E402

from cap_interfaces.action import ExecuteCommand, PickPlace  # noqa: E402
from cap_interfaces.msg import GraphNames  # noqa: E402
from cap_interfaces.srv import GetObjectState  # noqa: E402
from cap_bringup.graph import Graph, GraphOptions  # noqa: E402
from cap_lmp_ros.lmp_node import COMMAND_QOS  # noqa: E402
from cap_lmp.cassette import FORMAT as CASSETTE_FORMAT

OBJECTS = 'red block, blue block, green block, red bowl, blue bowl, green bowl'
PROGRAMS = {
    'look at the red block a thousand times': "for i in range(1000):\n    get_obj_pos('red block')",
    'put the green block in the green bowl': "put_first_on_second('green block', 'green bowl')",
}


def wait(predicate, timeout=120.0):
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise TimeoutError('benchmark step timed out')
        time.sleep(0.0005)


def wait_future(future, timeout=300.0):
    """Block on a done callback, not by polling: a polling main thread would compete for the interpreter with
    the threads being timed."""
    done = threading.Event()
    future.add_done_callback(lambda _: done.set())
    if not done.wait(timeout):
        raise TimeoutError('benchmark step timed out')


def percentiles_ms(samples) -> dict:
    values = np.array(samples) * 1e3
    return {'p50': round(float(np.percentile(values, 50)), 3), 'p99': round(float(np.percentile(values, 99)), 3),
            'n': len(values)}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument('--cycles', type=int, default=10, help='pick-and-place cycles to time')
    parser.add_argument('--queries', type=int, default=500, help='perception service calls to time')
    parser.add_argument('--in-process-sandbox', action='store_true', help='run programs in lmp_node\'s process '
                        '(sandbox_process:=false) instead of its sandbox process')
    parser.add_argument('--fast', action='store_true', help='simulate as fast as possible (default: real time, as '
                        'a robot runs); the physics thread then competes with the nodes for the interpreter')
    args = parser.parse_args()
    cassette = pathlib.Path(tempfile.mkdtemp()) / 'bench.yaml'
    cassette.write_text(yaml.safe_dump({'format': CASSETTE_FORMAT, 'entries': [
        {'lmp': 'tabletop_ui', 'query': q, 'context': '*', 'completion': c,
         'source': 'written by hand as a reference program'} for q, c in PROGRAMS.items()]}))
    context = Context()
    rclpy.init(context=context)
    graph = Graph(context, GraphOptions(seed=3, objects=OBJECTS, cassette=str(cassette), camera_rate=0.0,
                                        real_time=not args.fast,
                                        extra={'lmp_node': {'sandbox_process': not args.in_process_sandbox}}))
    node = rclpy.create_node('latency_benchmark', context=context)
    graph.executor.add_node(node)
    world = graph.world
    results: dict = {'machine_load_1min': round(os.getloadavg()[0], 2),
                     'simulation': 'as fast as possible' if args.fast else 'real time',
                     'programs_run_in': 'lmp_node' if args.in_process_sandbox else 'the sandbox process'}
    try:
        state = node.create_client(GetObjectState, GraphNames.PERCEPTION_OBJECT_STATE_SERVICE)
        pick_place = ActionClient(node, PickPlace, GraphNames.PICK_PLACE_ACTION)
        execute = ActionClient(node, ExecuteCommand, GraphNames.EXECUTE_ACTION)
        wait(lambda: state.service_is_ready() and pick_place.server_is_ready() and execute.server_is_ready())
        wait(lambda: bool(graph.nodes['perception_node'].source.objects()))

        # Perception service round trip.
        samples = []
        for _ in range(args.queries):
            started = time.perf_counter()
            future = state.call_async(GetObjectState.Request(name='red block'))
            wait(future.done)
            samples.append(time.perf_counter() - started)
        results['perception_round_trip_ms'] = percentiles_ms(samples)
        # Each perception answer reaches every client of the service in the process: an idle client left here
        # would wake this node's executor at every call timed below.
        node.destroy_client(state)

        # Robot API calls from generated code.
        robot = graph.nodes['lmp_node'].robot
        engine = graph.nodes['lmp_node'].engine
        robot.api_call_seconds.clear()
        program_side = getattr(engine, 'api_call_seconds', robot.api_call_seconds)  # in process: the same calls
        program_side.clear()
        goal = execute.send_goal_async(ExecuteCommand.Goal(command='look at the red block a thousand times'))
        wait_future(goal)
        result = goal.result().get_result_async()
        wait_future(result)
        assert result.result().result.success, result.result().result.message
        results['api_call_round_trip_ms'] = percentiles_ms(program_side)
        results['api_call_ros_round_trip_ms'] = percentiles_ms(robot.api_call_seconds)

        # /cap/command to the first motion request (pick-and-place goal accepted).
        accepted = {}

        def on_status(msg: GoalStatusArray) -> None:
            if 'at' not in accepted and any(s.status in (GoalStatus.STATUS_ACCEPTED, GoalStatus.STATUS_EXECUTING)
                                            for s in msg.status_list):
                accepted['at'] = time.perf_counter()
        node.create_subscription(GoalStatusArray, GraphNames.PICK_PLACE_ACTION + '/_action/status', on_status, 10)
        commands = node.create_publisher(String, GraphNames.COMMAND_TOPIC, COMMAND_QOS)
        wait(lambda: commands.get_subscription_count() > 0)
        time.sleep(0.5)
        lmp = graph.nodes['lmp_node']
        sent = time.perf_counter()
        commands.publish(String(data='put the green block in the green bowl'))
        wait(lambda: 'at' in accepted)
        wait(lambda: lmp.queue.running is None and lmp.queue.waiting() == 0, 300)
        results['command_to_first_motion_ms'] = round((accepted['at'] - sent) * 1e3, 2)
        results['command_to_first_motion_note'] = 'model time excluded: answers replayed from a cassette'

        # Pick-and-place cycles, simulator as fast as possible.
        cycles = []
        targets = ['red bowl', 'blue bowl', 'green bowl']
        for i in range(args.cycles):
            block = ['red block', 'blue block'][i % 2]
            sim_started, wall_started = world.time, time.perf_counter()
            goal = pick_place.send_goal_async(PickPlace.Goal(object_name=block, target_name=targets[i % 3]))
            wait(goal.done)
            result = goal.result().get_result_async()
            wait(result.done)
            cycles.append({'sim_s': world.time - sim_started, 'wall_s': time.perf_counter() - wall_started,
                           'ok': result.result().result.error_code == PickPlace.Result.NONE})
        results['pick_place_cycle'] = {
            'n': len(cycles), 'succeeded': sum(c['ok'] for c in cycles),
            'sim_s_median': round(float(np.median([c['sim_s'] for c in cycles])), 2),
            'wall_s_median': round(float(np.median([c['wall_s'] for c in cycles])), 2),
            'real_time_factor_median': round(float(np.median([c['sim_s'] / c['wall_s'] for c in cycles])), 2)}
    finally:
        graph.close()
        node.destroy_node()
        context.try_shutdown()
    print(json.dumps(results, indent=2))


if __name__ == '__main__':
    main()
