"""The kitchen in MuJoCo: real-time factor of the full scene, and navigation driven through the physics.

No ROS: the navigation executor (planner, path follower, timed trajectory; cap_control.navigation.executor) drives
the simulated base through a port that runs the world itself, from location to location in a seeded random order.
Per drive: the base's final position and heading error against the goal, the planned duration, and the simulated
time over the wall time it took (the real-time factor while the base drives and the arm holds its stowed pose).
Also the real-time factor at rest and with the head camera rendered at 640x480 (10 and 2 frames a second of
simulated time). One core is used.

Prints one JSON object. Run: source scripts/env.sh && python benchmarks/mobile_sim.py [--drives 30]
"""
from __future__ import annotations

import argparse
import json
import math
import random
import time
from concurrent.futures import Future

import numpy as np
from cap_mobile import layout, robot

from cap_control.navigation.plan import wrap_angle
from cap_control.navigation.executor import Base, NavigateRequest, NavigationExecutor
from cap_control.ports import ArmOutcome, ArmResult, Ending, Interruption, PendingGoal
from cap_sim_bridge.world import World


def _done(value=None) -> Future:
    future: Future = Future()
    future.set_result(value)
    return future


class _Finished(PendingGoal):
    def __init__(self, outcome: ArmOutcome):
        self._result = _done(outcome)

    @property
    def accepted(self) -> Future:
        return _done(True)

    @property
    def result(self) -> Future:
        return self._result

    def cancel(self) -> Future:
        return _done()


class WorldBase(Base):
    """The simulated base, stepped in the calling thread until each trajectory ends (and 0.5 s more to settle)."""

    server_description = 'the simulated base'

    def __init__(self, world: World):
        self.world = world
        self.simulated = 0.0  # [s] while driving
        self.wall = 0.0

    def server_ready(self) -> Future:
        return _done()

    def pose(self) -> Future:
        return _done(self.world.base_pose())

    def latest_pose(self) -> np.ndarray:
        return self.world.base_pose()

    def follow(self, times, positions, velocities, path_tolerance) -> PendingGoal:
        world = self.world
        started, start_time = time.perf_counter(), world.time
        end = world.follow_base_trajectory(times, positions, velocities)
        worst = 0.0
        while world.time < end + 0.5:
            world.run_for(0.05)
            worst = max(worst, float(np.abs(world.base_pose() - world.base_reference()[0]).max()))
        self.simulated += world.time - start_time
        self.wall += time.perf_counter() - started
        if worst > path_tolerance:
            return _Finished(ArmOutcome(ArmResult.TOLERANCE_VIOLATED, f'tracking error {worst:.3f}'))
        return _Finished(ArmOutcome(ArmResult.SUCCEEDED))


def _stats(values) -> dict:
    values = np.asarray(values, dtype=float)
    return {'median': round(float(np.median(values)), 4), 'p90': round(float(np.percentile(values, 90)), 4),
            'max': round(float(values.max()), 4)}


def _rtf(world: World, seconds: float, camera_rate: float = 0.0) -> float:
    started, start_time = time.perf_counter(), world.time
    next_frame = world.time
    while world.time < start_time + seconds:
        world.run_for(0.01)
        if camera_rate > 0 and world.time >= next_frame:
            world.render(robot.HEAD_CAMERA, 640, 480)
            next_frame += 1.0 / camera_rate
    return (world.time - start_time) / (time.perf_counter() - started)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--drives', type=int, default=30)
    parser.add_argument('--seed', type=int, default=0)
    args = parser.parse_args()
    world = World('mobile', seed=args.seed)
    base = WorldBase(world)
    executor = NavigationExecutor(base)
    rng = random.Random(args.seed)
    position_errors, yaw_errors, durations, failures = [], [], [], []
    here = None
    for _ in range(args.drives):
        name = rng.choice([n for n in layout.LOCATION_NAMES if n != here])
        simulated_before = base.simulated
        outcome = executor.run(NavigateRequest(location_name=name), Interruption())
        if outcome.ending != Ending.SUCCEEDED:
            failures.append(f'{name}: {outcome.message}')
            continue
        here = name
        goal = layout.location(name).approach()
        pose = world.base_pose()
        position_errors.append(math.dist(pose[:2], goal[:2]))
        yaw_errors.append(abs(wrap_angle(pose[2] - goal[2])))
        durations.append(base.simulated - simulated_before)
    print(json.dumps({
        'drives': args.drives, 'reached': len(position_errors), 'failures': failures,
        'goal_position_error_m': _stats(position_errors), 'goal_yaw_error_rad': _stats(yaw_errors),
        'drive_s_simulated': _stats(durations),
        'real_time_factor': {
            'driving': round(base.simulated / base.wall, 1),
            'at_rest': round(_rtf(world, 10.0), 1),
            'head_camera_2hz': round(_rtf(world, 10.0, camera_rate=2.0), 1),
            'head_camera_10hz': round(_rtf(world, 5.0, camera_rate=10.0), 1),
        },
        'model': {'bodies': world.model.nbody, 'geoms': world.model.ngeom, 'dofs': world.model.nv,
                  'timestep_s': world.timestep},
    }, indent=2))


if __name__ == '__main__':
    main()
