"""Two benchmark jobs of unequal length: does the longer one keep its speed once the shorter one has ended?

A 2-job table-top run once slowed its remaining job to 0.2x real time after the other job finished (its process
at 100% CPU, nearly all system time). This runs two graphs side by side as the benchmark does (each in a process
of its own, on a DDS domain and a CPU of its own, oracle programs, ground-truth perception): job A runs `--long`
episodes, job B `--short` ones, so A goes on alone after B's graph has closed. For A it prints the real-time
factor (simulated over wall seconds) of its episodes that ended while B still ran and of those that began after B
ended; a ratio alone/together far below 1 is the slowdown coming back. (Alone, a job has the machine to itself and
is usually faster.)

Prints one JSON object. Run: source scripts/env.sh && ROS_DOMAIN_ID=96 python benchmarks/unequal_jobs.py
[--long 12] [--short 3]
"""
from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import pathlib
import tempfile
import time

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

from cap_bench.tabletop.bench import write_oracle_cassette  # noqa: E402  (after the environment is set)
from cap_bench.tabletop.options import TabletopOptions  # noqa: E402
from cap_bench.tabletop.runner import TabletopRunner, episode_graph  # noqa: E402
from cap_bench.tabletop.sampling import episode_for_key, sample_episode  # noqa: E402
from cap_bench.tabletop.templates import GROUPS  # noqa: E402


def _job(name: str, keys: list[str], domain_id: int, cpu: int, cassette: str, results) -> None:
    os.environ['ROS_DOMAIN_ID'] = str(domain_id)
    options = TabletopOptions(trials=len(keys), jobs=1)
    graph = episode_graph(options, lambda: TabletopRunner(options, pathlib.Path(cassette), cpu=cpu))
    try:
        for key in keys:
            started = time.monotonic()
            record = graph.run(episode_for_key(key))
            results.put((name, key, started, time.monotonic(), record['sim_seconds'], record['success']))
    finally:
        graph.close()
        results.put((name, None, None, time.monotonic(), None, None))


def _rtf(rows: list[tuple]) -> float | None:
    wall = sum(end - start for _, _, start, end, _, _ in rows)
    return round(sum(row[4] for row in rows) / wall, 2) if wall > 0 else None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--long', type=int, default=12, help='episodes of job A [12]')
    parser.add_argument('--short', type=int, default=3, help='episodes of job B [3]')
    args = parser.parse_args()
    base = int(os.environ.get('ROS_DOMAIN_ID', '96'))
    # The benchmark's rows in turn (every template, seeds counting up), as a run's jobs take them.
    rows = [(group, template) for group, (_, templates) in GROUPS.items() for template in templates]
    episodes = [sample_episode(*rows[i % len(rows)], i // len(rows)) for i in range(args.long + args.short)]
    keys = [e.key for e in episodes]
    with tempfile.TemporaryDirectory() as folder:
        cassette = pathlib.Path(folder) / 'oracle.yaml'
        write_oracle_cassette(episodes, cassette)
        context = multiprocessing.get_context('spawn')
        results = context.Queue()
        jobs = [context.Process(target=_job, args=('A', keys[:args.long], base, 0, str(cassette), results)),
                context.Process(target=_job, args=('B', keys[args.long:], base + 1, 1, str(cassette), results))]
        started = time.monotonic()
        for job in jobs:
            job.start()
        records, closed = [], {}
        while len(closed) < 2:
            name, key, start, end, sim, success = results.get(timeout=1800)
            if key is None:
                closed[name] = end
            else:
                records.append((name, key, start, end, sim, success))
        for job in jobs:
            job.join()
    b_closed = closed['B']
    a_rows = [row for row in records if row[0] == 'A']
    together = [row for row in a_rows if row[3] <= b_closed]
    alone = [row for row in a_rows if row[2] >= b_closed]
    together_rtf, alone_rtf = _rtf(together), _rtf(alone)
    print(json.dumps({
        'episodes': {'A': len(a_rows), 'B': len(records) - len(a_rows)},
        'succeeded': sum(1 for row in records if row[5]),
        'b_closed_after_s': round(b_closed - started, 1),
        'a_rtf_while_b_ran': together_rtf, 'a_episodes_while_b_ran': len(together),
        'a_rtf_after_b_ended': alone_rtf, 'a_episodes_after_b_ended': len(alone),
        'alone_over_together': round(alone_rtf / together_rtf, 2) if together_rtf and alone_rtf else None,
        'wall_s': round(time.monotonic() - started, 1),
    }, indent=2))


if __name__ == '__main__':
    main()
