"""What every demo shares: the graph brought up for one run of commands and a user node beside it (`DemoRun`), which
resets the scene, sends each command through /cap/execute and waits for it, collects what the robot says meanwhile,
prints the per-command lines and writes summary.json; a video of the run (`VideoRecorder`) and other recorders of
the simulator's state (`SimulatedClockSampler`); the command line's common options and its ending (`demo_parser`,
`run_main`).

A demo module holds its scene, its steps and their checks, and runs them inside a `DemoRun`::

    with DemoRun(out_dir, len(STEPS), name='toy_demo', domain='toy', llm_backend=backend) as run:
        run.reset_scene(placed_objects(SCENE))
        for step in STEPS:
            ran = run.run_command(step.command)
            run.report(ran, outcome_problems(ran) + [p for p in (check() for check in step.checks) if p])
    return run.summary

Everything printed that comes from the graph (code, said lines, messages) has its control characters escaped.
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import os
import pathlib
import sys
import threading
import time
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from cap_lmp.local_server import MODEL_READY_TIMEOUT_S
from cap_lmp.safe_text import terminal_text

Log = Callable[[str], None]
ACCEPT_TIMEOUT_S = 30.0  # for lmp_node to accept a command
COMMAND_TIMEOUT_S = 900.0  # for a command to end
SAY_DRAIN_S = 0.2  # after the result: the last /cap/say lines arrive just after it


def wait_until(predicate: Callable[[], bool], timeout: float, what: str) -> None:
    """Return once `predicate()` holds; TimeoutError naming `what` after `timeout` seconds."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise TimeoutError(f'timed out waiting for {what}')
        time.sleep(0.01)


def result_of(future, timeout: float, what: str) -> Any:
    """The result of an rclpy future, once it is done (TimeoutError naming `what` otherwise)."""
    wait_until(future.done, timeout, what)
    return future.result()


class SimulatedClockSampler:
    """Calls `sample()` every `period` seconds of simulated time, from a thread of its own, until closed.

    The simulator may run faster than the wall clock: a sampler that falls behind samples again at once until it
    has caught up, so the samples keep their count per simulated second.
    """

    def __init__(self, world, period: float, name: str) -> None:
        self.world, self.period = world, period
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def sample(self) -> None:
        raise NotImplementedError

    def _run(self) -> None:
        next_time = self.world.time
        while not self._stop.is_set():
            if self.world.time < next_time:
                time.sleep(0.002)
                continue
            self.sample()
            next_time += self.period

    def close(self) -> None:
        self._stop.set()
        self._thread.join(10)


class VideoRecorder(SimulatedClockSampler):
    """Renders a camera every `period` of simulated time and writes an MP4 (H.264 via imageio-ffmpeg)."""

    def __init__(self, world, path: pathlib.Path, period: float = 0.2, fps: int = 15,
                 size: tuple[int, int] = (640, 480), camera: str = 'front') -> None:
        import imageio_ffmpeg

        self.size, self.camera = size, camera
        self._writer = imageio_ffmpeg.write_frames(str(path), size, fps=fps, macro_block_size=8,
                                                   output_params=['-loglevel', 'error'])
        self._writer.send(None)
        self.frames = 0
        super().__init__(world, period, 'demo_video')

    def sample(self) -> None:
        rgb, _ = self.world.render(self.camera, *self.size, with_depth=False)
        self._writer.send(np.ascontiguousarray(rgb))
        self.frames += 1

    def close(self) -> None:
        super().close()
        self._writer.close()


@dataclasses.dataclass
class Ran:
    """One command as it ran: lmp_node's result, its outcome's name, what the robot said meanwhile, how long it took
    in simulated and in wall time."""

    command: str
    result: Any  # cap_interfaces.action.ExecuteCommand.Result
    outcome: str  # 'done', 'error', 'refused', ... (cap_lmp_ros.lmp_node.outcome_name)
    said: list[str]
    sim_seconds: float
    wall_seconds: float

    @property
    def code(self) -> str:
        return self.result.code

    @property
    def message(self) -> str:
        return self.result.message


def outcome_problems(ran: Ran, expect: str = 'done', message_must_name: str = '') -> list[str]:
    """What is wrong with the command's outcome: not the one expected, or (for an expected error) a message that
    does not name what it should."""
    problems = []
    if ran.outcome != expect:
        problems.append(f'expected {expect}, got {ran.outcome}' + (f': {ran.message}' if ran.message else ''))
    if message_must_name and message_must_name not in ran.message:
        problems.append(f'the message does not name {message_must_name!r}')
    return problems


def placed_objects(scene: Mapping[str, Sequence[float]],
                   kinds: Mapping[str, tuple[str, str]] | None = None) -> list:
    """ObjectSpec messages for a scene placed by hand (name -> x, y [m]); `kinds` gives a name's (category, colour)
    where the simulator needs them."""
    from geometry_msgs.msg import Point

    from cap_interfaces.msg import ObjectSpec

    kinds = kinds or {}
    return [ObjectSpec(name=name, category=kinds.get(name, ('', ''))[0], color_name=kinds.get(name, ('', ''))[1],
                       use_position=True, position=Point(x=float(xy[0]), y=float(xy[1])))
            for name, xy in scene.items()]


