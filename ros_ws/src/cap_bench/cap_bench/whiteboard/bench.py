"""`cap bench whiteboard`: drawing and erasing on the simulated whiteboard through the real graph, judged on the ink.

Every episode goes the way of a user's commands: the scene is reset through the sim bridge's service (which also
wipes the board), the session is reset, the episode's instructions go to lmp_node's /cap/execute action one after
another, the programs (the reference programs replayed from a cassette, or a model's code from an OpenAI-compatible
endpoint) run in the sandbox and drive follow_path over ROS, and the ink image the bridge serves (GetInk) is judged
against the episode's shapes (cap_bench.whiteboard.ink_check). Episodes: cap_bench.whiteboard.episodes.

    cap bench whiteboard --trials 20 --out output/whiteboard            # the reference programs (oracle)
    cap bench whiteboard --policy llm --backend local --trials 5      # the local model

Results are appended to episodes.jsonl as each episode ends (--resume continues a run); report.json, report.md and
report.png summarise them per template. One graph runs the episodes one after another.
"""
from __future__ import annotations

import argparse
import json
import pathlib
import signal
import sys
import time
from typing import Sequence

import cv2
import numpy as np
import yaml

from cap_bench.charts import Bar, bar_chart
from cap_bench.episode_runs import EPISODES, lmp_parameters, load_records, run_episodes
from cap_bench.runner import (BenchOptions, Interrupted, _raise_interrupted, _wait, add_model_arguments, domain_ids,
                              model_endpoint, model_settings, outcome_name, policy_description)
from cap_bench.whiteboard.episodes import TEMPLATES, Episode, oracle_program, sample_episode
from cap_bench.whiteboard.ink_check import MAX_P95_MM, MIN_COVERAGE, check_drawing, check_erased
from cap_lmp.cassette import FORMAT as CASSETTE_FORMAT, HAND_WRITTEN, normalise_query
from cap_lmp.errors import LLMError
from cap_lmp.safe_text import one_line

DEFAULT_OUT = 'output/whiteboard'
UI_LMP = 'whiteboard_ui'
SERVICE_TIMEOUT_S = 60.0
# The bar the oracle must clear (the paper has no figure for this domain): this share of episodes passing.
TARGET_ORACLE_RATE = 0.99


def plan(templates: Sequence[str], trials: int, base_seed: int = 0) -> list[Episode]:
    """Every episode of the run, trial by trial across the templates."""
    return [sample_episode(template, base_seed + trial) for trial in range(trials) for template in templates]


def write_oracle_cassette(episodes: Sequence[Episode], path: pathlib.Path) -> None:
    """One reference program per distinct instruction (a program depends only on its instruction's words)."""
    entries = {}
    for episode in episodes:
        for instruction in episode.instructions:
            entries[normalise_query(instruction)] = {
                'lmp': UI_LMP, 'query': instruction, 'context': '*',
                'source': f'{HAND_WRITTEN} (cap_bench whiteboard, {episode.template})',
                'completion': oracle_program(instruction)}
    path.write_text(yaml.safe_dump({'format': CASSETTE_FORMAT, 'entries': list(entries.values())},
                                   sort_keys=False, width=120), encoding='utf-8')


