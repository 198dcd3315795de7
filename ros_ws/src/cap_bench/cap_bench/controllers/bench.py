"""`cap bench controllers`: the controller templates (templates.py) through the real graph, one episode after another.

Every episode goes the way of a user's command: the scene is reset with the episode's seed, the session is reset,
the instruction is sent to lmp_node, whose program (the oracle's reference program replayed from a cassette, or a
model's code) hands its controller to controller_node; for the push template the runner pushes the tool through the
simulator's PushTool service one second into the run. The verdict comes from the run's end (controller_node) and the
tool's path on /joint_states. Writes items.jsonl (one line per episode), report.json, report.md and report.png (this
run beside the paper's claim), and prints the summary as JSON.
"""
from __future__ import annotations

import argparse
import json
import pathlib
import threading
import time
from typing import Any, Sequence

import numpy as np
import rclpy
from geometry_msgs.msg import Vector3
from cap_ros_common.actions import ActionClient
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from cap_bench.bench_options import BenchOptions, lmp_parameters, policy_description
from cap_bench.charts import Bar, bar_chart
from cap_bench.controllers import devset, templates
from cap_bench.controllers.templates import ControllerEpisode, Verdict
from cap_bench.episode_runs import CASSETTE, show_progress, write_record
from cap_bench.graph_cli import GraphBench, comma_separated
from cap_bench.run_facts import run_facts
from cap_bench.ros_domains import domain_ids, use_own_domain
from cap_bringup.graph import Graph, GraphOptions
from cap_control import kinematics
from cap_controllers import plants
from cap_interfaces.action import ExecuteCommand
from cap_interfaces.msg import GraphNames
from cap_interfaces.srv import PushTool, ResetScene
from cap_lmp.cassette import ANY_CONTEXT, HAND_WRITTEN, Cassette, CassetteEntry
from cap_lmp_ros.domains.controllers.domain import DOMAIN
from cap_ros_common.time import to_seconds

DEFAULT_OUT = 'output/bench-controllers'
ITEMS = 'items.jsonl'
UI_LMP = 'controllers_ui'


def write_oracle_cassette(episodes: Sequence[ControllerEpisode], path: pathlib.Path) -> None:
    """The domain's reference cassette (its function-generation answers among them) plus each episode's program."""
    cassette = Cassette.load(DOMAIN.cassette)
    cassette.path = path
    for item in episodes:
        cassette.add(CassetteEntry(lmp=UI_LMP, query=item.instruction, context=ANY_CONTEXT, completion=item.reference,
                                   source=f'{HAND_WRITTEN} (cap bench controllers, {item.template})'))
    cassette.save()