class DemoRun:
    """A domain's whole graph in this process (cap_bringup.graph.Graph) and a user node beside it, for one run of
    `total` commands whose outputs go to `out_dir`.

    Use it as a context manager: entering waits for the graph to come up; leaving closes what the demo asked to
    close (`closing`), the video, then the graph, and, unless an exception ends the run, writes the summary
    (`summary`, also out_dir/summary.json). `graph_options` are GraphOptions' fields.
    """

    def __init__(self, out_dir: pathlib.Path, total: int, *, name: str = 'demo', log: Log = print,
                 video: bool = True, verdict: str = 'as asked', **graph_options: Any) -> None:
        import rclpy
        from cap_ros_common.actions import ActionClient
        from rclpy.context import Context
        from std_msgs.msg import String

        from cap_bringup.graph import Graph, GraphOptions
        from cap_interfaces.action import ExecuteCommand
        from cap_interfaces.msg import GraphNames
        from cap_interfaces.srv import ResetScene

        self.out_dir, self.total, self.log, self.video, self.verdict = out_dir, total, log, video, verdict
        self.options = GraphOptions(**graph_options)
        out_dir.mkdir(parents=True, exist_ok=True)
        os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
        self.context = Context()
        rclpy.init(context=self.context)
        self.graph = Graph(self.context, self.options)
        self.node = rclpy.create_node(name, context=self.context)
        self.graph.executor.add_node(self.node)
        self.said: list[str] = []
        self.node.create_subscription(String, GraphNames.SAY_TOPIC, lambda m: self.said.append(m.data), 50)
        self._execute = ActionClient(self.node, ExecuteCommand, GraphNames.EXECUTE_ACTION)
        self._reset = self.node.create_client(ResetScene, GraphNames.SIM_RESET_SERVICE)
        self._ready: list[Callable[[], bool]] = [self._execute.server_is_ready, self._reset.service_is_ready]
        self._closing = contextlib.ExitStack()
        self.summary: dict[str, Any] = {'output': str(out_dir), 'steps': []}
        self._started = time.monotonic()

    @property
    def world(self):
        """The simulator (cap_sim_bridge.world.World) the graph's bridge steps."""
        return self.graph.world

    def service(self, kind: type, name: str):
        """A client of one of the graph's services, which must be up before the run starts (call before `with`)."""
        client = self.node.create_client(kind, name)
        self._ready.append(client.service_is_ready)
        return client

    def closing(self, callback: Callable[[], Any]) -> None:
        """Call `callback` when the run ends, before the graph closes (the last one given first)."""
        self._closing.callback(callback)

    def __enter__(self) -> DemoRun:
        try:
            wait_until(lambda: all(ready() for ready in self._ready), 30, 'the graph to come up')
        except BaseException:
            self._close()
            raise
        return self

    def __exit__(self, kind, error, trace) -> None:
        self._close()
        if kind is None:
            self.summary['commands'] = self.total
            self.summary['all_as_expected'] = all(s['as_expected'] for s in self.summary['steps']) and \
                len(self.summary['steps']) == self.total
            self.summary['wall_seconds'] = time.monotonic() - self._started
            (self.out_dir / 'summary.json').write_text(json.dumps(self.summary, indent=2))

    def _close(self) -> None:
        try:
            self._closing.close()
        finally:
            self.graph.close()
            self.node.destroy_node()
            self.context.try_shutdown()

    # ------------------------------------------------------------------------------------------- before the steps
    def wait_for_model(self) -> None:
        """With the local model: wait until it has loaded and read its prompts (minutes on one core, once)."""
        if self.options.llm_backend == 'local':
            self.log('waiting for the local model to load and read its prompts ...')
            wait_until(self.graph.nodes['lmp_node'].model_ready.is_set, MODEL_READY_TIMEOUT_S, 'the local model')

    def reset_scene(self, objects: Sequence = (), seed: int = 0) -> None:
        """Reset the simulator's scene with these ObjectSpec messages (none: the seed's own episode)."""
        from cap_interfaces.srv import ResetScene

        answer = result_of(self._reset.call_async(ResetScene.Request(seed=seed, objects=list(objects))), 30,
                           'the scene reset')
        if not answer.success:
            raise RuntimeError(f'scene reset failed: {answer.message}')

    def wait_for_perception(self, names) -> None:
        """Wait until perception has seen exactly these objects (the scene just reset)."""
        source = self.graph.nodes['perception_node'].source

        def known() -> bool:
            try:
                return set(source.names()) == set(names)
            except Exception:  # no observation yet
                return False
        wait_until(known, 30, 'perception to see the scene')

    def record_video(self, camera: str, period: float = 0.2) -> None:
        """Unless the video is off: a video of the run from `camera` (out_dir/demo.mp4), closed when the run ends."""
        if not self.video:
            return
        recorder = VideoRecorder(self.world, self.out_dir / 'demo.mp4', period=period, camera=camera)

        def close() -> None:
            recorder.close()
            self.summary['video'] = str(self.out_dir / 'demo.mp4')
            self.summary['video_frames'] = recorder.frames
        self.closing(close)

    # ------------------------------------------------------------------------------------------- the steps
    def run_command(self, command: str, during: Callable[[Any], None] | None = None) -> Ran:
        """Send `command` through /cap/execute and wait until it ends. `during(result_future)` runs once lmp_node
        has accepted it (e.g. a push while a controller runs)."""
        from cap_interfaces.action import ExecuteCommand
        from cap_lmp_ros.lmp_node import outcome_name

        self.log(f'\n[{len(self.summary["steps"]) + 1}/{self.total}] > {terminal_text(command)}')
        self.said.clear()
        sim_started, wall_started = self.world.time, time.monotonic()
        goal = result_of(self._execute.send_goal_async(ExecuteCommand.Goal(command=command)), ACCEPT_TIMEOUT_S,
                         'lmp_node to accept the command')
        future = goal.get_result_async()
        if during is not None:
            during(future)
        result = result_of(future, COMMAND_TIMEOUT_S, 'the command to finish').result
        time.sleep(SAY_DRAIN_S)
        return Ran(command, result, outcome_name(result.outcome), list(self.said), self.world.time - sim_started,
                   time.monotonic() - wall_started)

    def report(self, ran: Ran, problems: Sequence[str], details: str = '', **record: Any) -> None:
        """Print the command's code, words, outcome and verdict; add it (with `record`) to the summary."""
        self.log('code:\n' + '\n'.join('    ' + line for line in terminal_text(ran.code).splitlines()))
        for text in ran.said:
            self.log(f'robot says: {terminal_text(text)}')
        message = f' ({terminal_text(ran.message)})' if not ran.result.success else ''
        self.log(f'outcome: {ran.outcome}{message}; {ran.sim_seconds:.1f} s simulated, {ran.wall_seconds:.1f} s wall'
                 + (f'; {details}' if details else ''))
        self.log(f'{self.verdict}: ' + ('yes' if not problems else 'NO: ' + terminal_text('; '.join(problems))))
        self.summary['steps'].append({'command': ran.command, 'outcome': ran.outcome, 'as_expected': not problems,
                                      'problems': list(problems), 'code': ran.code, 'said': ran.said,
                                      'message': ran.message, 'sim_seconds': ran.sim_seconds,
                                      'wall_seconds': ran.wall_seconds, **record})


