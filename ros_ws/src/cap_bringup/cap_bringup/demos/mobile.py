"""The mobile demo: the paper's navigation commands for the mobile robot in the kitchen, through the whole graph.

    cap demo mobile [--out DIR] [--backend cassette|http|local] [--cassette FILE] [--no-video]

By default every answer comes from the mobile domain's cassette of hand-written reference programs (no network, no
model). Each command's code, words and outcome are printed and checked on the base's path, recorded from the
simulator while it runs: the corners of a rectangle reached, the same rectangle turned, a loop around the chairs,
visits to two places in turn, a distance said; a count of snacks, a bottle fetched to the middle of the fruits and
things put away in their bins are checked on the simulator's objects; a search round the barstool that stops at a
corner from which the head camera sees the banana, on the base's path and the simulator's view. DIR gets
map.png (the kitchen from above with each command's path), a video of the run from the camera that follows the
robot (demo.mp4) and summary.json. Exit code 0 when every
command did what it should; 130 on Ctrl-C (the graph is closed first).
"""
from __future__ import annotations

import math
import pathlib
import re
import sys
import threading
from dataclasses import dataclass
from typing import Callable

import numpy as np
from cap_mobile import layout, objects as mobile_objects, robot

from cap_bringup import base_path
from cap_bringup.demos._mobile_map import draw_map
from cap_bringup.demos._support import DemoRun, SimulatedClockSampler, demo_parser, outcome_problems, \
    placed_objects, run_main

Path = np.ndarray  # (N, 2) the base's x, y while a command ran
Objects = list  # the simulator's object states when the command ended
Check = Callable[[Path, list[str], Objects], str]  # (path, words said, objects) -> problem ('' when fine)

CHAIR = np.array(layout.location('office chair').centre)
RECTANGLE = base_path.rectangle_corners('office chair', 3.0, 2.0)
_TURN = np.radians(-45)
TURNED_RECTANGLE = CHAIR + (RECTANGLE - CHAIR) @ np.array([[math.cos(_TURN), -math.sin(_TURN)],
                                                           [math.sin(_TURN), math.cos(_TURN)]]).T
BARSTOOL_SQUARE = base_path.rectangle_corners('barstool', 1.5, 1.5)


def _reached(points: np.ndarray, what: str) -> Check:
    def check(path: Path, said: list[str], objects: Objects) -> str:
        missed = base_path.missed_points(path, points)
        return f'{what}: corner(s) {missed} not reached' if missed else ''
    return check


def _around(names: tuple[str, ...]) -> Check:
    def check(path: Path, said: list[str], objects: Objects) -> str:
        turns = {name: base_path.winding_turns(path, layout.location(name).centre) for name in names}
        short = [f'{name} ({value:+.2f} turns)' for name, value in turns.items() if abs(value) < 0.9]
        return f'not once around {", ".join(short)}' if short else ''
    return check


def _back_and_forth(first: str, second: str, times: int) -> Check:
    def check(path: Path, said: list[str], objects: Objects) -> str:
        places = {name: layout.location(name).approach() for name in (first, second)}
        order = base_path.visits(path, places)
        expected = [first, second] * times
        return '' if order[-len(expected):] == expected else f'visited {order}, not {expected}'
    return check


def _said_distance_to(name: str) -> Check:
    def check(path: Path, said: list[str], objects: Objects) -> str:
        truth = math.dist(path[-1], layout.location(name).centre)
        numbers = [float(n) for text in said for n in re.findall(r'\d+\.\d+|\d+', text)]
        if not any(abs(n - truth) <= 0.1 for n in numbers):
            return f'said {said}, but the {name} is {truth:.1f} m away'
        return ''
    return check


def _counted_on(group: str, surface: str) -> Check:
    def check(path: Path, said: list[str], objects: Objects) -> str:
        truth = sum(1 for state in objects if mobile_objects.GROUPS.get(state.name) == group
                    and mobile_objects.surface_of(*state.position[:2]) == surface)
        numbers = [int(n) for text in said for n in re.findall(r'\b\d+\b', text)]
        return '' if numbers[-1:] == [truth] else f'said {said}, but there are {truth} {group}s on the {surface}'
    return check


def _near(name: str, where: Callable[[Objects], np.ndarray], within: float, what: str) -> Check:
    def check(path: Path, said: list[str], objects: Objects) -> str:
        state = next((s for s in objects if s.name == name), None)
        if state is None:
            return f'no {name} in the scene'
        target = where(objects)
        gap = math.dist(state.position[:2], target[:2])
        return '' if gap <= within else f'the {name} is {gap:.2f} m from {what}'
    return check


def _in_bin(name: str, bin_name: str) -> Check:
    def check(path: Path, said: list[str], objects: Objects) -> str:
        state = next((s for s in objects if s.name == name), None)
        if state is None:
            return f'no {name} in the scene'
        x_min, y_min, x_max, y_max = layout.location(bin_name).footprint
        inside = x_min < state.position[0] < x_max and y_min < state.position[1] < y_max and \
            state.position[2] < layout.location(bin_name).top
        return '' if inside else f'the {name} is at {np.round(state.position, 2).tolist()}, not in the {bin_name}'
    return check


def _fruit_centre(objects: Objects) -> np.ndarray:
    fruit = [np.array(s.position) for s in objects if mobile_objects.GROUPS.get(s.name) == mobile_objects.GROUP_FRUIT
             and mobile_objects.surface_of(*s.position[:2]) == 'table']
    return np.mean(fruit, axis=0)


