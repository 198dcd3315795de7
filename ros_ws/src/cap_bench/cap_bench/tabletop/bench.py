"""`cap bench tabletop`: the paper's simulated table-top benchmark through the real graph.

Every episode goes the way of a user's command: the scene is reset through the sim bridge's service, the
instruction is sent to lmp_node's /cap/execute action, the program (an oracle reference program replayed from a
cassette, or a model's code from an OpenAI-compatible endpoint) runs in the sandbox and drives perception and
pick-and-place over ROS, and the result is judged on the simulator's final state by cap_bench.tabletop.success.

Results are appended to episodes.jsonl as each episode ends, so an interrupted run resumes where it stopped
(--resume). Parallel jobs run separate graphs in separate processes (local_executor.py) or Ray tasks
(ray_executor.py), each on its own ROS_DOMAIN_ID: with ROS_DOMAIN_ID set in the environment, job i
(0 <= i < --jobs) uses ROS_DOMAIN_ID + i, so `--jobs 4` with ROS_DOMAIN_ID=20 occupies domains 20-23; without it
the first id is derived from the process id (in 1..101, the ids whose DDS ports stay below Linux's ephemeral range).

SIGINT (Ctrl-C) or SIGTERM stops the run: the workers close their graphs, the episodes finished so far stay in
episodes*.jsonl, and the command exits 130 or 143 (continue later with --resume).
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import pathlib
import time
from typing import Callable, Iterable, Iterator

from cap_bench.bench_options import policy_description, policy_name
from cap_bench.episode_runs import CASSETTE, write_cassette
from cap_bench.graph_cli import GraphBench, comma_separated
from cap_bench.ros_domains import domain_ids
from cap_bench.tabletop import local_executor
from cap_bench.tabletop.episodes import Episode
from cap_bench.tabletop.oracle import oracle_program
from cap_bench.tabletop.options import RGBD_CAMERA_RATE, TabletopOptions
from cap_bench.tabletop.report import write_report
from cap_bench.tabletop.sampling import sample_episode
from cap_bench.tabletop.templates import GROUPS, TEMPLATES
from cap_lmp.cassette import HAND_WRITTEN
from cap_lmp.safe_text import terminal_text


def plan(options: TabletopOptions) -> list[Episode]:
    """Every episode of the run, trial by trial across all rows: a run stopped early has covered every row alike."""
    episodes = []
    for trial in range(options.trials):
        for group in options.groups:
            for template in (t for t in GROUPS[group][1] if t in options.tasks):
                episodes.append(sample_episode(group, template, options.base_seed + trial))
    return episodes


def write_oracle_cassette(episodes: Iterable[Episode], path: pathlib.Path) -> None:
    """One reference program per distinct instruction (a program depends only on the instruction's attributes)."""
    entries = {}
    for episode in episodes:
        entries[episode.instruction.lower()] = {
            'lmp': 'tabletop_ui', 'query': episode.instruction, 'context': '*',
            'source': f'{HAND_WRITTEN} (cap_bench oracle, {episode.template})',
            'completion': oracle_program(episode)}
    write_cassette(entries.values(), path)


def load_records(out_dir: pathlib.Path) -> list[dict]:
    """The episodes' records in `out_dir`, from every job's episodes*.jsonl (the last one of each key)."""
    records = {}
    for path in sorted(out_dir.glob('episodes*.jsonl')):
        for line in path.read_text(encoding='utf-8').splitlines():
            if line.strip():
                record = json.loads(line)
                records[record['key']] = record
    return list(records.values())


def run_benchmark(options: TabletopOptions, show_progress: bool = True) -> dict:
    """Run (or resume) a benchmark; return the summary written to report.json / report.md / report.png."""
    out_dir = pathlib.Path(options.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    episodes = plan(options)
    done = {r['key'] for r in load_records(out_dir)} if options.resume else set()
    if not options.resume:
        for old in out_dir.glob('episodes*.jsonl'):
            old.unlink()
    todo = [e for e in episodes if e.key not in done]
    cassette = None
    if options.policy == 'oracle':
        cassette = out_dir / CASSETTE
        write_oracle_cassette(episodes, cassette)
    options.first_domain_id = domain_ids(options.jobs, options.first_domain_id)[0]
    (out_dir / 'options.json').write_text(json.dumps(dataclasses.asdict(options), indent=2))
    started = time.monotonic()
    jobs = max(1, min(options.jobs, len(todo)))
    keys = [e.key for e in todo]
    if todo:
        with progress_bar(show_progress, len(episodes), len(episodes) - len(todo)) as count:
            if options.executor == 'ray':
                from cap_bench.tabletop import ray_executor  # only here: the local executor never loads Ray

                ray_executor.run_jobs(keys, jobs, options, cassette, out_dir, count)
            else:
                local_executor.run_jobs(keys, jobs, options, cassette, out_dir, count)
    planned = {e.key for e in episodes}
    records = [r for r in load_records(out_dir) if r['key'] in planned]
    title = (f"Table-top benchmark ({policy_name(options)}): perception {options.perception}, "
             f"{options.trials} trial(s) per row")
    summary = write_report(records, out_dir, title, policy_description(options), time.monotonic() - started)
    summary['wall_seconds_this_run'] = summary['run']['wall_s']
    summary['episodes'] = len(records)
    return summary


@contextlib.contextmanager
def progress_bar(show: bool, total: int, already: int) -> Iterator[Callable[[bool], None]]:
    """A function to call with each finished episode's success: a progress bar on the terminal when `show`."""
    if not show:
        yield lambda success: None
        return
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn
    bar = Progress(TextColumn('[bold]cap bench'), BarColumn(), MofNCompleteColumn(),
                   TextColumn('{task.fields[ok]}'), TimeRemainingColumn())
    task = bar.add_task('episodes', total=total, completed=already, ok='')
    finished, successes = already, 0

    def count(success: bool) -> None:
        nonlocal finished, successes
        finished += 1
        successes += bool(success)
        bar.update(task, completed=finished, ok=f'{successes}/{finished - already} succeeded')

    bar.start()
    try:
        yield count
    finally:
        bar.stop()


class TabletopBench(GraphBench):
    """The table top's own options: the rows (--groups, --tasks), the perception, and the jobs that run them."""

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        parser.add_argument('--groups', default=','.join(GROUPS), help='comma-separated: SA-SI, UA-SI, UA-UI')
        parser.add_argument('--tasks', default=','.join(TEMPLATES), help='comma-separated template names')
        parser.add_argument('--perception', choices=('ground_truth', 'rgbd'), default='ground_truth')
        parser.add_argument('--camera-rate', type=float, default=RGBD_CAMERA_RATE,
                            help=f'with --perception rgbd: camera images per second of simulated time '
                                 f'[{RGBD_CAMERA_RATE:g}]')
        parser.add_argument('--jobs', type=int, default=1,
                            help='parallel graphs (processes) [1]; job i uses ROS_DOMAIN_ID + i when ROS_DOMAIN_ID '
                                 'is set, else consecutive ids from a start derived from the process id')
        parser.add_argument('--executor', choices=('local', 'ray'), default='local',
                            help='local: a process per job on this machine; ray: a task per job on a Ray cluster, '
                                 'on one machine or several [local]')
        parser.add_argument('--ray-address', default='',
                            help='with --executor ray: the cluster to join (HEAD:6379, `ray start --head` on HEAD); '
                                 'default: a Ray instance on 127.0.0.1 for this run')

    def options(self, args: argparse.Namespace) -> TabletopOptions:
        groups, tasks = tuple(comma_separated(args.groups)), tuple(comma_separated(args.tasks))
        unknown = [g for g in groups if g not in GROUPS] + [t for t in tasks if t not in TEMPLATES]
        if unknown:
            raise ValueError(f'unknown groups or tasks: {", ".join(unknown)}; groups: {", ".join(GROUPS)}; tasks: '
                             f'{", ".join(TEMPLATES)}')
        return TabletopOptions(**dataclasses.asdict(super().options(args)), groups=groups, tasks=tasks,
                               perception=args.perception, camera_rate=args.camera_rate, jobs=args.jobs,
                               executor=args.executor, ray_address=args.ray_address)

    def run(self, options: TabletopOptions, args: argparse.Namespace) -> dict:
        return run_benchmark(options)

    def kept(self, args: argparse.Namespace) -> str:
        done = len(load_records(pathlib.Path(args.out)))
        return f'{done} episode(s) are in {args.out}; continue with --resume'

    def show(self, summary: dict, args: argparse.Namespace) -> None:
        # The report quotes the programs' messages: never a raw control character on the terminal.
        report = (pathlib.Path(args.out) / 'report.md').read_text(encoding='utf-8')
        print(terminal_text(report, limit=len(report)))
        print(json.dumps({'overall_percent': summary['overall']['percent'], 'episodes': summary['episodes'],
                          'wall_seconds': round(summary['wall_seconds_this_run'], 1), 'out': args.out}))


BENCH = TabletopBench(name='tabletop', description='The paper\'s simulated table-top benchmark through the cap-ros '
                      'graph.', out='output/bench', trials=50, per='row', episode_timeout=900.0, default_api='chat')


def main(argv: list[str] | None = None) -> int:
    return BENCH.main(argv)