def _wait(predicate, timeout: float, period: float = 0.01) -> bool:
    """Poll `predicate` every `period` s (this thread shares the interpreter with the graph: it polls gently)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(period)
    return predicate()


class Runner:
    """One graph of the controllers domain and a client node; runs episodes one after another."""

    def __init__(self, options: GraphOptions, episode_timeout_s: float, feedback_rounds: int = 0) -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.graph = Graph(self.context, options)
        self.node = rclpy.create_node('cap_bench_controllers', context=self.context)
        self.graph.executor.add_node(self.node)
        self.timeout_s = episode_timeout_s
        self.feedback_rounds = feedback_rounds  # recorded per episode: the report's protocol
        self.execute = ActionClient(self.node, ExecuteCommand, GraphNames.EXECUTE_ACTION)
        self.reset = self.node.create_client(ResetScene, GraphNames.SIM_RESET_SERVICE)
        self.session = self.node.create_client(Trigger, GraphNames.RESET_SESSION_SERVICE)
        self.push = self.node.create_client(PushTool, GraphNames.SIM_PUSH_TOOL_SERVICE)
        self._lock = threading.Lock()
        self.samples: list[tuple[float, np.ndarray]] = []  # (time, arm joint positions)
        self.latest = 0.0  # the newest sample's time
        self.node.create_subscription(JointState, GraphNames.JOINT_STATES_TOPIC, self._on_joints, 100)
        if not (self.execute.wait_for_server(timeout_sec=30.0) and self.reset.wait_for_service(timeout_sec=30.0)):
            raise RuntimeError('the graph did not come up')

    def _on_joints(self, message: JointState) -> None:
        index = {name: i for i, name in enumerate(message.name)}
        if all(name in index for name in plants.ARM_JOINTS):
            q = np.array([message.position[index[name]] for name in plants.ARM_JOINTS])
            stamp = to_seconds(message.header.stamp)
            with self._lock:
                self.samples.append((stamp, q))
            self.latest = stamp

    def _latest_time(self) -> float:
        return self.latest

    def _call(self, future, what: str):
        if not _wait(future.done, 30.0):
            raise RuntimeError(f'{what} did not answer')
        return future.result()

    def run(self, item: ControllerEpisode) -> dict[str, Any]:
        started = time.monotonic()
        if not self._call(self.reset.call_async(ResetScene.Request(seed=item.seed)), 'the scene reset').success:
            raise RuntimeError('the scene reset failed')
        self._call(self.session.call_async(Trigger.Request()), 'the session reset')
        controller = self.graph.nodes['controller_node']
        controller.last_result = None
        with self._lock:
            self.samples.clear()
        goal = self._call(self.execute.send_goal_async(ExecuteCommand.Goal(command=item.instruction)), 'lmp_node')
        result = goal.get_result_async()
        pushed_at = None
        if item.template == templates.PUSH:
            lockstep = self.graph.nodes['sim_bridge'].lockstep
            if _wait(lambda: lockstep.active or result.done(), self.timeout_s) and not result.done():
                took_over = self._latest_time()
                if _wait(lambda: self._latest_time() >= took_over + templates.PUSH_START_S or result.done(),
                         self.timeout_s) and not result.done():
                    force = templates.PUSH_FORCE * np.asarray(templates.PUSH_DIRECTIONS[item.push_direction], float)
                    request = PushTool.Request(force=Vector3(x=float(force[0]), y=float(force[1]), z=float(force[2])),
                                               duration=templates.PUSH_DURATION_S)
                    self._call(self.push.call_async(request), 'the push')
                    pushed_at = self._latest_time()
        if not _wait(result.done, self.timeout_s):
            goal.cancel_goal_async()
            raise RuntimeError(f'the episode did not end within {self.timeout_s:g} s')
        answer = result.result().result
        wall = time.monotonic() - started
        run = controller.last_result
        outcome = '' if answer.outcome == ExecuteCommand.Result.OUTCOME_DONE else answer.message
        record: dict[str, Any] = {'key': item.key, 'template': item.template, 'seed': item.seed,
                                  'instruction': item.instruction, 'code': answer.code,
                                  'wall_seconds': round(wall, 2), 'model_calls': answer.model_calls,
                                  'prompt_tokens': answer.prompt_tokens, 'completion_tokens': answer.completion_tokens,
                                  'feedback_rounds': self.feedback_rounds}
        if run is None:
            verdict = Verdict(False, outcome or 'no controller ran', {})
        else:
            record.update(simulated_seconds=round(run.simulated_time, 3), calls=run.calls,
                          call_p50_ms=_ms(run.call_seconds, 50), call_p99_ms=_ms(run.call_seconds, 99),
                          function_p50_ms=_ms(run.function_seconds, 50),
                          function_p99_ms=_ms(run.function_seconds, 99))
            verdict = self._judge(item, run, outcome, pushed_at)
        record.update(success=verdict.success, reason=verdict.reason, **verdict.figures)
        return record

    def _judge(self, item: ControllerEpisode, run: Any, outcome: str, pushed_at: float | None) -> Verdict:
        if item.template == templates.BALANCE:
            return templates.judge_balance(item, run.simulated_time, outcome)
        with self._lock:
            samples = [(t - run.start_time, kinematics.forward_kinematics(q)[:3, 3]) for t, q in self.samples
                       if run.start_time <= t <= run.start_time + run.simulated_time + 1e-6]
        if not samples:
            return Verdict(False, outcome or 'no tool positions recorded', {})
        start = samples[0][1]
        times = [t for t, _ in samples]
        if item.template == templates.PUSH:
            if pushed_at is None:
                return Verdict(False, outcome or 'the run ended before the push', {})
            # Times as the template counts them: the push began PUSH_START_S into the run.
            shift = templates.PUSH_START_S - (pushed_at - run.start_time)
            return templates.judge_push(item, [t + shift for t in times], [p - start for _, p in samples], outcome)
        return templates.judge_track(item, times, [p for _, p in samples], start, run.simulated_time, outcome)

    def close(self) -> None:
        try:
            self.node.destroy_node()
        finally:
            self.graph.close()
            self.context.try_shutdown()


def _ms(values: Sequence[float], percent: float) -> float:
    return round(float(np.percentile(values, percent)) * 1000, 3) if len(values) else 0.0


def report(items: Sequence[dict[str, Any]], policy: str, wall_seconds: float, out: pathlib.Path) -> dict[str, Any]:
    """report.json, report.md and report.png in `out`; the summary (returned)."""
    rows = []
    for template in templates.TEMPLATES:
        mine = [item for item in items if item['template'] == template]
        if not mine:
            continue
        passed = sum(item['success'] for item in mine)

        def median(field: str) -> float:
            values = [item[field] for item in mine if field in item]
            return round(float(np.median(values)), 3) if values else 0.0

        rows.append({'template': template, 'passed': passed, 'total': len(mine),
                     'percent': round(100.0 * passed / len(mine), 1), 'paper_percent': templates.PAPER[template],
                     'call_p50_ms': median('call_p50_ms'), 'call_p99_ms': median('call_p99_ms'),
                     'function_p50_ms': median('function_p50_ms'), 'function_p99_ms': median('function_p99_ms'),
                     'wall_seconds_per_episode': median('wall_seconds'),
                     'failures': {item['key']: item['reason'] for item in mine if not item['success']}})
    passed = sum(item['success'] for item in items)
    summary = {'policy': policy, 'passed': passed, 'total': len(items),
               'percent': round(100.0 * passed / len(items), 1) if items else 0.0,
               'wall_seconds': round(wall_seconds, 1), 'templates': rows, 'run': run_facts(items, wall_seconds)}
    (out / 'report.json').write_text(json.dumps(summary, indent=2), encoding='utf-8')
    lines = [f'# Controller benchmark: {policy}', '',
             '| template | passed | % | paper % | call p50 / p99 [ms] | function p50 / p99 [ms] | wall / episode [s] |',
             '|---|---|---|---|---|---|---|']
    for row in rows:
        paper = '—' if row['paper_percent'] is None else f"{row['paper_percent']:g}"
        lines.append(f"| {row['template']} | {row['passed']}/{row['total']} | {row['percent']:g} | {paper} | "
                     f"{row['call_p50_ms']:g} / {row['call_p99_ms']:g} | {row['function_p50_ms']:g} / "
                     f"{row['function_p99_ms']:g} | {row['wall_seconds_per_episode']:g} |")
    lines += ['', f"Total {passed}/{len(items)}; {wall_seconds:.0f} s of wall time. The paper's figure: its "
                  'cart-pole PD controller balanced the pole for the whole episode; it gives none for impedance '
                  'control.', '']
    for row in rows:
        for key, reason in row['failures'].items():
            lines.append(f'- {key}: {reason}')
    (out / 'report.md').write_text('\n'.join(lines) + '\n', encoding='utf-8')
    bar_chart(out / 'report.png', [f'Controller benchmark: {policy}', f'{passed}/{len(items)} episodes'],
              [Bar(row['template'], row['percent'], row['paper_percent'], f"{row['passed']}/{row['total']}")
               for row in rows])
    return summary


def run_benchmark(options: BenchOptions, episodes: Sequence[ControllerEpisode], real_time: bool = False) -> dict:
    """Run `episodes` one after another in one graph on the policy of `options`; write items.jsonl and the report
    into options.out and return the summary."""
    out = pathlib.Path(options.out)
    out.mkdir(parents=True, exist_ok=True)
    graph = GraphOptions(domain=DOMAIN.name, real_time=real_time)
    graph.llm_backend, lmp = lmp_parameters(options)  # --backend local: the run's server, as an endpoint
    graph.extra = {'lmp_node': lmp}
    if options.policy == 'oracle':
        write_oracle_cassette(episodes, out / CASSETTE)
        graph.cassette = str(out / CASSETTE)
    # The graph comes up in this process: keep it on a DDS domain of its own, on this host.
    use_own_domain(domain_ids(1, options.first_domain_id)[0])
    started = time.monotonic()
    items: list[dict[str, Any]] = []
    runner = Runner(graph, options.episode_timeout_s, lmp.get('feedback_rounds', 0))
    try:
        with open(out / ITEMS, 'w', encoding='utf-8') as stream:
            for index, item in enumerate(episodes, 1):
                try:
                    record = runner.run(item)
                except RuntimeError as error:  # the graph did not answer: a failed episode, the run goes on
                    record = {'key': item.key, 'template': item.template, 'seed': item.seed, 'success': False,
                              'reason': f'the run failed: {error}'}
                items.append(record)
                write_record(stream, record)
                show_progress(index, len(episodes), item.key, record, record.get('wall_seconds', 0))
    finally:
        runner.close()
    return report(items, policy_description(options), time.monotonic() - started, out)


class ControllersBench(GraphBench):
    """The controller benchmark's own options: the templates, the balance episodes' length, real time."""

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        parser.add_argument('--templates', default=','.join(templates.TEMPLATES),
                            help=f'comma-separated [{",".join(templates.TEMPLATES)}]')
        parser.add_argument('--balance-seconds', type=float, default=30.0, help='length of a balance episode [30]')
        parser.add_argument('--real-time', action='store_true', help='simulate in real time (default: as fast as '
                                                                      'possible)')
        parser.add_argument('--set', choices=('benchmark', 'dev'), default='benchmark',
                            help='benchmark: the templates\' episodes; dev: the development set the prompts are '
                                 'tuned on (--templates and --balance-seconds do not apply) [benchmark]')

    def episodes(self, args: argparse.Namespace) -> list[ControllerEpisode]:
        """The run's episodes (ValueError for an unknown template)."""
        if getattr(args, 'set', 'benchmark') == 'dev':
            return devset.episodes(args.trials)
        return [templates.episode(name, args.seed + trial, args.balance_seconds)
                for trial in range(args.trials) for name in comma_separated(args.templates)]

    def options(self, args: argparse.Namespace) -> BenchOptions:
        self.episodes(args)
        if args.rehearse != 'off':
            raise ValueError('controllers run functions of the program at a fixed rate: they are not rehearsed on a '
                             'twin (--rehearse off)')
        return super().options(args)

    def run(self, options: BenchOptions, args: argparse.Namespace) -> dict:
        return run_benchmark(options, self.episodes(args), args.real_time)

    def kept(self, args: argparse.Namespace) -> str:
        return f'the episodes finished so far are in {args.out}/{ITEMS}'


BENCH = ControllersBench(name='controllers', description=__doc__.split('\n\n')[0], out=DEFAULT_OUT, trials=5,
                         seed_aliases=('--base-seed',), resume=False, episode_timeout=600.0,
                         timeout_per='episode (wall time)', default_api='chat')


def main(argv: list[str] | None = None) -> int:
    return BENCH.main(argv)
