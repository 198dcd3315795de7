"""The table-top demo: a sequence of plain-language commands run through the whole graph in simulation.

    python -m cap_bringup.demo [--out DIR] [--backend cassette|http] [--cassette FILE] [--record] [--perception rgbd]
    cap demo [tabletop] [...]         the same;  cap demo whiteboard [...]: the whiteboard session (whiteboard_demo.py);
                                      cap demo mobile [...]: the mobile robot's navigation commands (mobile_demo.py)

By default every answer comes from the demo cassette of hand-written reference programs (no network, no model). With
`--backend http` the same commands go to an OpenAI-compatible endpoint (CAP_LLM_BASE_URL, CAP_LLM_MODEL,
CAP_LLM_API_KEY); add `--record --cassette new.yaml` to keep its answers. The demo prints each command, the code
that ran, what the robot said and the outcome; it checks each outcome against what the command should do on the
simulator's state, and writes before/after images per command and a video of the whole run into the output folder.
Exit code 0 when every command had its expected outcome; 130 / 143 when ended by Ctrl-C / SIGTERM (the graph is
closed first). Everything printed that comes from the graph has its control characters escaped.
"""
from __future__ import annotations

import argparse
import json
import os
import pathlib
import sys
import threading
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from cap_lmp.safe_text import terminal_text
from cap_lmp.local_server import MODEL_READY_TIMEOUT_S
from cap_tabletop.workspace import CORNERS

DEMO_CASSETTE = pathlib.Path(__file__).resolve().parent / 'cassettes' / 'tabletop_demo.yaml'

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


class VideoRecorder:
    """Renders a camera every `period` of simulated time and writes an MP4 (H.264 via imageio-ffmpeg)."""

    def __init__(self, world, path: pathlib.Path, period: float = 0.2, fps: int = 15,
                 size: tuple[int, int] = (640, 480), camera: str = 'front') -> None:
        import imageio_ffmpeg

        self.world, self.period, self.size, self.camera = world, period, size, camera
        self._writer = imageio_ffmpeg.write_frames(str(path), size, fps=fps, macro_block_size=8,
                                                   output_params=['-loglevel', 'error'])
        self._writer.send(None)
        self._stop = threading.Event()
        self.frames = 0
        self._thread = threading.Thread(target=self._run, name='demo_video', daemon=True)
        self._thread.start()

    def _run(self) -> None:
        next_time = self.world.time
        while not self._stop.is_set():
            if self.world.time < next_time:
                time.sleep(0.002)
                continue
            rgb, _ = self.world.render(self.camera, *self.size, with_depth=False)
            self._writer.send(np.ascontiguousarray(rgb))
            self.frames += 1
            next_time += self.period

    def close(self) -> None:
        self._stop.set()
        self._thread.join(10)
        self._writer.close()


def _state(world) -> State:
    return {s.name: np.array(s.position) for s in world.object_states()}


def _save_png(world, path: pathlib.Path) -> None:
    import cv2

    rgb, _ = world.render('front', 640, 480, with_depth=False)
    cv2.imwrite(str(path), rgb[..., ::-1])


