"""The kitchen's RGB-D detector (cap_perception.detectors.mobile) on MuJoCo renders of the head camera.

Per seeded episode (the kitchen's default objects of the seed), the base drives by its servos from the start pose
to the approach pose of the table, the countertop and the desk (each a straight drive from the room's open middle)
and the detector reads one 640x480 frame there. Against the ground truth's `visible` (the simulator's ray test of
the head camera): precision (the objects found that the camera sees, under the right name), recall (the objects the
camera sees that are found), the position error of those found (3-D distance to the centre of the bounding box) and
the detector's time per frame. One core is used.

Prints one JSON object. Run: source scripts/env.sh && python benchmarks/mobile_detector.py [--episodes 30]
"""
from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np
from cap_mobile import layout, robot

from cap_perception.detectors.mobile import detect_kitchen
from cap_perception.rgbd import CameraView
from cap_sim_bridge.world import World

VIEWPOINTS = ('table', 'countertop', 'desk')
WIDTH, HEIGHT = 640, 480


def _stats(values, scale: float = 1.0) -> dict:
    values = np.asarray(values, dtype=float) * scale
    if not values.size:
        return {'median': None, 'p90': None, 'max': None}
    return {'median': round(float(np.median(values)), 2), 'p90': round(float(np.percentile(values, 90)), 2),
            'max': round(float(values.max()), 2)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--episodes', type=int, default=30)
    parser.add_argument('--first-seed', type=int, default=1000)
    args = parser.parse_args()
    world = World('mobile', seed=args.first_seed)
    found_total = true_found = seen_total = 0
    errors, seconds, misses, phantoms = [], [], [], []
    for seed in range(args.first_seed, args.first_seed + args.episodes):
        for place in VIEWPOINTS:
            world.reset(seed)
            goal = layout.location(place).approach()
            distance = math.dist(world.base_pose()[:2], goal[:2])
            end = world.follow_base_trajectory([distance / 0.4 + 1.0], [list(goal)])
            world.run_for(end - world.time + 0.5)
            rgb, depth = world.render(robot.HEAD_CAMERA, WIDTH, HEIGHT)
            view = CameraView(rgb, depth, world.camera_intrinsics(robot.HEAD_CAMERA, WIDTH, HEIGHT).matrix,
                              world.camera_pose(robot.HEAD_CAMERA))
            started = time.perf_counter()
            found = detect_kitchen(view)
            seconds.append(time.perf_counter() - started)
            seen = {state.name: state for state in world.object_states() if state.visible}
            found_total += len(found)
            seen_total += len(seen)
            for obj in found:
                if obj.name in seen:
                    true_found += 1
                    errors.append(math.dist(obj.position, seen[obj.name].position))
                else:
                    phantoms.append(f'{seed} {place}: {obj.name}')
            misses += [f'{seed} {place}: {name}' for name in sorted(set(seen) - {obj.name for obj in found})]
    world.close()
    print(json.dumps({
        'episodes': args.episodes, 'first_seed': args.first_seed, 'viewpoints': list(VIEWPOINTS),
        'frames': len(seconds), 'objects_in_view': seen_total, 'objects_found': found_total,
        'precision': round(true_found / max(found_total, 1), 4), 'recall': round(true_found / max(seen_total, 1), 4),
        'position_error_mm': _stats(errors, 1000.0), 'detection_ms_per_frame': _stats(seconds, 1000.0),
        'missed': misses, 'not_in_view_or_misnamed': phantoms,
    }, indent=2))


if __name__ == '__main__':
    main()
