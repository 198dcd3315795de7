"""`cap bench mobile`: the mobile robot in the simulated kitchen through the real graph, judged on the simulator's
final state and on the base's recorded path.

Every episode goes the way of a user's commands: the scene is reset through the sim bridge's service (objects where
the episode puts them, the robot at its start pose), the session is reset, the episode's instructions go to
lmp_node's /cap/execute action, the programs (the reference programs replayed from a cassette, or a model's code)
run in the sandbox and drive the navigation and mobile pick-and-place nodes over ROS, and the outcome is judged
(`judge`): where the base went (cap_bringup.base_path), where the objects are, what the robot said. Episodes:
cap_bench.mobile.episodes.

    cap bench mobile --trials 20 --out output/mobile           # the reference programs (oracle)

Results are appended to episodes.jsonl as each episode ends (--resume continues a run); report.json and report.md
summarise them per template, with each failure's reason. One graph runs the episodes one after another.
"""
from __future__ import annotations

import argparse
import json
import math
import pathlib
import re
import signal
import sys
import threading
import time
from typing import Sequence

import numpy as np
import yaml
from cap_mobile import layout, objects

from cap_bench.episode_runs import EPISODES, lmp_parameters, load_records, run_episodes
from cap_bench.mobile.episodes import (TEMPLATES, Episode, oracle_program, rectangle_corners, sample_episode,
                                       square_poses)
from cap_bench.runner import (BenchOptions, Interrupted, _raise_interrupted, _wait, add_model_arguments, domain_ids,
                              model_endpoint, model_settings, outcome_name, policy_description)
from cap_bringup import base_path
from cap_lmp.cassette import FORMAT as CASSETTE_FORMAT, HAND_WRITTEN, normalise_query
from cap_lmp.errors import LLMError
from cap_lmp.safe_text import one_line

DEFAULT_OUT = 'output/mobile'
UI_LMP = 'mobile_ui'
SERVICE_TIMEOUT_S = 60.0
TARGET_ORACLE_RATE = 0.98  # the bar the reference programs must clear
REACHED = 0.05  # [m] a goal or corner reached
HEADING = 0.05  # [rad]
PLACED = 0.05  # [m] of a fetched object from its spot


def plan(templates: Sequence[str], trials: int, base_seed: int = 0) -> list[Episode]:
    return [sample_episode(template, base_seed + trial) for trial in range(trials) for template in templates]


def write_oracle_cassette(episodes: Sequence[Episode], path: pathlib.Path) -> None:
    """One reference program per distinct instruction."""
    entries = {}
    for episode in episodes:
        for instruction in episode.instructions:
            entries[normalise_query(instruction)] = {
                'lmp': UI_LMP, 'query': instruction, 'context': '*',
                'source': f'{HAND_WRITTEN} (cap_bench mobile, {episode.template})',
                'completion': oracle_program(instruction)}
    path.write_text(yaml.safe_dump({'format': CASSETTE_FORMAT, 'entries': list(entries.values())},
                                   sort_keys=False, width=120), encoding='utf-8')


def judge(episode: Episode, path: np.ndarray, final_pose: np.ndarray, states: dict, said: Sequence[str]) -> str:
    """Why the episode failed, or '' when it did what was asked. `states`: object name -> ObjectState at the end."""
    a = episode.attributes
    if episode.template == 'goto':
        goal = layout.location(a['place']).approach()
        gap = math.dist(final_pose[:2], goal[:2])
        turn = abs((final_pose[2] - goal[2] + math.pi) % (2 * math.pi) - math.pi)
        return '' if gap <= REACHED and turn <= HEADING else \
            f'the base ended {gap:.3f} m and {turn:.3f} rad from the {a["place"]}\'s approach pose'
    if episode.template == 'rectangle':
        missed = base_path.missed_points(path, rectangle_corners(a['around'], a['width'], a['height']), REACHED)
        if missed:
            return f'corner(s) {missed} of the rectangle not reached'
        gap = base_path.clearance_from(path, layout.location(a['around']).footprint)
        return '' if gap >= layout.BASE_RADIUS else f'the base came within {gap:.2f} m of the {a["around"]}'
    if episode.template == 'back_and_forth':
        places = {name: layout.location(name).approach() for name in (a['first'], a['second'])}
        expected = [a['first'], a['second']] * a['times']
        order = base_path.visits(path, places, REACHED)
        return '' if order[-len(expected):] == expected else f'visited {order}, not {expected}'
    if episode.template == 'search':
        return _judge_search(a, path, final_pose, states)
    if episode.template == 'fetch':
        state = states[a['object']]
        spot = layout.location(a['destination']).centre
        surface = objects.surface_of(*state.position[:2])
        gap = math.dist(state.position[:2], spot)
        if surface != a['destination'] or gap > PLACED:
            return (f'the {a["object"]} is on the {surface or "floor"}, {gap:.3f} m from the '
                    f'{a["destination"]}\'s middle')
        return ''
    if episode.template == 'bin':
        state = states[a['object']]
        x_min, y_min, x_max, y_max = layout.location(a['bin']).footprint
        inside = x_min < state.position[0] < x_max and y_min < state.position[1] < y_max
        where = np.round(state.position, 2).tolist()
        return '' if inside else f'the {a["object"]} is at {where}, not in the {a["bin"]} (told: the {a["label"]})'
    truth = sum(1 for state in states.values() if objects.GROUPS.get(state.name) == a['group']
                and objects.surface_of(*state.position[:2]) == a['surface'])
    numbers = [int(n) for text in said for n in re.findall(r'\b\d+\b', text)]
    return '' if numbers[-1:] == [truth] else f'said {list(said)}, but there are {truth} {a["group"]}s on the ' \
        f'{a["surface"]}'


