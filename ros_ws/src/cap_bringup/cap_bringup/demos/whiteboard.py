"""The whiteboard demo: the paper's ten-command drawing session, run through the whole graph in simulation.

    cap demo whiteboard [--out DIR] [--backend cassette|http|local] [--cassette FILE] [--no-video]

By default every answer comes from the whiteboard domain's cassette of hand-written reference programs (no network,
no model). Each command's code, words and outcome are printed and checked on the board's ink, as read from the
bridge's GetInk service: a drawing adds ink where it should, an erase takes it away. Per command, the ink image and
the top camera's view before and after go to DIR/commands/, with a video of the run (top camera) and
summary.json. Exit code 0 when every command did what it should; 130 on Ctrl-C (the graph is closed first).
"""
from __future__ import annotations

import pathlib
import sys
from dataclasses import dataclass
from typing import Callable

import numpy as np
from cap_whiteboard import board

from cap_bringup.demos._support import DemoRun, demo_parser, outcome_problems, placed_objects, result_of, run_main

# The scene: two blocks and two fruit, placed by hand where the session's drawings leave them room [m].
SCENE = {'red block': (0.18, -0.52), 'blue block': (0.05, -0.37), 'apple': (-0.17, -0.52), 'lemon': (-0.12, -0.38)}
CATEGORIES = {'red block': ('block', 'red'), 'blue block': ('block', 'blue'), 'apple': ('apple', 'red'),
              'lemon': ('lemon', 'yellow')}

Ink = np.ndarray
Check = Callable[[Ink, Ink], str]  # (ink before, ink after) -> problem ('' when fine)


def _pixels_near(ink: Ink, centre, inner: float, outer: float) -> int:
    """Inked pixels whose centre lies between `inner` and `outer` metres from `centre`."""
    rows, cols = np.nonzero(ink)
    x = board.X_RANGE[0] + (cols + 0.5) * board.INK_RESOLUTION
    y = board.Y_RANGE[1] - (rows + 0.5) * board.INK_RESOLUTION
    distance = np.hypot(x - centre[0], y - centre[1])
    return int(((distance >= inner) & (distance <= outer)).sum())


def _drew(at, within: float = 0.06, least: int = 100) -> Check:
    """New ink (at least `least` mm^2) within `within` of `at` (a named place, an object, or a point)."""
    def check(before: Ink, after: Ink) -> str:
        centre = SCENE.get(at) or board.PLACES.get(at) or at
        added = _pixels_near((after > 0) & (before == 0), centre, 0.0, within)
        return '' if added >= least else f'only {added} mm^2 of new ink within {within} m of {at}'
    return check


def _ring_around(name: str) -> Check:
    """Ink all around the object (in each quarter around it), clear of the object itself."""
    def check(before: Ink, after: Ink) -> str:
        x0, y0 = SCENE[name]
        new = (after > 0) & (before == 0)
        rows, cols = np.nonzero(new)
        x = board.X_RANGE[0] + (cols + 0.5) * board.INK_RESOLUTION - x0
        y = board.Y_RANGE[1] - (rows + 0.5) * board.INK_RESOLUTION - y0
        near = (np.hypot(x, y) > 0.03) & (np.hypot(x, y) < 0.09)
        quarters = {(bool(a), bool(b)) for a, b in zip(x[near] > 0, y[near] > 0)}
        return '' if len(quarters) == 4 else f'the new ink does not go around the {name}'
    return check


def _nothing_around(name: str) -> Check:
    def check(before: Ink, after: Ink) -> str:
        added = _pixels_near((after > 0) & (before == 0), SCENE[name], 0.0, 0.06)
        return '' if added < 20 else f'{added} mm^2 of new ink around the {name}'
    return check


def _erased(before_fraction: float = 0.05) -> Check:
    """At most `before_fraction` of the ink there was is left."""
    def check(before: Ink, after: Ink) -> str:
        was, left = int((before > 0).sum()), int((after > 0).sum())
        return '' if left <= before_fraction * max(was, 1) else f'{left} of {was} mm^2 of ink left'
    return check


