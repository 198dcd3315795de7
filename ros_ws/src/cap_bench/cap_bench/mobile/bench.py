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

import math
import pathlib
import re
import threading
import time
from typing import Sequence

import numpy as np
from cap_mobile import layout, objects

from cap_bench import episode_runs, template_report
from cap_bench.bench_options import BenchOptions, policy_description
from cap_bench.episode_runs import episode_record, load_records, run_episodes
from cap_bench.graph_cli import TemplateBench
from cap_bench.graph_client import GraphClient, outcome_name, prediction_fields
from cap_bench.mobile import devset
from cap_bench.mobile.episodes import (TEMPLATES, Episode, oracle_program, rectangle_corners, sample_episode,
                                       square_poses)
from cap_bringup import base_path
from cap_lmp.safe_text import one_line

DEFAULT_OUT = 'output/mobile'
UI_LMP = 'mobile_ui'
TARGET_ORACLE_RATE = 0.98  # the bar the reference programs must clear
REACHED = 0.05  # [m] a goal or corner reached
HEADING = 0.05  # [rad]
PLACED = 0.05  # [m] of a fetched object from its spot
CRITERIA = {'reached_m': REACHED, 'heading_rad': HEADING, 'placed_m': PLACED, 'oracle_rate_target': TARGET_ORACLE_RATE}


def plan(templates: Sequence[str], trials: int, base_seed: int = 0) -> list[Episode]:
    return [sample_episode(template, base_seed + trial) for trial in range(trials) for template in templates]


def write_oracle_cassette(episodes: Sequence[Episode], path: pathlib.Path) -> None:
    """One reference program per distinct instruction."""
    episode_runs.write_oracle_cassette(episodes, path, UI_LMP, 'mobile', oracle_program)


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


class MobileRunner(GraphClient):
    """One mobile graph in this process, running episodes one after another."""

    def __init__(self, options: BenchOptions, cassette: pathlib.Path | None) -> None:
        from std_msgs.msg import String

        from cap_interfaces.msg import GraphNames

        super().__init__(options, cassette, 'cap_bench_mobile', domain='mobile', camera_rate=0.0)
        self.said: list[str] = []
        self.node.create_subscription(String, GraphNames.SAY_TOPIC, lambda msg: self.said.append(msg.data), 50)
        self.wait_until_ready('the mobile graph')

    def scene_reset(self) -> None:
        # The mobile pick-and-place node's memory of what it holds goes with the scene.
        self.graph.nodes['mobile_pick_place'].executor_.held = None

    def run(self, episode: Episode) -> dict:
        world = self.graph.world
        record = episode_record(episode, self.options)
        wall_started = time.monotonic()
        if not self.start_episode(episode, record):
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
        try:
            results = self.run_instructions(episode.instructions, record)
            if results is None:
                return record
            time.sleep(0.2)  # the last words on the say topic
        finally:
            recording.set()
            recorder.join()
        done = self.finished(results)
        result = results[-1] if results else None
        world.run_for(0.5)  # what was just let go comes to rest
        path = np.array(points + [world.base_pose()[:2].copy()])
        states = {state.name: state for state in world.object_states()}
        reason = judge(episode, path, world.base_pose(), states, self.said) if done else \
            f'the command ended {outcome_name(result.outcome) if result else "without a result"}: ' \
            f'{one_line(result.message) if result else ""}'
        record.update(code='\n# ---\n'.join(r.code for r in results), success=not reason, reason=reason,
                      outcome=outcome_name(result.outcome) if result is not None else '',
                      said=list(self.said), sim_seconds=round(world.time - sim_started, 3),
                      wall_seconds=round(time.monotonic() - wall_started, 3),
                      travelled_m=round(float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1))), 3),
                      **prediction_fields(results))
        return record


def summarise(records: Sequence[dict], policy: str, wall_seconds: float) -> dict:
    """Per template and overall: passed / trials, the median simulated time; each failure's reason."""
    return template_report.summarise(
        records, TEMPLATES, 'Mobile kitchen: driving, fetching, putting away, counting, searching', policy,
        CRITERIA, wall_seconds, lambda mine: {'sim_seconds_median': float(np.median([r['sim_seconds'] for r in mine]))})


def write_report(summary: dict, out: pathlib.Path) -> None:
    template_report.write_report(summary, out, (('simulated s (median)', 'sim_seconds_median', '.1f'),))


def run_benchmark(options: BenchOptions, templates: Sequence[str], resume: bool = False) -> dict:
    episodes = plan(templates, options.trials, options.base_seed)
    seconds = run_episodes(options, episodes, resume, write_oracle_cassette, MobileRunner)
    out = pathlib.Path(options.out)
    summary = summarise(load_records(out), policy_description(options), seconds)
    write_report(summary, out)
    return summary


def write_dev_cassette(episodes: Sequence[Episode], path: pathlib.Path) -> None:
    """The development set's reference programs, one per instruction."""
    episode_runs.write_oracle_cassette(episodes, path, UI_LMP, 'mobile', devset.reference_program)


def run_devset(options: BenchOptions, resume: bool = False) -> dict:
    """The development set (cap_bench.mobile.devset), `options.trials` times, each command by its kind's judge."""
    seconds = run_episodes(options, devset.episodes(options.trials), resume, write_dev_cassette, MobileRunner)
    out = pathlib.Path(options.out)
    summary = template_report.summarise(
        load_records(out), devset.KINDS, 'Mobile kitchen development set, by kind', policy_description(options),
        CRITERIA, seconds, lambda mine: {'sim_seconds_median': float(np.median([r['sim_seconds'] for r in mine]))})
    write_report(summary, out)
    return summary


BENCH = TemplateBench(name='mobile', description=__doc__.split('\n\n')[0], out=DEFAULT_OUT,
                      templates=tuple(TEMPLATES), run_templates=run_benchmark, run_devset=run_devset)


def main(argv: list[str] | None = None) -> int:
    return BENCH.main(argv)
