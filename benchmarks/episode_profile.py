"""Where a table-top episode's wall time goes: py-spy samples the benchmark's graph process while it runs.

The graph runs every node in one process, whose threads share one interpreter lock on one CPU: what holds the lock
is what the episode waits for. This runs `cap bench tabletop` (one job, the oracle programs, ground-truth
perception; every row once by default) under `py-spy record --gil --subprocesses` (only the thread holding the
lock is sampled) and sorts each sample into one part:
- physics: the simulator's steps (`world.step`) as far as they hold the lock: the arm's references and
  feed-forward computed in Python at every step (MuJoCo's own stepping releases the lock and is not sampled);
- publishing: building and sending messages (/clock, /joint_states, objects, feedback);
- planning: pick-and-place plans (IK, Ruckig);
- otherwise the part of the deepest frame that is the project's or rclpy's: the simulator loop (the rest of
  sim_bridge: its physics loop, its action servers), the robot nodes (pick_place, perception, lmp_node; the
  sandbox process is not sampled: it does not hold the graph's lock), the benchmark client (the runner's resets,
  goals and checks), or rclpy (its executors: wait sets rebuilt in Python at every wake-up, dispatch to threads).
Prints one JSON object: the share of the sampled lock time per part, the samples, the episodes, their success and
the real-time factor (py-spy slows the process down: compare shares, not times, with an unprofiled run).

Run: source scripts/env.sh && ROS_DOMAIN_ID=95 python benchmarks/episode_profile.py [--trials 1] [--rate 200]
(py-spy needs ptrace: root, or kernel.yama.ptrace_scope 0)
"""
from __future__ import annotations

import argparse
import collections
import json
import os
import pathlib
import shutil
import subprocess
import sys
import tempfile

# A stack counts for the first of these parts that any of its frames shows...
SPECIFIC = (
    ('physics', 'World.step'),
    ('publishing', 'Publisher.publish'),
    ('publishing', '_joint_states'),
    ('planning', 'plan_pick_place'),
)
# ...else for the part of its deepest frame among these (the graph's thread wrappers aside).
GENERIC = (
    ('simulator loop', 'cap_sim_bridge/'),
    ('robot nodes', 'cap_control/'),
    ('robot nodes', 'cap_perception/'),
    ('robot nodes', 'cap_lmp/'),
    ('robot nodes', 'cap_lmp_ros/'),
    ('benchmark client', 'cap_bench/'),
    ('rclpy', 'rclpy/'),
)
WRAPPERS = ('thread_watch.py', 'cap_bringup/graph.py')


def part_of(stack: str) -> str:
    part = next((part for part, frame in SPECIFIC if frame in stack), None)
    if part is not None:
        return part
    for frame in reversed(stack.split(';')):
        if any(wrapper in frame for wrapper in WRAPPERS):
            continue
        part = next((part for part, where in GENERIC if where in frame), None)
        if part is not None:
            return part
    return 'other'


def summarise(raw: pathlib.Path) -> tuple[dict[str, float], int]:
    """Shares of the samples per part, from py-spy's raw (collapsed stacks) output."""
    counts: collections.Counter = collections.Counter()
    for line in raw.read_text().splitlines():
        stack, _, count = line.rpartition(' ')
        if 'spawn_main' not in stack or 'resource_tracker' in stack:
            continue  # the parent process and multiprocessing's helper: not the job's graph
        counts[part_of(stack)] += int(count)
    total = sum(counts.values())
    return {part: round(count / total, 3) for part, count in counts.most_common()}, total


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--trials', type=int, default=1, help='episodes per row of the table-top benchmark [1]')
    parser.add_argument('--rate', type=int, default=200, help='samples per second [200]')
    parser.add_argument('--keep', help='keep the raw profile and the run here (default: a temporary folder)')
    args = parser.parse_args()
    py_spy = shutil.which('py-spy')
    if py_spy is None:
        sys.exit('py-spy is not installed: make setup')
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    folder = pathlib.Path(args.keep) if args.keep else pathlib.Path(tempfile.mkdtemp(prefix='episode-profile-'))
    folder.mkdir(parents=True, exist_ok=True)
    raw, run = folder / 'profile.txt', folder / 'bench'
    shutil.rmtree(run, ignore_errors=True)
    subprocess.run([py_spy, 'record', '--gil', '--subprocesses', '--rate', str(args.rate), '--format', 'raw',
                    '--output', str(raw), '--', sys.executable, '-m', 'cap_bringup.cli', 'bench', 'tabletop',
                    '--trials', str(args.trials), '--jobs', '1', '--out', str(run)],
                   check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    records = [json.loads(line) for path in run.glob('episodes*.jsonl') for line in path.read_text().splitlines()]
    shares, samples = summarise(raw)
    wall = sum(r['wall_seconds'] for r in records)
    print(json.dumps({
        'lock_time_share': shares, 'samples': samples, 'rate_hz': args.rate,
        'episodes': len(records), 'succeeded': sum(bool(r['success']) for r in records),
        'episode_wall_s': round(wall, 1),
        'real_time_factor_profiled': round(sum(r['sim_seconds'] for r in records) / wall, 2) if wall else None,
        'raw_profile': str(raw) if args.keep else None,
    }, indent=2))
    if not args.keep:
        shutil.rmtree(folder, ignore_errors=True)


if __name__ == '__main__':
    main()