def _judge_search(a: dict, path: np.ndarray, final_pose: np.ndarray, states: dict) -> str:
    """Round the square's corners (from any corner, either way round), stopped at the first one from which the object
    is seen (facing the location's centre: the episode's `seen_from`), and the head camera sees it where the base
    stopped (the simulator's ray test now)."""
    corners = square_poses(a['around'], a['side'])[:, :2]
    order, in_turn = base_path.round_visits(path, corners, REACHED)
    thing, seen_from = a['object'], a['seen_from']
    if not order:
        return f'the base reached no corner of the square around the {a["around"]}'
    if not in_turn:
        return f'the base did not go round the square: corners in the order {order}'
    first = next((visit for visit, corner in enumerate(order) if seen_from[corner]), None)
    if first is None:
        return (f'the base stopped after corners {order}, before any corner the {thing} is seen from '
                f'({[i for i, seen in enumerate(seen_from) if seen]})')
    if first < len(order) - 1:
        return f'the {thing} is seen from corner {order[first]}, but the base went on to corners {order[first + 1:]}'
    gap = math.dist(final_pose[:2], corners[order[-1]])
    if gap > REACHED:
        return f'the base ended {gap:.3f} m from corner {order[-1]}, where the {thing} is seen from'
    if not states[thing].visible:
        return f'the head camera does not see the {thing} where the base ended ({np.round(final_pose, 2).tolist()})'
    return ''


class MobileRunner:
    """One mobile graph in this process, running episodes one after another."""

    def __init__(self, options: BenchOptions, cassette: pathlib.Path | None) -> None:
        import rclpy
        from cap_ros_common.actions import ActionClient
        from rclpy.context import Context
        from std_msgs.msg import String
        from std_srvs.srv import Trigger

        from cap_bringup.graph import Graph, GraphOptions
        from cap_interfaces.action import ExecuteCommand
        from cap_interfaces.msg import GraphNames
        from cap_interfaces.srv import ResetScene

        self.options = options
        self.context = Context()
        rclpy.init(context=self.context)
        backend, lmp = lmp_parameters(options)
        self.graph = Graph(self.context, GraphOptions(
            domain='mobile', llm_backend=backend, cassette=str(cassette) if cassette else '', camera_rate=0.0,
            extra={'lmp_node': lmp}))
        self.node = rclpy.create_node('cap_bench_mobile', context=self.context)
        self.graph.executor.add_node(self.node)
        self.said: list[str] = []
        self.node.create_subscription(String, GraphNames.SAY_TOPIC, lambda msg: self.said.append(msg.data), 50)
        self.execute = ActionClient(self.node, ExecuteCommand, GraphNames.EXECUTE_ACTION)
        self.reset = self.node.create_client(ResetScene, GraphNames.SIM_RESET_SERVICE)
        self.reset_session = self.node.create_client(Trigger, GraphNames.RESET_SESSION_SERVICE)
        self.ExecuteCommand, self.ResetScene, self.Trigger = ExecuteCommand, ResetScene, Trigger
        if not _wait(lambda: self.execute.server_is_ready() and self.reset.service_is_ready()
                     and self.reset_session.service_is_ready(), 60):
            raise RuntimeError('the mobile graph did not come up within 60 s')

    def _call(self, future, timeout: float, what: str):
        if not _wait(future.done, timeout):
            raise TimeoutError(f'no answer from {what} within {timeout:.0f} s')
        return future.result()

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
            ObjectSpec(name=o.name, use_position=True, position=Point(x=o.xy[0], y=o.xy[1])) for o in episode.objects])
        answer = self._call(self.reset.call_async(request), SERVICE_TIMEOUT_S, 'the scene reset')
        if not answer.success:
            record['reason'] = f'scene reset failed: {answer.message}'
            return record
        self._call(self.reset_session.call_async(self.Trigger.Request()), SERVICE_TIMEOUT_S,
                   'lmp_node (reset session)')
        # The mobile pick-and-place node's memory of what it holds goes with the scene.
        self.graph.nodes['mobile_pick_place'].executor_.held = None
        names = {o.name for o in episode.objects}
        if not _wait(lambda: self._perceived() == names, 30):
            record['reason'] = f'perception did not report the reset scene within 30 s: {sorted(self._perceived())}'
            return record
        sim_started = world.time
        self.said.clear()
        points, recording = [], threading.Event()

        def record_path() -> None:
            while not recording.is_set():
                points.append(world.base_pose()[:2].copy())
                time.sleep(0.01)

        recorder = threading.Thread(target=record_path, daemon=True)
        recorder.start()
        codes, result = [], None
        try:
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
            time.sleep(0.2)  # the last words on the say topic
        finally:
            recording.set()
            recorder.join()
        done = result is not None and result.outcome == self.ExecuteCommand.Result.OUTCOME_DONE
        world.run_for(0.5)  # what was just let go comes to rest
        path = np.array(points + [world.base_pose()[:2].copy()])
        states = {state.name: state for state in world.object_states()}
        reason = judge(episode, path, world.base_pose(), states, self.said) if done else \
            f'the command ended {outcome_name(result.outcome) if result else "without a result"}: ' \
            f'{one_line(result.message) if result else ""}'
        record.update(code='\n# ---\n'.join(codes), success=not reason, reason=reason,
                      outcome=outcome_name(result.outcome) if result is not None else '',
                      said=list(self.said), sim_seconds=round(world.time - sim_started, 3),
                      wall_seconds=round(time.monotonic() - wall_started, 3),
                      travelled_m=round(float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1))), 3))
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


