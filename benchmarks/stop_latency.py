"""Stop latency of the graph: how long /cap/stop takes to end the running program and to bring the robot to rest.

For each kind of work a program can be doing when the stop comes, the domain's whole graph runs in this process
(cap_bringup.graph.Graph, simulating in real time), a user node sends the command on /cap/execute and, once the work
is under way, publishes on /cap/stop. Timed from that publication, in wall time:
- end_s: until the command's result arrives (the program has ended);
- rest_s: until the robot is at rest for good: every arm and finger joint (and the mobile base) slower than 0.01
  rad/s or m/s from then on, and no controller driving a plant (its efforts gone); 0 when nothing moved after.
The kinds:
- python_loop (tabletop): a program spinning in a Python loop;
- pick_place (tabletop): put_first_on_second, stopped while the arm moves fast;
- c_call (tabletop): one long NumPy call in the sandbox process (a 1400 x 1400 integer matrix product, some 3 s,
  within its size rules), stopped 1 s into it;
- whiteboard_planning (whiteboard): draw() of 5,000 points all over the board, stopped while follow_path plans it;
  then a new path goal is sent at once: `next_goal_accepted` says whether follow_path took it;
- whiteboard_drawing (whiteboard): the same drawing, stopped 0.5 s after follow_path began sending the stroke's
  motion (hours of it);
- controller (controllers): a PD controller balancing the cart-pole, stopped 1 s into its run;
- navigation (mobile): back and forth between the table and the countertop, stopped while the base moves;
- robot_call_past_time_limit (tabletop, lmp_node time_limit_s 3 s): no stop; a put_first_on_second that lasts
  longer than the limit; end_s and rest_s are timed from the limit (the program's start + time_limit_s).
Each kind runs --trials times (the scene is reset before each); the JSON gives every trial (with the command's
outcome and message) and, per kind, the median and worst end_s and rest_s; and the planning time of the 5,000
points alone (cap_control.follow_path.plan.plan_path, no ROS).

Run: source scripts/env.sh && ROS_DOMAIN_ID=92 python benchmarks/stop_latency.py [--trials 3] [--kinds a,b]
"""
from __future__ import annotations

import argparse
import json
import math
import os
import pathlib
import tempfile
import time
from typing import Callable

import numpy as np
import yaml

os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'

import rclpy  # noqa: E402  (after the environment is set)
from action_msgs.msg import GoalStatus, GoalStatusArray  # noqa: E402
from geometry_msgs.msg import Point  # noqa: E402
from rclpy.action import ActionClient  # noqa: E402
from rclpy.context import Context  # noqa: E402
from std_msgs.msg import Empty  # noqa: E402

from cap_bringup.graph import Graph, GraphOptions  # noqa: E402
from cap_control.follow_path.plan import plan_path  # noqa: E402
from cap_interfaces.action import ExecuteCommand, FollowPath  # noqa: E402
from cap_interfaces.msg import GraphNames, StatusEvent, Stroke  # noqa: E402
from cap_interfaces.srv import ResetScene  # noqa: E402
from cap_lmp.cassette import FORMAT as CASSETTE_FORMAT  # noqa: E402
from cap_lmp_ros.lmp_node import COMMAND_QOS, EVENT_QOS, outcome_name  # noqa: E402

AT_REST = 0.01  # [rad/s, m/s]
SETTLE_S = 1.5  # motion is watched this long after the end and the last motion
TIME_LIMIT_S = 3.0
SCRIBBLE = ('t = np.arange(5000)\n'
            'pts = np.column_stack([0.23 * np.sin(1.7 * t), -0.5 + 0.18 * np.cos(2.3 * t)])\n'
            'draw(pts)')
TABLETOP_PROGRAMS = {
    'count forever': 'i = 0\nwhile True:\n    i = i + 1',
    'put the green block in the green bowl': "put_first_on_second('green block', 'green bowl')",
    'multiply two integer matrices': "a = np.ones((1400, 1400), dtype='int64')\nb = a @ a",
}
TABLETOP_OBJECTS = 'green block, green bowl, red block'


