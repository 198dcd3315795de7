"""Pick-and-place cycle time through the running graph: random picks and places, where the simulated time goes.

Each cycle resets the scene with a new seed (the table top's default episode: blocks and bowls), picks a random
block and places it on a random bowl, another block or a free corner of the table (in turn), through the
PickPlace action of the graph (sim bridge, perception, pick_place in this process, the simulator as fast as
possible with --fast, else in real time as a robot runs). Prints one JSON object with:
- cycle_sim_s: simulated seconds from the goal's sending to its result: median, p10, p90, max;
- stage_sim_s: median simulated seconds of each stage (from its feedback to the next stage's feedback);
- succeeded: results without an error whose object ended where asked (within 0.06 m of a bowl's or corner's
  centre, within 0.04 m of a block and above it) with no other object moved more than 0.05 m;
- failures: what went wrong, per cycle;
- wall_s and the real-time factor of the cycles.

Run: source scripts/env.sh && ROS_DOMAIN_ID=93 python benchmarks/pick_place_cycle.py [--cycles 50] [--perception rgbd]
"""
from __future__ import annotations

import argparse
import collections
import json
import math
import os
import threading
import time

import numpy as np

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

import rclpy  # noqa: E402  (after the environment is set)
from geometry_msgs.msg import Point  # noqa: E402
from rclpy.action import ActionClient  # noqa: E402
from rclpy.context import Context  # noqa: E402

from cap_bringup.graph import Graph, GraphOptions  # noqa: E402
from cap_interfaces.action import PickPlace  # noqa: E402
from cap_interfaces.msg import GraphNames  # noqa: E402
from cap_interfaces.srv import ResetScene  # noqa: E402
from cap_tabletop.workspace import CORNERS as TABLE_CORNERS  # noqa: E402

CORNERS = list(TABLE_CORNERS.values())

STAGE_NAMES = ('approach', 'descend', 'grasp', 'verify', 'lift', 'move', 'place', 'release', 'retreat')


def wait_future(future, timeout=300.0):
    """Block on a done callback (not by polling, which would compete with the graph's threads)."""
    done = threading.Event()
    future.add_done_callback(lambda _: done.set())
    if not done.wait(timeout):
        raise TimeoutError('benchmark step timed out')
    return future.result()


def let_time_pass(world, seconds: float) -> None:
    """Wait while the simulator (running on its own thread) advances `seconds` of simulated time."""
    until = world.time + seconds
    while world.time < until:
        time.sleep(0.01)


