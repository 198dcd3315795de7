"""Place accuracy of pick-and-place on open table: random relative moves through the running graph.

The graph is the robot part of the one `cap up` brings up: the sim bridge with MuJoCo, perception and pick_place,
composed in one process and talking over DDS, with their default parameters (as fast as possible, cameras
rendering at 10 Hz, like `cap up`). Each move is what "move the <block> <d> cm to the <direction>" makes generated
code do: read the block's position, add an offset, put_first_on_second(block, position + offset), here as a
PickPlace goal sent straight to the action. A move picks a random block, a random direction and a distance of
3-15 cm, keeps the target inside the range pick_place allows (the whole block on the table) and clear of the other
objects (open table), and the error is measured on the simulator's ground truth once the block has come to rest.

Prints one JSON object: n, median_cm, p90_cm, max_cm (xy error of the moves that succeeded), max_tilt_deg,
failures (moves whose result was not success, with their messages and errors), seed, and the run's settings.

Run: source scripts/env.sh && ROS_DOMAIN_ID=77 python benchmarks/place_accuracy.py [--moves 50] [--seed 3]
     [--perception rgbd] [--real-time] [--camera-rate 0]
"""
from __future__ import annotations

import argparse
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
from rclpy.executors import MultiThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402

from cap_bringup.cpu_affinity import pin_to_one_cpu  # noqa: E402
from cap_control.pick_place.plan import ObjectInfo, allowed_target_range, yaw_of_quaternion  # noqa: E402
from cap_control.pick_place.node import PickPlaceNode  # noqa: E402
from cap_interfaces.action import PickPlace  # noqa: E402
from cap_interfaces.msg import GraphNames  # noqa: E402
from cap_perception.perception_node import PerceptionNode  # noqa: E402
from cap_sim_bridge.bridge_node import SimBridgeNode  # noqa: E402

DISTANCE = (0.03, 0.15)  # [m] of one relative move
# Room between the target and any other object's footprint: the held block and the open fingers pass clear.
OPEN_TABLE_ROOM = 0.05  # [m]
SETTLE = 0.5  # [s of simulated time] after a place before the block is measured


