"""Planning on the kitchen's occupancy grid and following the plan (cap_control.navigation.plan; no ROS, no simulator).

Random pairs of free start and goal poses in the kitchen (seeded): the grid is built once from the furniture's
footprints and inflated by the base's radius plus a margin; for each pair the planner's time, the path's length
over the straight line between them (a lower bound of the shortest free path: the figure is at least 1), and,
driving the plan with the path follower on an ideal base (its commands integrated exactly, 100 Hz), the final
position and heading errors and the driving time. The base's physics (wheels, servos, contacts) is not in these
figures.

Prints one JSON object. Run: source scripts/env.sh && python benchmarks/navigation_plan.py [--pairs 200]
"""
from __future__ import annotations

import argparse
import json
import math
import random
import time

import numpy as np
from cap_mobile.layout import BASE_RADIUS, FURNITURE, ROOM_X_RANGE, ROOM_Y_RANGE

from cap_control.navigation.plan import (
    NavigationError, OccupancyGrid, PathFollower, follow_on_ideal_base, path_length, plan_path, wrap_angle,
)

MARGIN = 0.05  # [m] planned clearance beyond the base's radius
DT = 0.01  # [s] follower period


def _stats(values) -> dict:
    values = np.asarray(values, dtype=float)
    return {'median': round(float(np.median(values)), 4), 'p90': round(float(np.percentile(values, 90)), 4),
            'max': round(float(values.max()), 4)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--pairs', type=int, default=200)
    parser.add_argument('--seed', type=int, default=0)
    args = parser.parse_args()
    started = time.perf_counter()
    grid = OccupancyGrid.from_boxes([piece.footprint for piece in FURNITURE], ROOM_X_RANGE, ROOM_Y_RANGE) \
        .inflated(BASE_RADIUS + MARGIN)
    grid_s = time.perf_counter() - started
    rng = random.Random(args.seed)

    def free_pose():
        while True:
            x, y = rng.uniform(*ROOM_X_RANGE), rng.uniform(*ROOM_Y_RANGE)
            if grid.is_free((x, y)):
                return (x, y, rng.uniform(-math.pi, math.pi))

    plan_ms, ratios, position_errors, yaw_errors, drive_s, unreachable = [], [], [], [], [], 0
    for _ in range(args.pairs):
        start, goal = free_pose(), free_pose()
        t0 = time.perf_counter()
        try:
            path = plan_path(grid, start, goal)
        except NavigationError:
            unreachable += 1
            continue
        plan_ms.append((time.perf_counter() - t0) * 1000)
        straight = math.dist(start[:2], goal[:2])
        if straight > 0.5:
            ratios.append(path_length(path) / straight)
        poses, commands = follow_on_ideal_base(PathFollower(path, goal[2]), start, DT)
        end, seconds = poses[-1], (len(commands) - 1) * DT
        position_errors.append(math.dist(end[:2], goal[:2]))
        yaw_errors.append(abs(wrap_angle(end[2] - goal[2])))
        drive_s.append(seconds)
    rows, columns = grid.occupied.shape
    print(json.dumps({
        'grid': {'cells': [rows, columns], 'resolution_m': grid.resolution, 'build_and_inflate_ms':
                 round(grid_s * 1000, 2), 'inflation_m': BASE_RADIUS + MARGIN},
        'pairs': args.pairs, 'planned': len(plan_ms), 'unreachable': unreachable,
        'plan_ms': _stats(plan_ms),
        'path_over_straight_line': _stats(ratios),
        'goal_position_error_m': _stats(position_errors),
        'goal_yaw_error_rad': _stats(yaw_errors),
        'drive_s': _stats(drive_s),
        'wall_s': round(time.perf_counter() - started, 1),
    }, indent=2))


if __name__ == '__main__':
    main()
