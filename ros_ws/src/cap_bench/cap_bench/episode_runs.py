"""What the domain benchmarks that run their episodes one after another through one in-process graph share (the
whiteboard's and the mobile kitchen's): the lmp_node parameters of a policy, the records file, and the loop that
runs the episodes, writes each record as it ends, and replaces a graph that stopped answering. No rclpy here."""
from __future__ import annotations

import json
import os
import pathlib
import sys
import time
from typing import Any, Callable, Protocol, Sequence

from cap_bench.runner import BenchOptions, domain_ids
from cap_lmp.safe_text import terminal_text

EPISODES = 'episodes.jsonl'
CASSETTE = 'oracle_cassette.yaml'


class EpisodeRunner(Protocol):
    def run(self, episode: Any) -> dict: ...

    def close(self) -> None: ...


def lmp_parameters(options: BenchOptions) -> tuple[str, dict[str, Any]]:
    """(llm backend, lmp_node parameters) of the run's policy: the cassette for the oracle, else the model's."""
    lmp: dict[str, Any] = {'time_limit_s': options.episode_timeout_s}
    backend = 'cassette' if options.policy == 'oracle' else options.backend
    if backend == 'local':
        lmp.update(model_file=options.model_file, model_threads=options.model_threads)
    elif options.policy == 'llm':
        lmp.update(api=options.api)
        if options.base_url:
            lmp['base_url'] = options.base_url
        if options.model:
            lmp['model'] = options.model
    return backend, lmp


def load_records(out: pathlib.Path) -> list[dict]:
    """The episodes' records in `out` (the last one of each key)."""
    path = out / EPISODES
    if not path.exists():
        return []
    records = {}
    for line in path.read_text(encoding='utf-8').splitlines():
        if line.strip():
            record = json.loads(line)
            records[record['key']] = record
    return list(records.values())


def run_episodes(options: BenchOptions, episodes: Sequence[Any], resume: bool,
                 write_cassette: Callable[[Sequence[Any], pathlib.Path], None],
                 make_runner: Callable[[BenchOptions, pathlib.Path | None], EpisodeRunner],
                 base_record: Callable[[Any, BenchOptions], dict]) -> float:
    """Run the episodes not recorded yet (all of them without `resume`) through one graph, appending each record to
    episodes.jsonl as it ends; returns the wall time taken [s]. The oracle's cassette is written first."""
    out = pathlib.Path(options.out)
    out.mkdir(parents=True, exist_ok=True)
    done = {r['key'] for r in load_records(out)} if resume else set()
    if not resume:
        (out / EPISODES).write_text('', encoding='utf-8')
    todo = [e for e in episodes if e.key not in done]
    cassette = None
    if options.policy == 'oracle':
        cassette = out / CASSETTE
        write_cassette(episodes, cassette)
    os.environ['ROS_DOMAIN_ID'] = str(domain_ids(1, options.first_domain_id)[0])
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    started = time.monotonic()
    runner = make_runner(options, cassette) if todo else None
    try:
        with open(out / EPISODES, 'a', encoding='utf-8') as stream:
            for index, episode in enumerate(todo, 1):
                try:
                    record = runner.run(episode)
                except TimeoutError as error:  # the graph stopped answering: this episode fails, a new graph goes on
                    record = base_record(episode, options)
                    record['reason'] = f'the graph stopped answering ({error})'
                    runner.close()
                    runner = None
                    runner = make_runner(options, cassette)
                stream.write(json.dumps(record) + '\n')
                stream.flush()
                verdict = 'ok' if record['success'] else f"FAILED: {terminal_text(record['reason'], limit=300)}"
                print(f"[{index}/{len(todo)}] {episode.key}: {verdict} ({record['wall_seconds']:.1f} s)",
                      file=sys.stderr, flush=True)
    finally:
        if runner is not None:
            runner.close()
    return time.monotonic() - started


__all__ = ['CASSETTE', 'EPISODES', 'lmp_parameters', 'load_records', 'run_episodes']