def wait(predicate: Callable[[], bool], timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise TimeoutError(f'timed out waiting for {what}')
        time.sleep(0.001)


def cassette(programs: dict[str, str], lmp: str) -> str:
    path = pathlib.Path(tempfile.mkdtemp()) / f'{lmp}.yaml'
    path.write_text(yaml.safe_dump({'format': CASSETTE_FORMAT, 'entries': [
        {'lmp': lmp, 'query': query, 'context': '*', 'completion': code, 'source': 'written by hand for the benchmark'}
        for query, code in programs.items()]}))
    return str(path)


class Bench:
    """A domain's graph and a user node beside it: sends commands, publishes stops, watches the robot."""

    def __init__(self, domain: str, programs: dict[str, str] | None = None, objects: str = '', seed: int = 0,
                 lmp_parameters: dict | None = None) -> None:
        self.domain, self.seed, self.objects = domain, seed, objects
        self.context = Context()
        rclpy.init(context=self.context)
        self.graph = Graph(self.context, GraphOptions(
            domain=domain, seed=seed, objects=objects, camera_rate=0.0, real_time=True,
            cassette=cassette(programs, f'{domain}_ui') if programs else '',
            extra={'lmp_node': lmp_parameters or {}}))
        self.world = self.graph.world
        self.node = rclpy.create_node('stop_latency_benchmark', context=self.context)
        self.graph.executor.add_node(self.node)
        self.execute = ActionClient(self.node, ExecuteCommand, GraphNames.EXECUTE_ACTION)
        self.stop = self.node.create_publisher(Empty, GraphNames.STOP_TOPIC, COMMAND_QOS)
        self.reset = self.node.create_client(ResetScene, GraphNames.SIM_RESET_SERVICE)
        self.executing: dict[str, float] = {}  # command -> when its program began
        self.node.create_subscription(StatusEvent, GraphNames.STATUS_TOPIC, self._on_status, EVENT_QOS)
        wait(lambda: self.execute.server_is_ready() and self.reset.service_is_ready()
             and self.stop.get_subscription_count() >= 2, 120, f'the {domain} graph')

    def _on_status(self, event: StatusEvent) -> None:
        if event.stage == StatusEvent.STAGE_EXECUTING:
            self.executing[event.command] = time.monotonic()

    def reset_scene(self) -> None:
        from cap_interfaces.msg import ObjectSpec

        names = [name.strip() for name in self.objects.split(',') if name.strip()]
        future = self.reset.call_async(ResetScene.Request(seed=self.seed, objects=[ObjectSpec(name=n) for n in names]))
        wait(future.done, 60, 'the scene reset')
        assert future.result().success, future.result().message
        time.sleep(0.5)  # perception catches up with the new scene

    def moving(self) -> bool:
        world = self.world
        speeds = [np.abs(world.joint_velocities()), np.abs(world.finger_velocities())]
        if world.base is not None:
            speeds.append(np.abs(world.base_velocity()))
        return bool(max(float(np.max(s)) for s in speeds if len(s)) > AT_REST) or self.graph.nodes[
            'sim_bridge'].lockstep.active

    def trial(self, command: str, under_way: Callable[[float], bool], stop: bool = True,
              deadline_after_start: float | None = None) -> dict:
        """Send `command`, publish a stop once `under_way(program start)` holds (or, without a stop, time from the
        program's start + `deadline_after_start`); the latencies and the command's outcome."""
        self.executing.pop(command, None)
        handle = self.execute.send_goal_async(ExecuteCommand.Goal(command=command))
        wait(handle.done, 60, 'lmp_node to accept the command')
        result = handle.result().get_result_async()
        ended: dict[str, float] = {}
        result.add_done_callback(lambda _: ended.setdefault('at', time.monotonic()))
        wait(lambda: command in self.executing or result.done(), 120, 'the program to start')
        started = self.executing.get(command, time.monotonic())
        wait(lambda: under_way(started) or result.done(), 300, 'the work to be under way')
        if stop:
            origin = time.monotonic()
            self.stop.publish(Empty())
        else:
            origin = started + deadline_after_start
        last_motion = None
        quiet_since = time.monotonic()
        while time.monotonic() - origin < 300:
            now = time.monotonic()
            if self.moving():
                last_motion, quiet_since = now, now
            if 'at' in ended and now - quiet_since > SETTLE_S and now - ended['at'] > SETTLE_S:
                break
            time.sleep(0.002)
        answer = result.result().result if result.done() else None
        return {'end_s': round(ended['at'] - origin, 3) if 'at' in ended else None,
                'rest_s': round(max(0.0, last_motion - origin), 3) if last_motion is not None else 0.0,
                'outcome': outcome_name(answer.outcome) if answer is not None else 'no result',
                'message': answer.message[:200] if answer is not None else ''}

    def close(self) -> None:
        self.graph.close()
        self.node.destroy_node()
        self.context.try_shutdown()


def next_path_goal_accepted(bench: Bench) -> dict:
    """Right after a stop: send follow_path a path (off the board: refused by its checks, nothing moves) and say
    whether the goal was accepted, and how soon its answer came."""
    # One client per bench, never destroyed while the graph's executor spins its node (rclpy then fails a
    # callback in flight on the destroyed handle, and the graph's executor thread with it).
    client = getattr(bench, 'path_client', None) or ActionClient(bench.node, FollowPath, GraphNames.FOLLOW_PATH_ACTION)
    bench.path_client = client
    wait(client.server_is_ready, 30, 'follow_path')
    sent = time.monotonic()
    goal = FollowPath.Goal(tool=FollowPath.Goal.TOOL_NONE,
                           strokes=[Stroke(points=[Point(x=0.0, y=-0.5), Point(x=0.6, y=-0.5)])])
    handle = client.send_goal_async(goal)
    wait(handle.done, 30, 'follow_path to answer the goal')
    accepted = bool(handle.result().accepted)
    answered = None
    if accepted:
        result = handle.result().get_result_async()
        wait(result.done, 30, 'follow_path\'s result')
        answered = round(time.monotonic() - sent, 3)
    return {'next_goal_accepted': accepted, 'next_goal_answered_s': answered}


def arm_speed_above(bench: Bench, speed: float) -> Callable[[float], bool]:
    return lambda _: float(np.max(np.abs(bench.world.joint_velocities()))) > speed


def seconds_after_start(seconds: float) -> Callable[[float], bool]:
    return lambda started: time.monotonic() > started + seconds


def after_message(bench: Bench, message_type, topic: str, matches: Callable, delay: float) -> Callable[[float], bool]:
    """True `delay` seconds after the first message on `topic` that `matches`. The subscription stays until the
    bench closes: destroying it while the graph's executor spins the node could fail a callback in flight."""
    seen: dict[str, float] = {}

    def on_message(msg) -> None:
        if matches(msg):
            seen.setdefault('at', time.monotonic())
    bench.node.create_subscription(message_type, topic, on_message, 10)

    def under_way(_: float) -> bool:
        return 'at' in seen and time.monotonic() > seen['at'] + delay
    return under_way


def follow_path_executing(bench: Bench, delay: float) -> Callable[[float], bool]:
    """True `delay` seconds after a follow_path goal began executing (its planning, for a 5,000-point stroke)."""
    return after_message(bench, GoalStatusArray, GraphNames.FOLLOW_PATH_ACTION + '/_action/status',
                         lambda msg: any(s.status == GoalStatus.STATUS_EXECUTING for s in msg.status_list), delay)


def follow_path_stage(bench: Bench, stage: str, delay: float) -> Callable[[float], bool]:
    """True `delay` seconds after follow_path's feedback first named `stage` ('follow': the stroke's motion, from
    the moment it is sent)."""
    return after_message(bench, FollowPath.Impl.FeedbackMessage, GraphNames.FOLLOW_PATH_ACTION + '/_action/feedback',
                         lambda msg: msg.feedback.stage == stage, delay)


def tabletop_kinds(trials: int, kinds: set[str]) -> dict:
    results: dict[str, list] = {}
    wanted = kinds & {'python_loop', 'pick_place', 'c_call'}
    if wanted:
        bench = Bench('tabletop', TABLETOP_PROGRAMS, TABLETOP_OBJECTS, seed=3)
        try:
            for _ in range(trials):
                if 'python_loop' in wanted:
                    results.setdefault('python_loop', []).append(
                        bench.trial('count forever', seconds_after_start(1.0)))
                if 'pick_place' in wanted:
                    bench.reset_scene()
                    results.setdefault('pick_place', []).append(
                        bench.trial('put the green block in the green bowl', arm_speed_above(bench, 0.3)))
                if 'c_call' in wanted:
                    results.setdefault('c_call', []).append(
                        bench.trial('multiply two integer matrices', seconds_after_start(1.0)))
        finally:
            bench.close()
    if 'robot_call_past_time_limit' in kinds:
        bench = Bench('tabletop', TABLETOP_PROGRAMS, TABLETOP_OBJECTS, seed=3,
                      lmp_parameters={'time_limit_s': TIME_LIMIT_S})
        try:
            for _ in range(trials):
                bench.reset_scene()
                results.setdefault('robot_call_past_time_limit', []).append(bench.trial(
                    'put the green block in the green bowl', seconds_after_start(TIME_LIMIT_S), stop=False,
                    deadline_after_start=TIME_LIMIT_S))
        finally:
            bench.close()
    return results


def whiteboard_kinds(trials: int, kinds: set[str]) -> dict:
    bench = Bench('whiteboard', {'draw a scribble of 5000 points': SCRIBBLE}, 'red block', seed=2)
    results: dict[str, list] = {}
    try:
        for _ in range(trials):
            if 'whiteboard_planning' in kinds:
                run = bench.trial('draw a scribble of 5000 points', follow_path_executing(bench, 0.2))
                run.update(next_path_goal_accepted(bench))
                results.setdefault('whiteboard_planning', []).append(run)
            if 'whiteboard_drawing' in kinds:
                bench.reset_scene()
                results.setdefault('whiteboard_drawing', []).append(
                    bench.trial('draw a scribble of 5000 points', follow_path_stage(bench, 'follow', 0.5)))
    finally:
        bench.close()
    return results


def controller_kind(trials: int) -> dict:
    bench = Bench('controllers')
    lockstep = bench.graph.nodes['sim_bridge'].lockstep
    took_over: dict[str, float] = {}

    def running_a_second(_: float) -> bool:
        if lockstep.active:
            took_over.setdefault('at', time.monotonic())
        return 'at' in took_over and time.monotonic() > took_over['at'] + 1.0
    runs = []
    try:
        for _ in range(trials):
            bench.reset_scene()
            took_over.clear()
            runs.append(bench.trial('keep the pole upright with a PD controller for 30 seconds', running_a_second))
    finally:
        bench.close()
    return {'controller': runs}


def navigation_kind(trials: int) -> dict:
    bench = Bench('mobile')
    runs = []
    try:
        for _ in range(trials):
            bench.reset_scene()
            runs.append(bench.trial('move back and forth between the table and the countertop 3 times',
                                    lambda _: float(np.linalg.norm(bench.world.base_velocity()[:2])) > 0.2))
    finally:
        bench.close()
    return {'navigation': runs}


def planning_seconds() -> float:
    """plan_path of the benchmark's 5,000 points alone (the median of 3)."""
    t = np.arange(5000)
    points = np.column_stack([0.23 * np.sin(1.7 * t), -0.5 + 0.18 * np.cos(2.3 * t)])
    ready = np.array([0.8413, -2.2842, 1.7017, -0.9883, -1.5708, -0.7295])
    times = []
    for _ in range(3):
        started = time.perf_counter()
        plan_path(ready, [points], 'marker')
        times.append(time.perf_counter() - started)
    return round(float(np.median(times)), 3)


def summary(runs: list[dict], key: str) -> dict:
    values = [run[key] for run in runs if run[key] is not None]
    if not values:
        return {'median': None, 'worst': None}
    return {'median': round(float(np.median(values)), 3), 'worst': round(float(max(values)), 3)}


KINDS = ('python_loop', 'pick_place', 'c_call', 'whiteboard_planning', 'whiteboard_drawing', 'controller',
         'navigation', 'robot_call_past_time_limit')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--trials', type=int, default=3, help='trials per kind')
    parser.add_argument('--kinds', default=','.join(KINDS), help=f'comma-separated, of {", ".join(KINDS)}')
    args = parser.parse_args()
    kinds = {kind.strip() for kind in args.kinds.split(',') if kind.strip()}
    unknown = kinds - set(KINDS)
    if unknown:
        parser.error(f'unknown kinds {sorted(unknown)}')
    results: dict[str, list] = {}
    results.update(tabletop_kinds(args.trials, kinds))
    if kinds & {'whiteboard_planning', 'whiteboard_drawing'}:
        results.update(whiteboard_kinds(args.trials, kinds))
    if 'controller' in kinds:
        results.update(controller_kind(args.trials))
    if 'navigation' in kinds:
        results.update(navigation_kind(args.trials))
    report = {
        'benchmark': 'stop latency: /cap/stop to the program\'s end and to the robot at rest [s, wall time]',
        'trials': args.trials,
        'at_rest': f'joints and base slower than {AT_REST} rad/s or m/s, no controller driving a plant',
        'kinds': {kind: {'end_s': summary(results[kind], 'end_s'), 'rest_s': summary(results[kind], 'rest_s'),
                         'runs': results[kind]} for kind in KINDS if kind in results},
        'robot_call_past_time_limit_note': f'timed from the program\'s start + time_limit_s ({TIME_LIMIT_S:g} s), '
                                           'not from a stop',
        'worst_after_a_stop_s': max((run[key] for kind, runs in results.items() for run in runs
                                     for key in ('end_s', 'rest_s')
                                     if kind != 'robot_call_past_time_limit' and run[key] is not None),
                                    default=math.nan),
        'planning_5000_points_s': planning_seconds() if 'whiteboard_planning' in kinds else None,
        'machine_load_1min': round(os.getloadavg()[0], 2),
    }
    print(json.dumps(report, indent=2))


if __name__ == '__main__':
    main()