def placed_where_asked(world, picked: str, target_name: str, corner, start: dict) -> str | None:
    """None when the object ended where asked and nothing else moved; else what is wrong."""
    moved = world.object_state(picked).position
    if corner is not None:
        ok = math.dist(moved[:2], corner) <= 0.06
    else:
        below = world.object_state(target_name).position
        limit = 0.04 if 'block' in target_name else 0.06
        ok = math.dist(moved[:2], below[:2]) <= limit and (moved[2] > below[2] or 'bowl' in target_name)
    others = [name for name, position in start.items() if name not in (picked, target_name)
              and math.dist(world.object_state(name).position[:2], position[:2]) > 0.05]
    if not ok:
        return f'the {picked} ended at {np.round(moved, 3).tolist()}'
    if others:
        return f'moved: {", ".join(others)}'
    return None


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument('--cycles', type=int, default=50, help='pick-and-place cycles [50]')
    parser.add_argument('--perception', choices=('ground_truth', 'rgbd'), default='ground_truth')
    parser.add_argument('--seed', type=int, default=1000, help='scene seed of the first cycle [1000]')
    parser.add_argument('--fast', action='store_true', help='simulate as fast as possible (default: real time, as a '
                        'robot runs; as fast as possible, the graph\'s messaging between steps costs simulated time '
                        'at the real-time factor)')
    args = parser.parse_args()
    context = Context()
    rclpy.init(context=context)
    graph = Graph(context, GraphOptions(seed=args.seed, perception=args.perception,
                                        camera_rate=10.0 if args.perception == 'rgbd' else 0.0,
                                        real_time=not args.fast))
    node = rclpy.create_node('pick_place_cycle_benchmark', context=context)
    graph.executor.add_node(node)
    world = graph.world
    rng = np.random.default_rng(2026)
    cycles, failures = [], []
    stage_times: dict[str, list[float]] = collections.defaultdict(list)
    started = time.perf_counter()
    try:
        action = ActionClient(node, PickPlace, GraphNames.PICK_PLACE_ACTION)
        reset = node.create_client(ResetScene, GraphNames.SIM_RESET_SERVICE)
        if not (action.wait_for_server(timeout_sec=30.0) and reset.wait_for_service(timeout_sec=30.0)):
            raise TimeoutError('the graph did not come up')
        for index in range(args.cycles):
            answer = wait_future(reset.call_async(ResetScene.Request(seed=args.seed + index)))
            objects = {o.name: o for o in answer.objects}
            blocks = [n for n, o in objects.items() if o.category == 'block']
            bowls = [n for n, o in objects.items() if o.category == 'bowl']
            picked = str(rng.choice(blocks))
            kind = ('bowl', 'block', 'corner')[index % 3]
            free = [c for c in CORNERS if all(math.dist(c, (o.position.x, o.position.y)) > 0.12
                                              for o in objects.values())]
            kind = 'bowl' if kind == 'corner' and not free else kind
            goal = PickPlace.Goal(object_name=picked)
            corner = None
            if kind == 'corner':
                corner = free[int(rng.integers(len(free)))]
                goal.target_position = Point(x=float(corner[0]), y=float(corner[1]), z=0.0)
            else:
                goal.target_name = str(rng.choice(bowls if kind == 'bowl' else [b for b in blocks if b != picked]))
            let_time_pass(world, 0.3)  # perception's next report of the new scene
            start = {name: world.object_state(name).position for name in objects}
            marks: list[tuple[str, float]] = []

            def on_feedback(message, marks=marks) -> None:
                stage = message.feedback.stage
                if not marks or marks[-1][0] != stage:
                    marks.append((stage, world.time))

            sim_started, wall_started = world.time, time.perf_counter()
            handle = wait_future(action.send_goal_async(goal, feedback_callback=on_feedback))
            result = wait_future(handle.get_result_async()).result
            sim_s, wall_s = world.time - sim_started, time.perf_counter() - wall_started
            for (stage, at), (_, after) in zip(marks, marks[1:] + [('end', world.time)]):
                stage_times[stage].append(after - at)
            let_time_pass(world, 0.5)
            problem = (f'code {result.error_code}: {result.error_msg}' if result.error_code != PickPlace.Result.NONE
                       else placed_where_asked(world, picked, goal.target_name, corner, start))
            if problem:
                failures.append(f'cycle {index} (seed {args.seed + index}, {picked} -> '
                                f'{goal.target_name or "corner"}): {problem}')
            cycles.append({'sim_s': sim_s, 'wall_s': wall_s, 'ok': problem is None})
    finally:
        graph.close()
        node.destroy_node()
        context.try_shutdown()
    sims = np.array([c['sim_s'] for c in cycles])
    print(json.dumps({
        'machine_load_1min': round(os.getloadavg()[0], 2), 'perception': args.perception,
        'simulation': 'as fast as possible' if args.fast else 'real time',
        'cycles': len(cycles), 'succeeded': sum(c['ok'] for c in cycles),
        'cycle_sim_s': {'median': round(float(np.median(sims)), 2), 'p10': round(float(np.percentile(sims, 10)), 2),
                        'p90': round(float(np.percentile(sims, 90)), 2), 'max': round(float(sims.max()), 2)},
        'stage_sim_s': {stage: round(float(np.median(stage_times[stage])), 3) for stage in STAGE_NAMES
                        if stage in stage_times},
        'real_time_factor': round(float(sims.sum() / sum(c['wall_s'] for c in cycles)), 2),
        'wall_s': round(time.perf_counter() - started, 1),
        'failures': failures}, indent=2))


if __name__ == '__main__':
    main()