# ----------------------------------------------------------------------------------------------- the command line
def demo_parser(prog: str, description: str, out_name: str, cassette_help: str) -> argparse.ArgumentParser:
    """The options every demo takes: --out, --backend, --cassette, --no-video (a demo adds its own)."""
    parser = argparse.ArgumentParser(prog=prog, description=description)
    parser.add_argument('--out', type=pathlib.Path,
                        default=pathlib.Path('output') / time.strftime(f'{out_name}-%Y%m%d-%H%M%S'),
                        help='output folder [output/<demo>-<date>-<time>]')
    parser.add_argument('--backend', choices=('cassette', 'http', 'local'), default='cassette',
                        help='cassette (the reference programs, default), http (an OpenAI-compatible endpoint: '
                             'CAP_LLM_BASE_URL, CAP_LLM_MODEL, CAP_LLM_API_KEY) or local (the llama.cpp server '
                             'and model of `make model`)')
    parser.add_argument('--cassette', default='', help=cassette_help)
    parser.add_argument('--no-video', action='store_true', help='no video of the run')
    return parser


def run_main(parser: argparse.ArgumentParser, argv: Sequence[str] | None, run: Callable[[argparse.Namespace], dict],
             did: str, outputs: str) -> int:
    """Parse the options, run the demo, print how many commands `did` what they should and where `outputs` are.
    Exit code 0 when every command did, 1 otherwise, 130 on Ctrl-C; SIGTERM raises SystemExit(143) once the graph
    is up (cap_bringup.graph.Graph). Either way the graph is closed first."""
    args = parser.parse_args(sys.argv[1:] if argv is None else list(argv))
    try:
        summary = run(args)
    except KeyboardInterrupt:
        print('interrupted (SIGINT)', file=sys.stderr)
        return 130
    good = sum(s['as_expected'] for s in summary['steps'])
    print(f'\n{good}/{summary["commands"]} commands {did} in {summary["wall_seconds"]:.0f} s.')
    print(f'{outputs} in {summary["output"]}')
    return 0 if summary['all_as_expected'] else 1


__all__ = ['DemoRun', 'Ran', 'SimulatedClockSampler', 'VideoRecorder', 'demo_parser', 'outcome_problems',
           'placed_objects', 'result_of', 'run_main', 'wait_until']
