"""Benchmark of the UR5e kinematics of cap_control: IK solve time, IK accuracy over the table, reach margins.

Prints one JSON object. Run: source scripts/env.sh && python benchmarks/kinematics.py
"""
from __future__ import annotations

import json
import math
import time

import numpy as np

from cap_control.kinematics import (
    HOME_JOINTS, forward_kinematics, inverse_kinematics, pose_error, top_down_pose, top_down_reach_margin,
)
from cap_control.pick_place.plan import ObjectInfo, plan_pick_place
from cap_tabletop.objects import BLOCK_SIZE
from cap_tabletop.workspace import (
    CORNERS, MIDDLE, SIDES, SPAWN_X_RANGE, SPAWN_Y_RANGE, TABLE_X_RANGE, TABLE_Y_RANGE, TABLE_Z,
)

POSES = 1000
TABLE_X, TABLE_Y = TABLE_X_RANGE, TABLE_Y_RANGE
BLOCK_CENTRE_HEIGHT = TABLE_Z + BLOCK_SIZE / 2
NAMED_POSITIONS = {**CORNERS, **SIDES, 'middle': MIDDLE}


def percentile_us(samples: list[float], q: float) -> float:
    return round(float(np.percentile(samples, q)) * 1e6, 1)


def main() -> None:
    rng = np.random.default_rng(0)
    poses = [top_down_pose((rng.uniform(*TABLE_X), rng.uniform(*TABLE_Y), rng.uniform(0.02, 0.3)),
                           rng.uniform(-math.pi, math.pi)) for _ in range(POSES)]
    for pose in poses[:100]:  # warm-up: first calls pay for imports and caches
        inverse_kinematics(pose)
    solve_times, position_errors, angle_errors = [], [], []
    for pose in poses:
        start = time.perf_counter()
        q = inverse_kinematics(pose)
        solve_times.append(time.perf_counter() - start)
        position_error, angle_error = pose_error(pose, forward_kinematics(q))
        position_errors.append(position_error)
        angle_errors.append(angle_error)

    grid = [(x, y) for x in np.linspace(*TABLE_X, 61) for y in np.linspace(*TABLE_Y, 61)]
    margins = [top_down_reach_margin((x, y, BLOCK_CENTRE_HEIGHT)) for x, y in grid]
    tightest = grid[int(np.argmin(margins))]

    plan_times = []
    for _ in range(20):
        obj = ObjectInfo('block', (rng.uniform(*SPAWN_X_RANGE), rng.uniform(*SPAWN_Y_RANGE), BLOCK_CENTRE_HEIGHT),
                         (BLOCK_SIZE,) * 3, yaw=rng.uniform(-math.pi, math.pi))
        start = time.perf_counter()
        plan = plan_pick_place(obj, (rng.uniform(-0.25, 0.25), rng.uniform(-0.75, -0.25)), HOME_JOINTS)
        plan_times.append(time.perf_counter() - start)

    print(json.dumps({
        'ik_poses': POSES,
        'ik_solve_us_p50': percentile_us(solve_times, 50),
        'ik_solve_us_p99': percentile_us(solve_times, 99),
        'ik_max_position_error_m': float(max(position_errors)),
        'ik_max_angle_error_deg': math.degrees(max(angle_errors)),
        'ik_poses_within_1mm_0.5deg': int(sum(p <= 1e-3 and math.degrees(a) <= 0.5
                                              for p, a in zip(position_errors, angle_errors))),
        'table_reach_margin_min_m': round(min(margins), 4),
        'table_reach_margin_min_at_xy': [round(v, 3) for v in tightest],
        'table_far_corner_distance_m': round(math.hypot(max(map(abs, TABLE_X)), max(map(abs, TABLE_Y))), 4),
        'named_position_reach_margin_m': {name: round(top_down_reach_margin((x, y, BLOCK_CENTRE_HEIGHT)), 4)
                                          for name, (x, y) in NAMED_POSITIONS.items()},
        'pick_place_plan_ms_p50': round(float(np.percentile(plan_times, 50)) * 1e3, 1),
        'pick_place_plan_ms_p99': round(float(np.percentile(plan_times, 99)) * 1e3, 1),
        'pick_place_planned_motion_s_last': round(plan.duration, 2),
    }, indent=2))


if __name__ == '__main__':
    main()
