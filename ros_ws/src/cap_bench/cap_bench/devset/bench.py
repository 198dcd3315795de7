"""`cap bench devset`: the table-top development set through the real graph, one command after another.

Every command goes the way of a user's: the scene is reset to the command's layout, its instructions are sent to
lmp_node in one session, the programs (the reference programs replayed from a cassette, or a model's code) drive
perception and pick-and-place, and the command's judge checks the simulator's final state.

All commands run in one graph, sequentially (a local model server answers one request at a time). Each result is
appended to items.jsonl as it ends; the summary is printed as JSON and written to summary.json.
"""
from __future__ import annotations

import argparse
import json
import os
import pathlib
import signal
import sys
import time
from typing import Any, Callable, Sequence

import yaml

from cap_bench.devset.commands import BY_KEY, COMMANDS, DevCommand, Positions, select
from cap_bench.episodes import Episode
from cap_bench.runner import (BenchOptions, Interrupted, _EpisodeRunner, add_model_arguments, domain_ids,
                              model_endpoint, model_settings)
from cap_bench.success import Verdict
from cap_lmp.cassette import FORMAT as CASSETTE_FORMAT, HAND_WRITTEN, normalise_query
from cap_lmp.errors import LLMError
from cap_lmp.safe_text import one_line, terminal_text

DEFAULT_OUT = 'output/devset'
ITEMS = 'items.jsonl'
SUMMARY = 'summary.json'
CASSETTE = 'oracle_cassette.yaml'
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
    path.write_text(yaml.safe_dump({'format': CASSETTE_FORMAT, 'entries': list(entries.values())},
                                   sort_keys=False, width=120), encoding='utf-8')


def item_record(command: DevCommand, run: dict[str, Any]) -> dict[str, Any]:
    """The line of items.jsonl for a command, from the runner's record of its episode."""
    return {'key': command.key, 'instructions': list(command.instructions), 'success': bool(run.get('success')),
            'reason': run.get('reason', ''), 'outcome': run.get('outcome', ''), 'code': run.get('code', ''),
            'latency_s': round(float(run.get('wall_seconds', 0.0)), 3),
            'sim_seconds': round(float(run.get('sim_seconds', 0.0)), 3), 'model_calls': run.get('model_calls', 0),
            'prompt_tokens': run.get('prompt_tokens', 0), 'completion_tokens': run.get('completion_tokens', 0),
            'final_state': run.get('final_state', {})}


def summarise(options: BenchOptions, items: Sequence[dict[str, Any]], wall_seconds: float) -> dict[str, Any]:
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


def run_devset(options: BenchOptions, commands: Sequence[DevCommand] = COMMANDS) -> dict[str, Any]:
    """Run `commands` in one graph on the policy of `options` (policy, base_url, model, api, episode_timeout_s,
    out, first_domain_id); write items.jsonl and summary.json into options.out and return the summary."""
    out = pathlib.Path(options.out)
    out.mkdir(parents=True, exist_ok=True)
    cassette = None
    if options.policy == 'oracle':
        cassette = out / CASSETTE
        write_oracle_cassette(commands, cassette)
    # The graph comes up in this process: keep it on a DDS domain of its own, on this host.
    os.environ['ROS_DOMAIN_ID'] = str(domain_ids(1, options.first_domain_id)[0])
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    started = time.monotonic()
    items = []
    runner = _EpisodeRunner(options, cassette)
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
                stream.write(json.dumps(item) + '\n')
                stream.flush()
                verdict = 'ok' if item['success'] else f"FAILED: {terminal_text(item['reason'], limit=300)}"
                print(f"[{index}/{len(commands)}] {command.key}: {verdict} ({item['latency_s']:.1f} s)",
                      file=sys.stderr, flush=True)
    finally:
        runner.close()
    summary = summarise(options, items, time.monotonic() - started)
    (out / SUMMARY).write_text(json.dumps(summary, indent=2), encoding='utf-8')
    return summary


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog='cap bench devset', description=__doc__.split('\n\n')[0])
    parser.add_argument('--policy', choices=('oracle', 'llm'), default='oracle',
                        help='oracle: the reference programs; llm: a model at an OpenAI-compatible endpoint')
    add_model_arguments(parser, default_api='completions')
    parser.add_argument('--commands', default='', help=f'comma-separated keys [all]: {", ".join(BY_KEY)}')
    parser.add_argument('--out', default=DEFAULT_OUT, help=f'output folder [{DEFAULT_OUT}]')
    parser.add_argument('--episode-timeout', type=float, default=BenchOptions.episode_timeout_s,
                        help=f'seconds per instruction [{BenchOptions.episode_timeout_s:g}]')
    return parser


def _raise_interrupted(signum: int, _frame: Any) -> None:
    raise Interrupted(signum)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        commands = select(part.strip() for part in args.commands.split(','))
        first_domain_id = domain_ids(1)[0]
    except (KeyError, ValueError) as error:
        print(f'cap bench devset: error: {error.args[0]}', file=sys.stderr)
        return 2
    options = BenchOptions(policy=args.policy, out=args.out, episode_timeout_s=args.episode_timeout,
                           first_domain_id=first_domain_id, **model_settings(args))
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, _raise_interrupted)
    try:
        with model_endpoint(options) as options:
            summary = run_devset(options, commands)
    except LLMError as error:  # the local model could not start: one line saying why and what to do
        print(f'cap bench devset: error: {one_line(str(error))}', file=sys.stderr)
        return 2
    except Interrupted as interrupted:
        print(f'interrupted ({interrupted}): the commands finished so far are in {args.out}/{ITEMS}',
              file=sys.stderr)
        return interrupted.exit_code
    print(json.dumps(summary))
    return 0


if __name__ == '__main__':
    sys.exit(main())
