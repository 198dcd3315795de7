"""What rehearsing every program on a twin costs: the table-top demo's commands (`make demo`) through the whole graph
with lmp_node's rehearse=always, the simulator in real time (so a real run takes what the UR5e takes), the twin
beside it in the same process as fast as it goes, on this machine's 2 cores.

Per command, from lmp_node's result (ExecuteCommand): twin_build_s (the twin reset to the scene as perceived, its
perception waited for; before the command's own clock), rehearsal_s (the program's whole run on the twin, its harm
checks and final report included), real_s (the rest of the command's total_seconds: the run on the robot at the
UR5e's speed) and share = (build + rehearsal) / real for the commands that moved the robot. Also the twin's world
alone: resetting a MuJoCo world to the demo's scene and settling it (no ROS), median of --resets.

Run: source scripts/env.sh && ROS_DOMAIN_ID=93 python benchmarks/rehearsal_cost.py [--out output/rehearsal-cost]
Prints JSON.
"""
from __future__ import annotations

import argparse
import json
import os
import pathlib
import statistics
import sys
import time

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')  # no DDS traffic leaves this host


def _world_reset_seconds(resets: int) -> float:
    from cap_bringup.demos.tabletop import SCENE
    from cap_sim_bridge.objects import ObjectSpec
    from cap_sim_bridge.twin_watch import TwinWatch
    from cap_sim_bridge.world import World

    specs = [ObjectSpec(name, name.split()[1], name.split()[0], tuple(xy)) for name, xy in SCENE.items()]
    world = World('tabletop', 0, specs)
    watch = TwinWatch(world)
    times = []
    for _ in range(resets):
        started = time.perf_counter()
        world.reset(0, specs, arm_joints=world.joint_positions())
        watch.start()
        times.append(time.perf_counter() - started)
    world.close()
    return statistics.median(times)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--out', type=pathlib.Path, default=pathlib.Path('output') / 'rehearsal-cost')
    parser.add_argument('--resets', type=int, default=20)
    args = parser.parse_args(argv)

    from cap_bringup.demos._support import DemoRun, placed_objects
    from cap_bringup.demos.tabletop import DEMO_CASSETTE, SCENE, STEPS

    rows = []
    with DemoRun(args.out, len(STEPS), name='rehearsal_cost', log=lambda *_: None, video=False, seed=0,
                 objects=', '.join(SCENE), cassette=str(DEMO_CASSETTE), real_time=True, rehearse='always') as run:
        run.wait_for_model()
        run.reset_scene(placed_objects(SCENE, {name: (name.split()[1], name.split()[0]) for name in SCENE}))
        run.wait_for_perception(SCENE)
        for step in STEPS:
            ran = run.run_command(step.command)
            result = ran.result
            real = result.total_seconds - result.rehearsal_seconds  # the build comes before that clock
            rows.append({'command': step.command, 'outcome': ran.outcome, 'rehearsed': result.rehearsed,
                         'twin_build_s': round(result.twin_build_seconds, 3),
                         'rehearsal_s': round(result.rehearsal_seconds, 3), 'real_s': round(real, 3),
                         'prediction': result.prediction})
            print(json.dumps(rows[-1]), file=sys.stderr)
    moved = [row for row in rows if row['outcome'] == 'done' and row['real_s'] > 1.0]
    shares = [(row['twin_build_s'] + row['rehearsal_s']) / row['real_s'] for row in moved]
    summary = {
        'commands': rows,
        'twin_world_reset_s_median': round(_world_reset_seconds(args.resets), 4),
        'twin_build_s_median': round(statistics.median(row['twin_build_s'] for row in rows if row['rehearsed']), 3),
        'rehearsal_s_median': round(statistics.median(row['rehearsal_s'] for row in rows if row['rehearsed']), 3),
        'share_of_real_motion_median': round(statistics.median(shares), 3) if shares else None,
        'share_of_real_motion_max': round(max(shares), 3) if shares else None,
        'share_of_real_motion_all': round(sum(r['twin_build_s'] + r['rehearsal_s'] for r in moved)
                                          / sum(r['real_s'] for r in moved), 3) if moved else None,
        'commands_moving_the_robot': len(moved),
    }
    print(json.dumps(summary))
    return 0


if __name__ == '__main__':
    sys.exit(main())
