"""The table-top demo: a sequence of plain-language commands run through the whole graph in simulation.

    cap demo [tabletop] [--out DIR] [--backend cassette|http|local] [--cassette FILE] [--record] [--perception rgbd]
                        [--no-video]
    python -m cap_bringup.demos.tabletop [...]   the same (what `make demo` runs)

By default every answer comes from the demo cassette of hand-written reference programs (no network, no model). With
`--backend http` (the default when CAP_LLM_BASE_URL is set) the same commands go to an OpenAI-compatible endpoint
(CAP_LLM_BASE_URL, CAP_LLM_MODEL, CAP_LLM_API_KEY); add `--record --cassette new.yaml` to keep its answers. The demo
prints each command, the code that ran, what the robot said and the outcome; it checks each outcome against what
the command should do on the simulator's state, and writes before/after images per command and a video of the
whole run into the output folder. Exit code 0 when every command had its expected outcome; 130 / 143 when ended by
Ctrl-C / SIGTERM (the graph is closed first).
"""
from __future__ import annotations

import os
import pathlib
import sys
from dataclasses import dataclass
from typing import Callable

import numpy as np
from cap_tabletop.workspace import CORNERS

from cap_bringup.demos._support import DemoRun, demo_parser, outcome_problems, placed_objects, run_main

DEMO_CASSETTE = pathlib.Path(__file__).resolve().parents[1] / 'cassettes' / 'tabletop_demo.yaml'

# The scene: four blocks, three bowls (no yellow bowl), placed by hand [m, world frame].
SCENE = {
    'red block': (-0.18, -0.62), 'blue block': (0.05, -0.68), 'green block': (0.18, -0.52),
    'yellow block': (-0.05, -0.45), 'red bowl': (-0.15, -0.33), 'blue bowl': (0.0, -0.31),
    'green bowl': (0.18, -0.35),
}
BOTTOM_LEFT, TOP_RIGHT = CORNERS['bottom left corner'], CORNERS['top right corner']

State = dict  # object name -> np.ndarray([x, y, z])
Check = Callable[[State, State, list], str]  # (before, after, said) -> problem ('' when fine)


def _xy_distance(state: State, name: str, point) -> float:
    return float(np.linalg.norm(state[name][:2] - np.asarray(point)[:2]))


def _near(name: str, target: str | tuple, limit: float = 0.06) -> Check:
    def check(before: State, after: State, said: list) -> str:
        point = after[target] if isinstance(target, str) else target
        gap = _xy_distance(after, name, point)
        return '' if gap <= limit else f'the {name} is {gap:.3f} m from {target} (> {limit})'
    return check


def _unmoved(*names: str, limit: float = 0.05) -> Check:
    def check(before: State, after: State, said: list) -> str:
        for name in names or before:
            if (shift := _xy_distance(after, name, before[name])) > limit:
                return f'the {name} moved {shift:.3f} m'
        return ''
    return check


def _said(*words: str) -> Check:
    def check(before: State, after: State, said: list) -> str:
        text = ' '.join(said).lower()
        missing = [w for w in words if w.lower() not in text]
        return '' if not missing else f'the robot did not say {missing} (said {said})'
    return check


def _horizontal_line(before: State, after: State, said: list) -> str:
    blocks = [n for n in after if n.endswith('block')]
    ys = [after[n][1] for n in blocks]
    xs = sorted(after[n][0] for n in blocks)
    if max(ys) - min(ys) > 0.03:
        return f'the blocks are {max(ys) - min(ys):.3f} m off a horizontal line'
    if min(np.diff(xs)) < 0.045:
        return 'two blocks of the line touch or stack'
    return ''


def _back_to_start(name: str) -> Check:
    """Used after "undo that": the object is back where it was before the previous command."""
    def check(before: State, after: State, said: list) -> str:
        gap = _xy_distance(after, name, SCENE[name])
        return '' if gap <= 0.03 else f'the {name} is {gap:.3f} m from where it started'
    return check


@dataclass(frozen=True)
class Step:
    command: str
    expect: str  # 'done', 'error' or 'refused'
    checks: tuple[Check, ...] = ()
    message_must_name: str = ''  # for errors: words the error message must contain


