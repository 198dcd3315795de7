"""What the benchmarks that run their episodes one after another through a graph share: the graph that replaces
itself when it stops answering, the records file, the oracle's cassette, and the loop of the whiteboard's and the
mobile kitchen's runs (run the episodes, write each record as it ends, resume where a run stopped). No rclpy here."""
from __future__ import annotations

import json
import pathlib
import sys
import time
from typing import IO, Any, Callable, Iterable, Protocol, Sequence

import yaml

from cap_bench.bench_options import BenchOptions, feedback_rounds
from cap_bench.ros_domains import domain_ids, use_own_domain
from cap_lmp.cassette import FORMAT as CASSETTE_FORMAT, HAND_WRITTEN, normalise_query
from cap_lmp.safe_text import terminal_text

EPISODES = 'episodes.jsonl'
CASSETTE = 'oracle_cassette.yaml'


class EpisodeRunner(Protocol):
    def run(self, episode: Any) -> dict: ...

    def close(self) -> None: ...


class EpisodeGraph:
    """Episodes run one at a time on a graph from `make_runner()`, built at once.

    A graph that stops answering (a service or a goal without an answer in time: TimeoutError) costs its episode,
    recorded as `failed(episode, error)` says, not the rest of the run: it is closed, and the next episodes run on a
    new one.
    """

    def __init__(self, make_runner: Callable[[], EpisodeRunner],
                 failed: Callable[[Any, TimeoutError], dict]) -> None:
        self.make_runner, self.failed = make_runner, failed
        self.runner: EpisodeRunner | None = make_runner()
        self.built = 1

    def run(self, episode: Any) -> dict:
        """The episode's record."""
        try:
            return self.runner.run(episode)
        except TimeoutError as error:
            record = self.failed(episode, error)
            self.runner.close()
            self.runner = None
            self.runner = self.make_runner()
            self.built += 1
            return record

    def close(self) -> None:
        if self.runner is not None:
            self.runner.close()
            self.runner = None


def write_record(out: IO[str], record: dict) -> None:
    """Append `record` to an episodes*.jsonl file, at once (a run stopped later keeps it)."""
    out.write(json.dumps(record) + '\n')
    out.flush()


def show_progress(index: int, total: int, key: str, record: dict, seconds: float) -> None:
    """One line on stderr as an episode ends: '[3/20] key: ok (12.5 s)', or its failure's reason."""
    verdict = 'ok' if record['success'] else f"FAILED: {terminal_text(record['reason'], limit=300)}"
    print(f'[{index}/{total}] {key}: {verdict} ({seconds:.1f} s)', file=sys.stderr, flush=True)


def write_cassette(entries: Iterable[dict], path: pathlib.Path) -> None:
    """A cassette of the oracle's reference programs (cap_lmp.cassette's format), for lmp_node to replay."""
    path.write_text(yaml.safe_dump({'format': CASSETTE_FORMAT, 'entries': list(entries)}, sort_keys=False,
                                   width=120), encoding='utf-8')


def write_oracle_cassette(episodes: Sequence[Any], path: pathlib.Path, lmp: str, bench: str,
                          program: Callable[[str], str]) -> None:
    """One reference program (`program(instruction)`) per distinct instruction of the episodes, for the LMP `lmp`
    that receives a user's instruction; `bench` names the benchmark in each entry's source."""
    entries = {}
    for episode in episodes:
        for instruction in episode.instructions:
            entries[normalise_query(instruction)] = {
                'lmp': lmp, 'query': instruction, 'context': '*',
                'source': f'{HAND_WRITTEN} (cap_bench {bench}, {episode.template})',
                'completion': program(instruction)}
    write_cassette(entries.values(), path)


def episode_record(episode: Any, options: BenchOptions) -> dict:
    """An episode's record before it ran: not a success (episodes of instructions in a scene of named objects)."""
    return {'key': episode.key, 'template': episode.template, 'seed': episode.seed,
            'instructions': list(episode.instructions), 'policy': options.policy,
            'feedback_rounds': feedback_rounds(options), 'success': False, 'reason': '',
            'code': '', 'outcome': '', 'sim_seconds': 0.0, 'wall_seconds': 0.0, 'model_calls': 0,
            'objects': {o.name: list(o.xy) for o in episode.objects}}


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
                 write_oracle: Callable[[Sequence[Any], pathlib.Path], None],
                 make_runner: Callable[[BenchOptions, pathlib.Path | None], EpisodeRunner]) -> float:
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
        write_oracle(episodes, cassette)
    use_own_domain(domain_ids(1, options.first_domain_id)[0])
    started = time.monotonic()

    def failed(episode: Any, error: TimeoutError) -> dict:
        return {**episode_record(episode, options), 'reason': f'the graph stopped answering ({error})'}

    graph = EpisodeGraph(lambda: make_runner(options, cassette), failed) if todo else None
    try:
        with open(out / EPISODES, 'a', encoding='utf-8') as stream:
            for index, episode in enumerate(todo, 1):
                record = graph.run(episode)
                write_record(stream, record)
                show_progress(index, len(todo), episode.key, record, record['wall_seconds'])
    finally:
        if graph is not None:
            graph.close()
    return time.monotonic() - started
