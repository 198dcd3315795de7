"""`cap bench devset`: the table-top development set through the real graph, one command after another.

Every command goes the way of a user's: the scene is reset to the command's layout, its instructions are sent to
lmp_node in one session, the programs (the reference programs replayed from a cassette, or a model's code) drive
perception and pick-and-place, and the command's judge checks the simulator's final state.

All commands run in one graph, sequentially (a local model server answers one request at a time). Each result is
appended to items.jsonl as it ends; the summary is printed as JSON and written to summary.json.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import pathlib
import time
from typing import Any, Callable, Sequence

from cap_bench.devset.commands import BY_KEY, COMMANDS, DevCommand, Positions, select
from cap_bench.episode_runs import CASSETTE, show_progress, write_cassette, write_record
from cap_bench.graph_cli import GraphBench, comma_separated
from cap_bench.ros_domains import domain_ids, use_own_domain
from cap_bench.tabletop.episodes import Episode
from cap_bench.tabletop.options import TabletopOptions
from cap_bench.tabletop.runner import TabletopRunner
from cap_bench.tabletop.success import Verdict
from cap_lmp.cassette import HAND_WRITTEN, normalise_query

DEFAULT_OUT = 'output/devset'
ITEMS = 'items.jsonl'
SUMMARY = 'summary.json'
UI_LMP = 'tabletop_ui'  # the LMP that receives a user's instruction (the only one the references answer)


def write_oracle_cassette(commands: Sequence[DevCommand], path: pathlib.Path) -> None:
    """One entry per instruction: its reference program, for any scene ('*'). Replayed in a session, each
    instruction finds the variables the earlier references of its command left (e.g. `moved`)."""
    entries: dict[str, dict[str, str]] = {}
    for command in commands:
        for instruction, program in zip(command.instructions, command.reference, strict=True):
            key = normalise_query(instruction)
            if key in entries and entries[key]['completion'] != program:
                raise ValueError(f'two dev commands send {instruction!r} with different reference programs')
            entries[key] = {'lmp': UI_LMP, 'query': instruction, 'context': '*',
                            'source': f'{HAND_WRITTEN} (cap_bench devset, {command.key})', 'completion': program}
    write_cassette(entries.values(), path)


def item_record(command: DevCommand, run: dict[str, Any]) -> dict[str, Any]:
    """The line of items.jsonl for a command, from the runner's record of its episode."""
    return {'key': command.key, 'instructions': list(command.instructions), 'success': bool(run.get('success')),
            'reason': run.get('reason', ''), 'outcome': run.get('outcome', ''), 'code': run.get('code', ''),
            'latency_s': round(float(run.get('wall_seconds', 0.0)), 3),
            'sim_seconds': round(float(run.get('sim_seconds', 0.0)), 3), 'model_calls': run.get('model_calls', 0),
            'prompt_tokens': run.get('prompt_tokens', 0), 'completion_tokens': run.get('completion_tokens', 0),
            'final_state': run.get('final_state', {})}


def summarise(options: TabletopOptions, items: Sequence[dict[str, Any]], wall_seconds: float) -> dict[str, Any]:
    """What was run and how it went: passed / total, the pass rate, wall time and each failure's reason."""
    passed = sum(item['success'] for item in items)
    summary: dict[str, Any] = {'policy': options.policy}
    if options.policy == 'llm':
        summary['model'] = options.model or os.environ.get('CAP_LLM_MODEL', '')
    summary.update(passed=passed, total=len(items), rate=round(passed / len(items), 4) if items else 0.0,
                   wall_seconds=round(wall_seconds, 1),
                   failures={item['key']: item['reason'] for item in items if not item['success']})
    return summary


def _episode_judge(command: DevCommand) -> Callable[[Episode, Positions, Positions], Verdict]:
    """The command's judge in the runner's form (the runner passes the episode too)."""
    return lambda _episode, initial, final: command.judge(initial, final)


def run_devset(options: TabletopOptions, commands: Sequence[DevCommand] = COMMANDS) -> dict[str, Any]:
    """Run `commands` in one graph on the policy of `options` (policy, base_url, model, api, episode_timeout_s,
    out, first_domain_id); write items.jsonl and summary.json into options.out and return the summary."""
    out = pathlib.Path(options.out)
    out.mkdir(parents=True, exist_ok=True)
    cassette = None
    if options.policy == 'oracle':
        cassette = out / CASSETTE
        write_oracle_cassette(commands, cassette)
    # The graph comes up in this process: keep it on a DDS domain of its own, on this host.
    use_own_domain(domain_ids(1, options.first_domain_id)[0])
    started = time.monotonic()
    items = []
    runner = TabletopRunner(options, cassette)
    try:
        with open(out / ITEMS, 'w', encoding='utf-8') as stream:
            for index, command in enumerate(commands, 1):
                try:
                    run = runner.run(command.episode(), judge=_episode_judge(command),
                                     instructions=command.instructions)
                except Exception as error:  # the graph did not answer: a failed item, the run goes on
                    run = {'success': False, 'reason': f'the run failed: {error}'}
                item = item_record(command, run)
                items.append(item)
                write_record(stream, item)
                show_progress(index, len(commands), command.key, item, item['latency_s'])
    finally:
        runner.close()
    summary = summarise(options, items, time.monotonic() - started)
    (out / SUMMARY).write_text(json.dumps(summary, indent=2), encoding='utf-8')
    return summary


class DevsetBench(GraphBench):
    """The development set's own option: which commands (--commands)."""

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        parser.add_argument('--commands', default='', help=f'comma-separated keys [all]: {", ".join(BY_KEY)}')

    def options(self, args: argparse.Namespace) -> TabletopOptions:
        try:
            select(comma_separated(args.commands))
        except KeyError as error:
            raise ValueError(error.args[0]) from None
        return TabletopOptions(**dataclasses.asdict(super().options(args)))

    def run(self, options: TabletopOptions, args: argparse.Namespace) -> dict:
        return run_devset(options, select(comma_separated(args.commands)))

    def kept(self, args: argparse.Namespace) -> str:
        return f'the commands finished so far are in {args.out}/{ITEMS}'


BENCH = DevsetBench(name='devset', description=__doc__.split('\n\n')[0], out=DEFAULT_OUT, domain='tabletop',
                    trials=None, resume=False, episode_timeout=TabletopOptions.episode_timeout_s)


def main(argv: list[str] | None = None) -> int:
    return BENCH.main(argv)