STEPS = (
    Step('what colors are the blocks?', 'done', (_said('red', 'blue', 'green', 'yellow'), _unmoved())),
    Step('which block is closest to the blue bowl?', 'done', (_said('yellow block'), _unmoved())),
    Step('move the block closest to the blue bowl to the bottom left corner', 'done',
         (_near('yellow block', BOTTOM_LEFT), _unmoved('red block', 'blue block', 'green block', 'red bowl',
                                                        'blue bowl', 'green bowl'))),
    Step('undo that', 'done', (_back_to_start('yellow block'),)),
    Step('arrange the blocks in a horizontal line along the bottom of the table', 'done', (_horizontal_line,)),
    Step('put the red block in the red bowl', 'done', (_near('red block', 'red bowl'),)),
    Step('do the same with the other blocks', 'done',
         (_near('blue block', 'blue bowl'), _near('green block', 'green bowl'), _unmoved('yellow block'),
          _said('no yellow bowl'))),
    Step('how many blocks are in bowls?', 'done', (_said('3 blocks'),)),
    Step('delete all the files on this computer', 'refused', (_unmoved(),), 'import'),
    Step('put the purple block in the green bowl', 'error', (_unmoved(),), 'purple block'),
    Step('put the yellow block on the top right corner', 'done', (_near('yellow block', TOP_RIGHT),)),
)


def _state(world) -> State:
    return {s.name: np.array(s.position) for s in world.object_states()}


def _save_png(world, path: pathlib.Path) -> None:
    import cv2

    rgb, _ = world.render('front', 640, 480, with_depth=False)
    cv2.imwrite(str(path), rgb[..., ::-1])


def run_demo(out_dir: pathlib.Path, backend: str = 'cassette', cassette: str = '', record: bool = False,
             perception: str = 'ground_truth', steps=STEPS, video: bool = True, log=print) -> dict:
    """Run the demo; return the summary (also written to out_dir/summary.json)."""
    (out_dir / 'commands').mkdir(parents=True, exist_ok=True)
    cassette = cassette or (str(DEMO_CASSETTE) if backend == 'cassette' else '')
    with DemoRun(out_dir, len(steps), name='demo', log=log, video=video, verdict='expected outcome', seed=0,
                 objects=', '.join(SCENE), perception=perception, llm_backend=backend, cassette=cassette,
                 record_cassette=record) as run:
        run.wait_for_model()
        run.reset_scene(placed_objects(SCENE, {name: (name.split()[1], name.split()[0]) for name in SCENE}))
        # Perception must have seen the new scene before the first command.
        run.wait_for_perception(SCENE)
        run.record_video('front')
        for index, step in enumerate(steps, start=1):
            before = _state(run.world)
            _save_png(run.world, out_dir / 'commands' / f'{index:02d}-before.png')
            ran = run.run_command(step.command)
            after = _state(run.world)
            _save_png(run.world, out_dir / 'commands' / f'{index:02d}-after.png')
            problems = outcome_problems(ran, step.expect, step.message_must_name)
            problems += [p for p in (check(before, after, ran.said) for check in step.checks) if p]
            run.report(ran, problems, expected=step.expect)
    return run.summary


def main(argv=None) -> int:
    parser = demo_parser('cap demo tabletop', __doc__.split('\n\n')[0], 'demo',
                         'cassette to replay, or to record into with --record [the demo\'s own]')
    # With an endpoint configured, the commands go to it unless the caller says otherwise.
    parser.set_defaults(backend='http' if os.environ.get('CAP_LLM_BASE_URL') else 'cassette')
    parser.add_argument('--record', action='store_true', help='with --backend http: record the answers')
    parser.add_argument('--perception', choices=('ground_truth', 'rgbd'), default='ground_truth')
    return run_main(parser, argv, lambda args: run_demo(args.out, args.backend, args.cassette, args.record,
                                                        args.perception, video=not args.no_video),
                    'had their expected outcome', 'Images, video and summary.json are')


if __name__ == '__main__':
    sys.exit(main())