def run_demo(out_dir: pathlib.Path, backend: str = 'cassette', cassette: str = '', record: bool = False,
             perception: str = 'ground_truth', steps=STEPS, video: bool = True, log=print) -> dict:
    """Run the demo; return the summary (also written to out_dir/summary.json)."""
    import rclpy
    from geometry_msgs.msg import Point
    from cap_ros_common.actions import ActionClient
    from rclpy.context import Context
    from std_msgs.msg import String

    from cap_interfaces.action import ExecuteCommand
    from cap_interfaces.msg import GraphNames, ObjectSpec
    from cap_interfaces.srv import ResetScene

    from cap_bringup.graph import Graph, GraphOptions
    from cap_lmp_ros.lmp_node import outcome_name

    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / 'commands').mkdir(exist_ok=True)
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    context = Context()
    rclpy.init(context=context)
    graph = Graph(context, GraphOptions(
        seed=0, objects=', '.join(SCENE), perception=perception, llm_backend=backend,
        cassette=cassette or (str(DEMO_CASSETTE) if backend == 'cassette' else ''), record_cassette=record))
    user = rclpy.create_node('demo', context=context)
    graph.executor.add_node(user)
    said: list[str] = []
    user.create_subscription(String, GraphNames.SAY_TOPIC, lambda m: said.append(m.data), 50)
    execute = ActionClient(user, ExecuteCommand, GraphNames.EXECUTE_ACTION)
    reset = user.create_client(ResetScene, GraphNames.SIM_RESET_SERVICE)
    summary: dict = {'output': str(out_dir), 'steps': []}
    recorder = None
    started = time.monotonic()
    try:
        _wait(lambda: execute.server_is_ready() and reset.service_is_ready(), 30, 'the graph to come up')
        if backend == 'local':  # the model loads and reads its prompts first (minutes on one core, once)
            log('waiting for the local model to load and read its prompts ...')
            _wait(graph.nodes['lmp_node'].model_ready.is_set, MODEL_READY_TIMEOUT_S, 'the local model')
        request = ResetScene.Request(seed=0, objects=[
            ObjectSpec(name=name, category=name.split()[1], color_name=name.split()[0], use_position=True,
                       position=Point(x=xy[0], y=xy[1])) for name, xy in SCENE.items()])
        answer = _call(reset.call_async(request), 30, 'the scene reset')
        if not answer.success:
            raise RuntimeError(f'scene reset failed: {answer.message}')
        # Perception must have seen the new scene before the first command.
        _wait(lambda: _names_known(graph, SCENE), 30, 'perception to see the scene')
        if video:
            recorder = VideoRecorder(graph.world, out_dir / 'demo.mp4')
        for index, step in enumerate(steps, start=1):
            log(f'\n[{index}/{len(steps)}] > {terminal_text(step.command)}')
            before = _state(graph.world)
            _save_png(graph.world, out_dir / 'commands' / f'{index:02d}-before.png')
            said.clear()
            sim_started, wall_started = graph.world.time, time.monotonic()
            goal = _call(execute.send_goal_async(ExecuteCommand.Goal(command=step.command)),
                         30, 'lmp_node to accept the command')
            result = _call(goal.get_result_async(), 900, 'the command to finish').result
            time.sleep(0.2)  # let the last /cap/say message arrive
            after = _state(graph.world)
            _save_png(graph.world, out_dir / 'commands' / f'{index:02d}-after.png')
            outcome = outcome_name(result.outcome)
            problems = [] if outcome == step.expect else [f'expected {step.expect}, got {outcome}']
            if step.message_must_name and step.message_must_name not in result.message:
                problems.append(f'the message does not name {step.message_must_name!r}')
            problems += [p for p in (check(before, after, list(said)) for check in step.checks) if p]
            # Code, said lines and messages come from the graph: never a raw control character on the terminal.
            log('code:\n' + '\n'.join('    ' + line for line in terminal_text(result.code).splitlines()))
            for text in said:
                log(f'robot says: {terminal_text(text)}')
            log(f'outcome: {outcome}' + (f' ({terminal_text(result.message)})' if not result.success else '')
                + f'; {graph.world.time - sim_started:.1f} s simulated, {time.monotonic() - wall_started:.1f} s wall')
            log('expected outcome: ' + ('yes' if not problems else 'NO: ' + terminal_text('; '.join(problems))))
            summary['steps'].append({'command': step.command, 'expected': step.expect, 'outcome': outcome,
                                     'as_expected': not problems, 'problems': problems, 'code': result.code,
                                     'said': list(said), 'message': result.message,
                                     'sim_seconds': graph.world.time - sim_started,
                                     'wall_seconds': time.monotonic() - wall_started})
    finally:
        if recorder is not None:
            recorder.close()
            summary['video'] = str(out_dir / 'demo.mp4')
            summary['video_frames'] = recorder.frames
        graph.close()
        user.destroy_node()
        context.try_shutdown()
    summary['all_as_expected'] = all(s['as_expected'] for s in summary['steps']) and \
        len(summary['steps']) == len(steps)
    summary['wall_seconds'] = time.monotonic() - started
    (out_dir / 'summary.json').write_text(json.dumps(summary, indent=2))
    return summary


def _names_known(graph, scene) -> bool:
    source = graph.nodes['perception_node'].source
    try:
        return set(source.names()) == set(scene)
    except Exception:  # no observation yet
        return False


def _wait(predicate, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise TimeoutError(f'timed out waiting for {what}')
        time.sleep(0.01)


def _call(future, timeout: float, what: str):
    _wait(future.done, timeout, what)
    return future.result()


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ['whiteboard']:  # `cap demo whiteboard`: the whiteboard domain's session
        from cap_bringup import whiteboard_demo
        return whiteboard_demo.main(argv[1:])
    if argv[:1] == ['mobile']:  # `cap demo mobile`: the mobile domain's navigation commands
        from cap_bringup import mobile_demo
        return mobile_demo.main(argv[1:])
    if argv[:1] == ['tabletop']:
        argv = argv[1:]
    parser = argparse.ArgumentParser(prog='cap-demo', description=__doc__.split('\n\n')[0])
    parser.add_argument('--out', type=pathlib.Path,
                        default=pathlib.Path('output') / time.strftime('demo-%Y%m%d-%H%M%S'))
    parser.add_argument('--backend', choices=('cassette', 'http', 'local'),
                        default='http' if os.environ.get('CAP_LLM_BASE_URL') else 'cassette',
                        help='cassette (default), http (default when CAP_LLM_BASE_URL is set) or local (the '
                             'llama.cpp server and model of `make model`)')
    parser.add_argument('--cassette', default='', help='cassette to replay, or to record into with --record')
    parser.add_argument('--record', action='store_true', help='with --backend http: record the answers')
    parser.add_argument('--perception', choices=('ground_truth', 'rgbd'), default='ground_truth')
    parser.add_argument('--no-video', action='store_true')
    args = parser.parse_args(argv)
    try:  # SIGTERM raises SystemExit(143) once the graph is up (cap_bringup.graph.Graph); both close the graph
        summary = run_demo(args.out, args.backend, args.cassette, args.record, args.perception,
                           video=not args.no_video)
    except KeyboardInterrupt:
        print('interrupted (SIGINT)', file=sys.stderr)
        return 130
    good = sum(s['as_expected'] for s in summary['steps'])
    print(f'\n{good}/{len(STEPS)} commands had their expected outcome in {summary["wall_seconds"]:.0f} s.')
    print(f'Images, video and summary.json are in {summary["output"]}')
    return 0 if summary['all_as_expected'] else 1


if __name__ == '__main__':
    sys.exit(main())
