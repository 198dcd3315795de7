"""What an idle graph costs: `cap up` (sim bridge, perception, pick-and-place, lmp_node in one process) started
as a user starts it, left alone, and its processes' CPU time measured.

Prints one JSON object: per mode (`cap up` in real time, its default, and `cap up --fast`), the percent of one core
the graph's processes used over the measuring window, after a settling time. The replay cassette is the language
model (a local model server would add its own idle cost, about zero).

Run: source scripts/env.sh && ROS_DOMAIN_ID=91 python benchmarks/idle_cpu.py [--settle 20] [--seconds 30]
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import time

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
CLOCK_TICKS = os.sysconf('SC_CLK_TCK')


def session_cpu_seconds(session: int) -> float:
    """User and system CPU time of every live process of a session."""
    total = 0
    for entry in os.listdir('/proc'):
        if not entry.isdigit():
            continue
        try:
            with open(f'/proc/{entry}/stat', encoding='ascii') as stat:
                fields = stat.read().rsplit(')', 1)[1].split()
        except OSError:
            continue  # ended meanwhile
        if int(fields[3]) == session:  # fields after the name: state, ppid, pgrp, session, ...
            total += int(fields[11]) + int(fields[12])  # utime, stime
    return total / CLOCK_TICKS


def measure(extra: list[str], settle: float, seconds: float) -> dict[str, float]:
    graph = subprocess.Popen([sys.executable, '-m', 'cap_bringup.cli', 'up', '--backend', 'cassette', *extra],
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        time.sleep(settle)
        if graph.poll() is not None:
            raise SystemExit(f'cap up {" ".join(extra)} exited with {graph.returncode}')
        before, started = session_cpu_seconds(graph.pid), time.monotonic()
        time.sleep(seconds)
        used, elapsed = session_cpu_seconds(graph.pid) - before, time.monotonic() - started
    finally:
        os.killpg(graph.pid, signal.SIGINT)
        try:
            graph.wait(30)
        except subprocess.TimeoutExpired:
            os.killpg(graph.pid, signal.SIGKILL)
    return {'percent_of_one_core': round(100 * used / elapsed, 2), 'cpu_seconds': round(used, 3),
            'wall_seconds': round(elapsed, 1)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--settle', type=float, default=20.0, help='seconds after start before measuring [20]')
    parser.add_argument('--seconds', type=float, default=30.0, help='measuring window [30]')
    args = parser.parse_args()
    report = {'settle_seconds': args.settle,
              'real_time': measure([], args.settle, args.seconds),
              'fast': measure(['--fast'], args.settle, args.seconds)}
    print(json.dumps(report, indent=2))


if __name__ == '__main__':
    main()