def summarise(records: Sequence[dict], policy: str, wall_seconds: float) -> dict:
    rows = []
    for template in TEMPLATES:
        mine = [r for r in records if r['template'] == template]
        if mine:
            rows.append({'template': template, 'trials': len(mine), 'successes': sum(r['success'] for r in mine),
                         'percent': 100.0 * sum(r['success'] for r in mine) / len(mine),
                         'sim_seconds_median': float(np.median([r['sim_seconds'] for r in mine]))})
    total, passed = len(records), sum(r['success'] for r in records)
    return {'title': 'Mobile kitchen: driving, fetching, putting away, counting, searching', 'policy': policy,
            'criteria': {'reached_m': REACHED, 'heading_rad': HEADING, 'placed_m': PLACED,
                         'oracle_rate_target': TARGET_ORACLE_RATE},
            'rows': rows, 'overall': {'trials': total, 'successes': passed,
                                      'percent': 100.0 * passed / total if total else None},
            'wall_seconds': round(wall_seconds, 1),
            'episode_wall_seconds_median': float(np.median([r['wall_seconds'] for r in records])) if records else 0,
            'failures': {r['key']: r['reason'] for r in records if not r['success']}}


def write_report(summary: dict, out: pathlib.Path) -> None:
    (out / 'report.json').write_text(json.dumps(summary, indent=2), encoding='utf-8')
    lines = [f"# {summary['title']}", '', f"Policy: {summary['policy']}", '',
             '| template | trials | passed % | simulated s (median) |', '|---|---|---|---|']
    for row in summary['rows']:
        lines.append(f"| {row['template']} | {row['trials']} | {row['percent']:.1f} | "
                     f"{row['sim_seconds_median']:.1f} |")
    overall = summary['overall']
    percent = '—' if overall['percent'] is None else f"{overall['percent']:.1f}"
    lines.append(f"| **all** | {overall['trials']} | **{percent}** | |")
    if summary['failures']:
        lines += ['', '## Failures', ''] + [f'- `{key}`: {reason}' for key, reason in summary['failures'].items()]
    (out / 'report.md').write_text('\n'.join(lines) + '\n', encoding='utf-8')


def run_benchmark(options: BenchOptions, templates: Sequence[str], resume: bool = False) -> dict:
    episodes = plan(templates, options.trials, options.base_seed)
    seconds = run_episodes(options, episodes, resume, write_oracle_cassette, MobileRunner, base_record)
    out = pathlib.Path(options.out)
    summary = summarise(load_records(out), policy_description(options), seconds)
    write_report(summary, out)
    return summary


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog='cap bench mobile', description=__doc__.split('\n\n')[0])
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
        print(f'cap bench mobile: error: unknown templates {unknown}' if unknown else
              'cap bench mobile: error: --trials must be at least 1', file=sys.stderr)
        return 2
    options = BenchOptions(policy=args.policy, out=args.out, trials=args.trials, base_seed=args.seed,
                           episode_timeout_s=args.episode_timeout, first_domain_id=domain_ids(1)[0],
                           **model_settings(args))
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, _raise_interrupted)
    try:
        with model_endpoint(options, 'mobile') as options:
            summary = run_benchmark(options, templates, args.resume)
    except LLMError as error:
        print(f'cap bench mobile: error: {one_line(str(error))}', file=sys.stderr)
        return 2
    except Interrupted as interrupted:
        print(f'interrupted ({interrupted}): the episodes finished so far are in {args.out}/{EPISODES}',
              file=sys.stderr)
        return interrupted.exit_code
    print(json.dumps({key: summary[key] for key in ('overall', 'rows', 'wall_seconds')}))
    return 0


if __name__ == '__main__':
    sys.exit(main())