def wait(predicate, timeout: float = 120.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise TimeoutError('benchmark step timed out')
        time.sleep(0.002)


def footprint_radius(state) -> float:
    return float(np.linalg.norm(np.asarray(state.bbox_max[:2]) - np.asarray(state.bbox_min[:2]))) / 2


def tilt_deg(state) -> float:
    """Angle between the block's nearest-to-vertical face normal and world z."""
    up = Rotation.from_quat(state.orientation_xyzw).inv().apply([0.0, 0.0, 1.0])
    return math.degrees(math.acos(min(1.0, float(np.max(np.abs(up))))))


def draw_move(rng: np.random.Generator, world, pick_place_config) -> tuple[str, tuple[float, float]] | None:
    """A random block and a target 3-15 cm away from it, on the table and clear of the other objects."""
    states = {state.name: state for state in world.object_states()}
    blocks = [name for name, state in states.items() if state.category == 'block']
    for _ in range(200):
        name = str(rng.choice(blocks))
        block = states[name]
        angle = rng.uniform(0.0, 2 * math.pi)
        distance = rng.uniform(*DISTANCE)
        target = (block.position[0] + distance * math.cos(angle), block.position[1] + distance * math.sin(angle))
        info = ObjectInfo.from_bounding_box(name, block.bbox_min, block.bbox_max, block.category,
                                            yaw_of_quaternion(*block.orientation_xyzw))
        (x_low, x_high), (y_low, y_high) = allowed_target_range(info, pick_place_config)
        if not (x_low <= target[0] <= x_high and y_low <= target[1] <= y_high):
            continue
        own = footprint_radius(block)
        if all(math.dist(target, other.position[:2]) >= own + footprint_radius(other) + OPEN_TABLE_ROOM
               for other_name, other in states.items() if other_name != name):
            return name, target
    return None


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument('--moves', type=int, default=50, help='relative moves to make [50]')
    parser.add_argument('--seed', type=int, default=3, help='scene seed, and the seed of the moves drawn [3]')
    parser.add_argument('--real-time', action='store_true', help='simulate in real time (default: as fast as '
                        'possible, as `cap up` does)')
    parser.add_argument('--camera-rate', type=float, default=10.0, help='camera images per simulated second, as '
                        '`cap up` renders them (0 = none) [10]')
    parser.add_argument('--perception', choices=('ground_truth', 'rgbd'), default='ground_truth',
                        help='what perception reports positions from, as `cap up --perception` [ground_truth]')
    args = parser.parse_args()

    pin_to_one_cpu(0)  # as the graph does (cap_bringup/cpu_affinity.py)
    context = Context()
    rclpy.init(context=context)
    bridge = SimBridgeNode(context=context, parameter_overrides=[
        Parameter('seed', value=args.seed), Parameter('real_time', value=args.real_time),
        Parameter('camera_rate', value=args.camera_rate)])
    perception = PerceptionNode(context=context, parameter_overrides=[Parameter('source', value=args.perception)])
    # A camera sees a fresh stack only once the tool has moved out of its line of sight (as `cap up` sets it).
    pick_place = PickPlaceNode(context=context, parameter_overrides=[
        Parameter('clear_view', value=args.perception == 'rgbd')])
    node = rclpy.create_node('place_accuracy_benchmark', context=context)
    nodes = (bridge, perception, pick_place, node)
    executor = MultiThreadedExecutor(num_threads=8, context=context)
    for each in nodes:
        executor.add_node(each)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    world = bridge.world
    config = pick_place.config
    rng = np.random.default_rng(args.seed)
    errors, tilts, failures = [], [], []
    started = time.monotonic()
    try:
        action = ActionClient(node, PickPlace, GraphNames.PICK_PLACE_ACTION)
        wait(action.server_is_ready)
        wait(lambda: bool(perception.source.objects()))
        for index in range(args.moves):
            move = draw_move(rng, world, config)
            if move is None:
                failures.append({'move': index, 'message': 'no open-table target found for any block'})
                break
            name, target = move
            goal = action.send_goal_async(PickPlace.Goal(object_name=name, target_position=Point(
                x=float(target[0]), y=float(target[1]), z=0.0)))
            wait(goal.done)
            result_future = goal.result().get_result_async()
            wait(result_future.done, 300.0)
            result = result_future.result().result
            settled_at = world.time + SETTLE
            wait(lambda: world.time >= settled_at)
            state = world.object_state(name)
            error = math.dist(state.position[:2], target)
            if result.error_code != PickPlace.Result.NONE:
                failures.append({'move': index, 'block': name, 'target': [round(v, 4) for v in target],
                                 'error_cm': round(error * 100, 2), 'message': result.error_msg})
                continue
            errors.append(error * 100)
            tilts.append(tilt_deg(state))
    finally:
        executor.shutdown(timeout_sec=5.0)
        spinner.join(timeout=5.0)
        for each in reversed(nodes):
            each.destroy_node()
        context.try_shutdown()
    values = np.array(errors) if errors else np.array([math.nan])
    print(json.dumps({
        'n': len(errors), 'median_cm': round(float(np.median(values)), 3),
        'p90_cm': round(float(np.percentile(values, 90)), 3), 'max_cm': round(float(np.max(values)), 3),
        'max_tilt_deg': round(max(tilts, default=math.nan), 2), 'n_failures': len(failures), 'failures': failures,
        'seed': args.seed,
        'simulation': 'real time' if args.real_time else 'as fast as possible', 'camera_rate': args.camera_rate,
        'perception': args.perception,
        'wall_s': round(time.monotonic() - started, 1)}, indent=2))


if __name__ == '__main__':
    main()