class WhiteboardRunner:
    """One whiteboard graph in this process, running episodes one after another."""

    def __init__(self, options: BenchOptions, cassette: pathlib.Path | None) -> None:
        import rclpy
        from cap_ros_common.actions import ActionClient
        from rclpy.context import Context
        from std_srvs.srv import Trigger

        from cap_bringup.graph import Graph, GraphOptions
        from cap_interfaces.action import ExecuteCommand
        from cap_interfaces.msg import GraphNames
        from cap_interfaces.srv import GetInk, ResetScene

        self.options = options
        self.context = Context()
        rclpy.init(context=self.context)
        backend, lmp = lmp_parameters(options)
        self.graph = Graph(self.context, GraphOptions(
            domain='whiteboard', llm_backend=backend, cassette=str(cassette) if cassette else '', camera_rate=0.0,
            extra={'lmp_node': lmp}))
        self.node = rclpy.create_node('cap_bench_whiteboard', context=self.context)
        self.graph.executor.add_node(self.node)
        self.execute = ActionClient(self.node, ExecuteCommand, GraphNames.EXECUTE_ACTION)
        self.reset = self.node.create_client(ResetScene, GraphNames.SIM_RESET_SERVICE)
        self.reset_session = self.node.create_client(Trigger, GraphNames.RESET_SESSION_SERVICE)
        self.get_ink = self.node.create_client(GetInk, GraphNames.SIM_GET_INK_SERVICE)
        self.ExecuteCommand, self.ResetScene, self.Trigger, self.GetInk = ExecuteCommand, ResetScene, Trigger, GetInk
        if not _wait(lambda: self.execute.server_is_ready() and self.reset.service_is_ready()
                     and self.reset_session.service_is_ready() and self.get_ink.service_is_ready(), 60):
            raise RuntimeError('the whiteboard graph did not come up within 60 s')

    def _call(self, future, timeout: float, what: str):
        if not _wait(future.done, timeout):
            raise TimeoutError(f'no answer from {what} within {timeout:.0f} s')
        return future.result()

    def ink(self) -> np.ndarray:
        """The board's ink now, as the bridge serves it (a PNG, decoded)."""
        answer = self._call(self.get_ink.call_async(self.GetInk.Request()), SERVICE_TIMEOUT_S, 'the ink service')
        return cv2.imdecode(np.frombuffer(bytes(answer.image.data), np.uint8), cv2.IMREAD_GRAYSCALE)

    def _perceived(self) -> set[str]:
        try:
            return {obj.name for obj in self.graph.nodes['perception_node'].source.objects()}
        except Exception:  # noqa: BLE001 - perception not ready yet
            return set()

    def run(self, episode: Episode) -> dict:
        from geometry_msgs.msg import Point

        from cap_interfaces.msg import ObjectSpec

        world = self.graph.world
        record = base_record(episode, self.options)
        wall_started = time.monotonic()
        request = self.ResetScene.Request(seed=episode.seed, objects=[
            ObjectSpec(name=o.name, category=o.category, color_name=o.color, use_position=True,
                       position=Point(x=o.xy[0], y=o.xy[1])) for o in episode.objects])
        answer = self._call(self.reset.call_async(request), SERVICE_TIMEOUT_S, 'the scene reset')
        if not answer.success:
            record['reason'] = f'scene reset failed: {answer.message}'
            return record
        self._call(self.reset_session.call_async(self.Trigger.Request()), SERVICE_TIMEOUT_S,
                   'lmp_node (reset session)')
        names = {o.name for o in episode.objects}
        if not _wait(lambda: self._perceived() == names, 30):
            record['reason'] = f'perception did not report the reset scene within 30 s: {sorted(self._perceived())}'
            return record
        sim_started = world.time
        codes, result = [], None
        for instruction in episode.instructions:
            goal = self._call(self.execute.send_goal_async(self.ExecuteCommand.Goal(command=instruction)), 30,
                              'lmp_node (goal)')
            future = goal.get_result_async()
            if not _wait(future.done, self.options.episode_timeout_s + 60):
                goal.cancel_goal_async()
                _wait(future.done, 30)
                record['reason'] = f'no result within {self.options.episode_timeout_s:.0f} s'
                return record
            result = future.result().result
            codes.append(result.code)
            record['model_calls'] += result.model_calls
            if result.outcome != self.ExecuteCommand.Result.OUTCOME_DONE:
                break
        done = result is not None and result.outcome == self.ExecuteCommand.Result.OUTCOME_DONE
        ink = self.ink()
        verdict = check_erased(ink) if episode.erase else check_drawing(ink, episode.targets)
        record.update(code='\n# ---\n'.join(codes), success=bool(done and verdict.success),
                      outcome=outcome_name(result.outcome) if result is not None else '',
                      sim_seconds=round(world.time - sim_started, 3),
                      wall_seconds=round(time.monotonic() - wall_started, 3), **verdict.figures())
        if not done:
            record['reason'] = f'the command ended {record["outcome"]}: {one_line(result.message)}'
        elif not verdict.success:
            record['reason'] = f'the ink is wrong: {verdict.reason}'
        return record

    def close(self) -> None:
        self.graph.close()
        self.node.destroy_node()
        self.context.try_shutdown()


def base_record(episode: Episode, options: BenchOptions) -> dict:
    """An episode's record before it ran: not a success."""
    return {'key': episode.key, 'template': episode.template, 'seed': episode.seed,
            'instructions': list(episode.instructions), 'policy': options.policy, 'success': False, 'reason': '',
            'code': '', 'outcome': '', 'sim_seconds': 0.0, 'wall_seconds': 0.0, 'model_calls': 0,
            'objects': {o.name: list(o.xy) for o in episode.objects}}


def summarise(records: Sequence[dict], title: str, policy: str, wall_seconds: float) -> dict:
    """Per template and overall: passed / trials; the ink figures of the drawings; each failure's reason."""
    rows = []
    for template in TEMPLATES:
        mine = [r for r in records if r['template'] == template]
        if not mine:
            continue
        drawn = [r for r in mine if 'p95_mm' in r and r['template'] != 'erase' and r.get('ink_pixels', 0)]
        rows.append({'template': template, 'trials': len(mine), 'successes': sum(r['success'] for r in mine),
                     'percent': 100.0 * sum(r['success'] for r in mine) / len(mine),
                     'p95_mm_median': float(np.median([r['p95_mm'] for r in drawn])) if drawn else None,
                     'p95_mm_max': float(max(r['p95_mm'] for r in drawn)) if drawn else None,
                     'coverage_min': float(min(r['coverage'] for r in drawn)) if drawn else None})
    total = len(records)
    passed = sum(r['success'] for r in records)
    return {'title': title, 'policy': policy, 'criteria': {'p95_mm_at_most': MAX_P95_MM,
                                                           'coverage_at_least': MIN_COVERAGE,
                                                           'oracle_rate_target': TARGET_ORACLE_RATE},
            'rows': rows, 'overall': {'trials': total, 'successes': passed,
                                      'percent': 100.0 * passed / total if total else None},
            'wall_seconds': round(wall_seconds, 1),
            'episode_wall_seconds_median': float(np.median([r['wall_seconds'] for r in records])) if records else 0,
            'failures': {r['key']: r['reason'] for r in records if not r['success']}}


