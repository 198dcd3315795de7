"""Per-call cost of a generated controller run by controller_node, through the whole graph (simulator, controller
node, lmp_node and its sandbox process in one process, the sandbox process apart).

Runs the reference cassette's commands ('keep the pole upright with a PD controller for 30 seconds': 3,000 calls
at 100 Hz; 'hold the tool where it is with impedance control for 10 seconds': 1,000 calls of a heavier function)
and prints one JSON object per command with, over every call of the run:
- call_ms: one controller call as controller_node sees it (CallController request to answer: the node's service
  client, lmp_node's service, the socket to the sandbox process and back, the function): p50, p99, max;
- function_ms: the function's own CPU time in the sandbox process (what its time budget bounds): p50, p99, max;
- step_ms: one plant step (ControlStep request to answer: the simulator advancing 10 ms in lockstep): p50, p99;
  with --real-time it includes the simulator's wait for the wall clock, so a tick then lasts about one period;
- tick_ms: call + step, what one period costs, beside the period (10 ms at 100 Hz) and the budget share used;
- wall_s / simulated_s: the run as fast as possible, and the real-time factor it reached;
- outcome: the run's end (a 30 s balance is a success only if the pole stayed within its limits throughout).

Run: source scripts/env.sh && ROS_DOMAIN_ID=91 python benchmarks/controller_loop.py [--real-time]
"""
from __future__ import annotations

import argparse
import json
import os
import threading
import time

import numpy as np

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

import rclpy  # noqa: E402  (after the environment is set)
from rclpy.action import ActionClient  # noqa: E402

from cap_bringup.graph import Graph, GraphOptions  # noqa: E402
from cap_interfaces.action import ExecuteCommand  # noqa: E402
from cap_interfaces.msg import GraphNames  # noqa: E402

COMMANDS = ('keep the pole upright with a PD controller for 30 seconds',
            'hold the tool where it is with impedance control for 10 seconds')


def wait_future(future, timeout: float = 600.0):
    done = threading.Event()
    future.add_done_callback(lambda _: done.set())
    if not done.wait(timeout):
        raise TimeoutError('the command did not end in time')
    return future.result()


def figures(values: list[float]) -> dict[str, float]:
    array = np.asarray(values, dtype=float) * 1000.0
    return {'p50': round(float(np.percentile(array, 50)), 3), 'p99': round(float(np.percentile(array, 99)), 3),
            'max': round(float(array.max()), 3)} if array.size else {}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--real-time', action='store_true', help='simulate in real time (default: as fast as '
                                                                  'possible)')
    args = parser.parse_args()
    context = rclpy.Context()
    rclpy.init(context=context)
    graph = Graph(context, GraphOptions(domain='controllers', seed=1, real_time=args.real_time))
    user = rclpy.create_node('controller_loop_benchmark', context=context)
    graph.executor.add_node(user)
    reports = []
    try:
        client = ActionClient(user, ExecuteCommand, GraphNames.EXECUTE_ACTION)
        if not client.wait_for_server(timeout_sec=30.0):
            raise SystemExit('lmp_node did not come up')
        node = graph.nodes['controller_node']
        for command in COMMANDS:
            started = time.monotonic()
            handle = wait_future(client.send_goal_async(ExecuteCommand.Goal(command=command)))
            answer = wait_future(handle.get_result_async()).result
            wall = time.monotonic() - started
            run = node.last_result
            ticks = [c + s for c, s in zip(run.call_seconds, run.step_seconds)]
            period_ms = 10.0
            reports.append({
                'command': command, 'outcome': answer.message or 'done', 'calls': run.calls,
                'call_ms': figures(run.call_seconds), 'function_ms': figures(run.function_seconds),
                'step_ms': figures(run.step_seconds), 'tick_ms': figures(ticks), 'period_ms': period_ms,
                'tick_p99_share_of_period': round(float(np.percentile(ticks, 99)) * 1000.0 / period_ms, 3),
                'wall_s': round(wall, 2), 'simulated_s': round(run.simulated_time, 2),
                'real_time_factor': round(run.simulated_time / wall, 2),
                'load_average_1min': round(os.getloadavg()[0], 2)})
    finally:
        user.destroy_node()
        graph.close()
        context.try_shutdown()
    print(json.dumps({'real_time': args.real_time, 'runs': reports}, indent=2))


if __name__ == '__main__':
    main()
