"""Benchmark of drawing on the whiteboard (no ROS): how closely the tool tip follows the commanded path, how long a
line takes, and how fast the simulation runs with the ink being laid.

For each shape (a 20 cm line, a 10 cm square, a circle of radius 5 cm, each at the default tool speed 0.1 m/s and at
0.2 m/s), the path is planned by cap_control.follow_path.plan and run in the MuJoCo world of the whiteboard scene:
- tracking error: while the marker follows a stroke, the distance in the board's plane from the simulated tip (the
  sphere's centre, where the physics puts it) to the commanded stroke [mm], median / 95th percentile /
  max over all steps in contact;
- ink error: the ink's distance to the target (cap_bench.whiteboard.ink_check), mean / 95th percentile [mm];
- time per 10 cm: the simulated duration of the follow motion of the 20 cm line divided by two [s], and of the
  whole command (travel, landing, line, lift, park);
- real-time factor with ink on: simulated seconds per wall second of the whole run, physics, trajectory sampling
  and the per-step contact scan that lays the ink included (one core, no rendering).

Prints one JSON object. Run: source scripts/env.sh && python benchmarks/whiteboard_path.py
"""
from __future__ import annotations

import json
import os
import time

os.environ.setdefault('MUJOCO_GL', 'egl')

import numpy as np  # noqa: E402

from cap_bench.whiteboard import shapes  # noqa: E402
from cap_bench.whiteboard.ink_check import check_drawing, distance_to_polylines  # noqa: E402
from cap_control.follow_path.plan import PathConfig, StepKind, plan_path  # noqa: E402
from cap_sim_bridge.world import World  # noqa: E402
from cap_whiteboard import board, tool  # noqa: E402

SHAPES = {
    'line_20cm': np.array([[-0.1, -0.5], [0.1, -0.5]]),
    'square_10cm': shapes.square_around(board.MIDDLE, 0.05),
    'circle_r5cm': shapes.circle(board.MIDDLE, 0.05),
}
SPEEDS = (0.1, 0.2)
STEPS_PER_CHUNK = 5  # the bridge steps 10 ms at a time


def run(world: World, shape: np.ndarray, speed: float) -> dict:
    world.reset(0, ['red block'])
    world.ink_canvas.clear()
    plan = plan_path(world.joint_positions(), [shape], tool.TOOL_MARKER, speed)
    tip_geom = world.model.geom('marker_tip').id
    errors = []
    wall = time.perf_counter()
    sim_start = world.time
    follow_seconds = 0.0
    for step in plan.steps:
        trajectory = step.trajectory
        if len(trajectory) < 2:
            continue
        world.follow_trajectory(trajectory.times[1:], trajectory.positions[1:], trajectory.velocities[1:])
        end = world.trajectory_end_time
        while world.time < end + 0.05:
            world.step(STEPS_PER_CHUNK)
            if step.kind == StepKind.FOLLOW:
                tip = world.data.geom_xpos[tip_geom][:2]
                errors.append(float(distance_to_polylines(tip[None], [shape])[0]) * 1000)
        if step.kind == StepKind.FOLLOW:
            follow_seconds = trajectory.duration
    wall = time.perf_counter() - wall
    ink = check_drawing(world.ink_canvas.image(), [shape])
    errors = np.array(errors)
    return {'tracking_error_mm': {'median': round(float(np.median(errors)), 3),
                                  'p95': round(float(np.percentile(errors, 95)), 3),
                                  'max': round(float(errors.max()), 3)},
            'ink_error_mm': {'mean': round(ink.mean_mm, 3), 'p95': round(ink.p95_mm, 3)},
            'ink_coverage': round(ink.coverage, 4),
            'follow_seconds': round(follow_seconds, 3), 'command_seconds': round(plan.duration, 3),
            'real_time_factor': round((world.time - sim_start) / wall, 2)}


def main() -> None:
    if hasattr(os, 'sched_setaffinity'):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    world = World('whiteboard', seed=0, objects=['red block'])
    results = {f'{name}@{speed}m/s': run(world, shape, speed) for name, shape in SHAPES.items() for speed in SPEEDS}
    line = {speed: results[f'line_20cm@{speed}m/s'] for speed in SPEEDS}
    print(json.dumps({
        'benchmark': 'whiteboard path following',
        'default_speed_m_s': PathConfig().speed,
        'results': results,
        'seconds_per_10cm_of_line': {f'{speed}m/s': round(line[speed]['follow_seconds'] / 2, 3) for speed in SPEEDS},
        'real_time_factor_with_ink': round(float(np.median([r['real_time_factor'] for r in results.values()])), 2),
        'load_average_1min': round(os.getloadavg()[0], 2),
    }, indent=2))


if __name__ == '__main__':
    main()