def write_report(summary: dict, out: pathlib.Path) -> None:
    (out / 'report.json').write_text(json.dumps(summary, indent=2), encoding='utf-8')
    lines = [f"# {summary['title']}", '', f"Policy: {summary['policy']}", '',
             f"A drawing passes with the ink's 95th-percentile distance to the target at most {MAX_P95_MM} mm and "
             f"at least {MIN_COVERAGE:.0%} of the target inked; an erase with the board clean.", '',
             '| template | trials | passed % | p95 median [mm] | p95 max [mm] | least coverage |',
             '|---|---|---|---|---|---|']

    def figure(value, form):
        return '—' if value is None else format(value, form)

    for row in summary['rows']:
        lines.append(f"| {row['template']} | {row['trials']} | {row['percent']:.1f} | "
                     f"{figure(row['p95_mm_median'], '.2f')} | {figure(row['p95_mm_max'], '.2f')} | "
                     f"{figure(row['coverage_min'], '.3f')} |")
    overall = summary['overall']
    lines.append(f"| **all** | {overall['trials']} | **{figure(overall['percent'], '.1f')}** | | | |")
    if summary['failures']:
        lines += ['', '## Failures', ''] + [f'- `{key}`: {reason}' for key, reason in summary['failures'].items()]
    (out / 'report.md').write_text('\n'.join(lines) + '\n', encoding='utf-8')
    bars = [Bar(row['template'], row['percent'], None, f"{row['successes']}/{row['trials']}")
            for row in summary['rows']]
    bars.append(Bar('all', overall['percent'], None, f"{overall['successes']}/{overall['trials']}", bold=True))
    bar_chart(out / 'report.png', [summary['title'], f"policy: {summary['policy']}"], bars)


def run_benchmark(options: BenchOptions, templates: Sequence[str], resume: bool = False) -> dict:
    episodes = plan(templates, options.trials, options.base_seed)
    seconds = run_episodes(options, episodes, resume, write_oracle_cassette, WhiteboardRunner, base_record)
    out = pathlib.Path(options.out)
    summary = summarise(load_records(out), 'Whiteboard: drawing and erasing, judged on the ink',
                        policy_description(options), seconds)
    write_report(summary, out)
    return summary


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog='cap bench whiteboard', description=__doc__.split('\n\n')[0])
    parser.add_argument('--policy', choices=('oracle', 'llm'), default='oracle',
                        help='oracle: the reference programs; llm: a model at an OpenAI-compatible endpoint')
    add_model_arguments(parser, default_api='completions')
    parser.add_argument('--trials', type=int, default=10, help='episodes per template [10]')
    parser.add_argument('--templates', default=','.join(TEMPLATES), help=f'comma-separated [{",".join(TEMPLATES)}]')
    parser.add_argument('--seed', type=int, default=0, help='seed of the first trial [0]')
    parser.add_argument('--out', default=DEFAULT_OUT, help=f'output folder [{DEFAULT_OUT}]')
    parser.add_argument('--resume', action='store_true', help='keep the episodes already in the output folder')
    parser.add_argument('--episode-timeout', type=float, default=300.0, help='seconds per instruction [300]')
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    templates = [t.strip() for t in args.templates.split(',') if t.strip()]
    unknown = [t for t in templates if t not in TEMPLATES]
    if unknown or args.trials < 1:
        print(f'cap bench whiteboard: error: unknown templates {unknown}' if unknown else
              'cap bench whiteboard: error: --trials must be at least 1', file=sys.stderr)
        return 2
    options = BenchOptions(policy=args.policy, out=args.out, trials=args.trials, base_seed=args.seed,
                           episode_timeout_s=args.episode_timeout, first_domain_id=domain_ids(1)[0],
                           **model_settings(args))
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, _raise_interrupted)
    try:
        with model_endpoint(options, 'whiteboard') as options:
            summary = run_benchmark(options, templates, args.resume)
    except LLMError as error:
        print(f'cap bench whiteboard: error: {one_line(str(error))}', file=sys.stderr)
        return 2
    except Interrupted as interrupted:
        print(f'interrupted ({interrupted}): the episodes finished so far are in {args.out}/{EPISODES}',
              file=sys.stderr)
        return interrupted.exit_code
    print(json.dumps({key: summary[key] for key in ('overall', 'rows', 'wall_seconds')}))
    return 0


if __name__ == '__main__':
    sys.exit(main())