def _bigger() -> Check:
    """The ink now spans a wider box than before (the shapes grew)."""
    def check(before: Ink, after: Ink) -> str:
        def width(ink: Ink) -> int:
            cols = np.nonzero(ink.any(axis=0))[0]
            return int(cols.max() - cols.min()) if len(cols) else 0
        return '' if width(after) > 1.3 * width(before) else f'the drawing spans {width(after)} mm, was {width(before)}'
    return check


@dataclass(frozen=True)
class Step:
    command: str
    checks: tuple[Check, ...]


STEPS = (
    Step('draw a 5cm hexagon around the middle', (_drew('middle', 0.04),)),
    Step('draw a line that bisects the hexagon', (_drew('middle', 0.06),)),
    Step('make them both bigger', (_bigger(),)),
    Step('erase the hexagon and the line', (_erased(),)),
    Step('draw the sun as a circle at the top right', (_drew((0.15, -0.388), 0.06),)),
    Step('draw the ground as a line at the bottom', (_drew((0.0, -0.64), 0.2),)),
    Step('draw a pyramid as a triangle on the ground', (_drew((0.06, -0.61), 0.07),)),
    Step('draw a smaller pyramid a little bit to the left', (_drew((-0.065, -0.62), 0.05),)),
    Step('draw circles around the blocks', (_ring_around('red block'), _ring_around('blue block'))),
    Step('draw a square around the sweeter fruit', (_ring_around('apple'), _nothing_around('lemon'))),
)


def run_demo(out_dir: pathlib.Path, backend: str = 'cassette', cassette: str = '', steps=STEPS,
             video: bool = True, log=print) -> dict:
    """Run the session; return the summary (also written to out_dir/summary.json)."""
    import cv2

    from cap_interfaces.msg import GraphNames
    from cap_interfaces.srv import GetInk

    (out_dir / 'commands').mkdir(parents=True, exist_ok=True)
    run = DemoRun(out_dir, len(steps), name='whiteboard_demo', log=log, video=video, domain='whiteboard', seed=0,
                  objects=', '.join(SCENE), llm_backend=backend, cassette=cassette, camera_rate=0.0)
    get_ink = run.service(GetInk, GraphNames.SIM_GET_INK_SERVICE)

    def ink() -> Ink:
        answer = result_of(get_ink.call_async(GetInk.Request()), 30, 'the ink')
        return cv2.imdecode(np.frombuffer(bytes(answer.image.data), np.uint8), cv2.IMREAD_GRAYSCALE)

    def save(image: Ink, name: str) -> None:
        cv2.imwrite(str(out_dir / 'commands' / f'{name}-ink.png'), 255 - image)
        rgb, _ = run.world.render('top', 640, 480, with_depth=False, quality='pretty')
        cv2.imwrite(str(out_dir / 'commands' / f'{name}-top.png'), rgb[..., ::-1])

    with run:
        run.wait_for_model()
        run.reset_scene(placed_objects(SCENE, CATEGORIES))
        run.wait_for_perception(SCENE)
        run.record_video('top')
        for index, step in enumerate(steps, start=1):
            before = ink()
            save(before, f'{index:02d}-before')
            ran = run.run_command(step.command)
            after = ink()
            save(after, f'{index:02d}-after')
            problems = outcome_problems(ran) + [p for p in (check(before, after) for check in step.checks) if p]
            inked = int((after > 0).sum())
            run.report(ran, problems, f'ink {inked} mm^2', ink_mm2=inked)
    return run.summary


def main(argv=None) -> int:
    parser = demo_parser('cap demo whiteboard', __doc__.split('\n\n')[0], 'whiteboard',
                         'cassette to replay [the whiteboard domain\'s reference one]')
    return run_main(parser, argv, lambda args: run_demo(args.out, args.backend, args.cassette,
                                                        video=not args.no_video),
                    'did what was asked', 'Ink images, camera views, video and summary.json are')


if __name__ == '__main__':
    sys.exit(main())