def _keeps_off(name: str) -> Check:
    def check(path: Path, said: list[str], objects: Objects) -> str:
        gap = base_path.clearance_from(path, layout.location(name).footprint)
        return f'the base came within {gap:.2f} m of the {name}' if gap < layout.BASE_RADIUS else ''
    return check


def _found_from_a_corner(name: str, corners: np.ndarray) -> Check:
    """Went round the corners in turn (either way) and stopped at one from which the head camera sees `name`."""
    def check(path: Path, said: list[str], objects: Objects) -> str:
        order, in_turn = base_path.round_visits(path, corners)
        if not in_turn:
            return f'the base did not go round the square: corners in the order {order}'
        gap = math.dist(path[-1], corners[order[-1]])
        if gap > base_path.REACHED:
            return f'the base stopped {gap:.2f} m from corner {order[-1]}'
        state = next((s for s in objects if s.name == name), None)
        return '' if state is not None and state.visible else f'the head camera does not see the {name} at the stop'
    return check


@dataclass(frozen=True)
class Step:
    command: str
    checks: tuple[Check, ...]


STEPS = (
    Step('move in a 3m by 2m rectangle around the office chair',
         (_reached(RECTANGLE, 'rectangle'), _keeps_off('office chair'))),
    Step('do that again but rotated 45 degrees clockwise',
         (_reached(TURNED_RECTANGLE, 'turned rectangle'), _keeps_off('office chair'))),
    Step('follow the convex hull containing the chairs', (_around(('office chair', 'chair')),)),
    Step('move back and forth between the table and the countertop 3 times',
         (_back_and_forth('table', 'countertop', 3),)),
    Step('how far are you from the desk', (_said_distance_to('desk'),)),
    Step('how many snacks are on the table?', (_counted_on(mobile_objects.GROUP_SNACK, 'table'),)),
    Step('take the water bottle from the desk and put it in the middle of the fruits on the table',
         (_near('water bottle', _fruit_centre, 0.05, 'the middle of the fruits'),)),
    # The bins are named by colour; the user says which is which, and the session remembers it.
    Step('go to the green bin', ()),
    Step('this is the compost bin', ()),
    Step('go to the blue bin', ()),
    Step('this is the recycle bin', ()),
    Step('go to the grey bin', ()),
    Step('this is the landfill bin', ()),
    Step('the coke can and the apple are on the table', ()),
    Step('put away the coke can and the apple on their corresponding bins',
         (_in_bin('coke can', 'blue bin'), _in_bin('apple', 'green bin'))),
    # The banana on the countertop is out of the head camera's view at the bins, in view from the square's first
    # corner facing the barstool.
    Step('go in a 1.5m square around the barstool as many times as needed, check each step if there is a banana, '
         'only stop moving when you see the banana', (_found_from_a_corner('banana', BARSTOOL_SQUARE),)),
)

# The scene: fruit, a can and a snack on the table, the water bottle on the desk, a can on the countertop, the banana
# on the countertop (for the search), placed where the arm reaches them and where "the middle of the fruits" is
# free [m].
SCENE = {'coke can': (1.4, 0.85), 'apple': (1.7, 0.72), 'orange': (2.5, 0.72), 'banana': (-2.0, 2.6),
         'chips bag': (2.3, 0.75), 'water bottle': (3.0, -2.3), 'sprite can': (-1.0, 2.55)}


class PathRecorder(SimulatedClockSampler):
    """The base's x, y every `period` of simulated time, read from the simulator in a thread of its own."""

    def __init__(self, world, period: float = 0.05) -> None:
        self.points: list[np.ndarray] = []
        self._lock = threading.Lock()
        super().__init__(world, period, 'demo_path')

    def sample(self) -> None:
        with self._lock:
            self.points.append(self.world.base_pose()[:2].copy())

    def take(self) -> Path:
        """The points since the last take (at least the base's position now)."""
        with self._lock:
            points, self.points = self.points, []
        return np.array(points + [self.world.base_pose()[:2].copy()])


def run_demo(out_dir: pathlib.Path, backend: str = 'cassette', cassette: str = '', steps=STEPS,
             video: bool = True, log=print) -> dict:
    """Run the commands; return the summary (also written to out_dir/summary.json)."""
    paths: list[tuple[str, Path]] = []

    def draw() -> None:
        if paths:
            run.summary['map'] = str(draw_map(paths, out_dir / 'map.png'))

    with DemoRun(out_dir, len(steps), name='mobile_demo', log=log, video=video, domain='mobile',
                 llm_backend=backend, cassette=cassette, camera_rate=0.0) as run:
        run.reset_scene(placed_objects(SCENE))
        run.wait_for_model()
        run.closing(draw)
        recorder = PathRecorder(run.world)
        run.closing(recorder.close)
        run.record_video(robot.FOLLOW_CAMERA, period=0.4)
        for step in steps:
            recorder.take()
            ran = run.run_command(step.command)
            path = recorder.take()
            paths.append((step.command, path))
            objects = run.world.object_states()
            problems = outcome_problems(ran) + [p for p in (check(path, ran.said, objects) for check in step.checks)
                                                if p]
            travelled = float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1))) if len(path) > 1 else 0.0
            run.report(ran, problems, f'drove {travelled:.1f} m', travelled_m=travelled)
    return run.summary


def main(argv=None) -> int:
    parser = demo_parser('cap demo mobile', __doc__.split('\n\n')[0], 'mobile',
                         'cassette to replay [the mobile domain\'s reference one]')
    return run_main(parser, argv, lambda args: run_demo(args.out, args.backend, args.cassette,
                                                        video=not args.no_video),
                    'did what was asked', 'The map, the video and summary.json are')


if __name__ == '__main__':
    sys.exit(main())
