"""The controllers demo: generated controllers balance a cart-pole and hold and move the arm's tool, in simulation.

    cap demo controllers [--out DIR] [--backend cassette|http|local] [--cassette FILE] [--no-video]

By default every answer comes from the controllers domain's reference cassette of hand-written programs (no network,
no model); function generation writes the PD and impedance laws the programs name. Each command's code, words and
outcome are printed and checked on the simulator's state, recorded while it runs, the way the controller benchmark
judges its runs (cap_controllers.judging): the lean the robot says is the pole's; the pole stayed within 12 degrees
and the cart on its rail for the whole 30 s; the tool held by impedance control yields to a 20 N push one second
into the run and settles back within 5 mm; the tool goes round the 4 cm circle every 5 s within 10 mm RMS. DIR gets
a video of the run (the scene's overview camera, demo.mp4) and summary.json. Exit code 0 when every command did what
it should; 130 on Ctrl-C (the graph is closed first).
"""
from __future__ import annotations

import dataclasses
import math
import pathlib
import re
import sys
import threading
from typing import Any, Callable

import numpy as np
from cap_controllers import judging, plants

from cap_bringup.demos._support import DemoRun, SimulatedClockSampler, demo_parser, outcome_problems, result_of, \
    run_main, wait_until

SEED = 0  # the cart-pole's start: held still, the pole leaning -1.3 degrees
PUSH_DIRECTION = '+y'  # the held tool is pushed away from the arm's base
CAMERA = 'overview'


@dataclasses.dataclass(frozen=True)
class Seen:
    """What the simulator recorded while a command ran, with what the robot said and the controller's run."""

    times: np.ndarray  # [s] simulated time of each sample
    cart: np.ndarray  # [m] the cart's place on its rail
    lean: np.ndarray  # [rad] the pole's angle from upright
    tool: np.ndarray  # (N, 3) the tool centre point [m, world frame]
    said: list[str]
    failure: str  # '' when the command ended done, else why not
    run: Any  # controller_node's run (cap_control.control_loop.Result); None when no controller ran
    pushed_at: float | None = None  # [s] simulated time the push began

    def in_run(self) -> np.ndarray:
        """Which samples fall within the controller's run."""
        start = self.run.start_time
        return (self.times >= start - 1e-9) & (self.times <= start + self.run.simulated_time + 1e-6)


Check = Callable[[Seen], str]  # -> problem ('' when fine)


def _says_the_lean(seen: Seen) -> str:
    truth = math.degrees(seen.lean[-1])
    numbers = [float(n) for text in seen.said for n in re.findall(r'-?\d+(?:\.\d+)?', text)]
    return '' if any(abs(n - truth) <= 0.1 for n in numbers) else \
        f'said {seen.said}, but the pole leans {truth:.2f} degrees'


def _no_run(seen: Seen) -> str:
    return seen.failure or 'no controller ran'


def _balanced(duration_s: float) -> Check:
    def check(seen: Seen) -> str:
        if seen.run is None:
            return _no_run(seen)
        window = seen.in_run()
        verdict = judging.judge_balance(duration_s, seen.run.simulated_time, seen.failure, seen.lean[window])
        if not verdict.success:
            return verdict.reason
        cart = float(np.abs(seen.cart[window]).max(initial=0.0))
        return '' if cart <= plants.RAIL_LIMIT else f'the cart went {cart:.2f} m along its rail'
    return check


def _held_under_push(direction: str) -> Check:
    def check(seen: Seen) -> str:
        if seen.run is None:
            return _no_run(seen)
        if seen.pushed_at is None:
            return seen.failure or 'the run ended before the push'
        window = seen.in_run()
        # Times as the judge counts them: the push began PUSH_START_S into the run.
        times = seen.times[window] - seen.pushed_at + judging.PUSH_START_S
        tool = seen.tool[window]
        verdict = judging.judge_push(direction, times, tool - tool[0], seen.failure)
        return '' if verdict.success else verdict.reason
    return check


def _went_round(radius_m: float, duration_s: float) -> Check:
    def check(seen: Seen) -> str:
        if seen.run is None:
            return _no_run(seen)
        window = seen.in_run()
        tool = seen.tool[window]
        verdict = judging.judge_track(radius_m, duration_s, seen.times[window] - seen.run.start_time, tool,
                                      tool[0] if len(tool) else np.zeros(3), seen.run.simulated_time, seen.failure)
        return '' if verdict.success else verdict.reason
    return check


@dataclasses.dataclass(frozen=True)
class Step:
    command: str
    check: Check
    push: str = ''  # a push on the tool (a key of judging.PUSH_DIRECTIONS) PUSH_START_S into the controller's run


# The commands the domain's reference cassette answers, the question first, while the pole is still held.
STEPS = (
    Step('what is the angle of the pole?', _says_the_lean),
    Step('keep the pole upright with a PD controller for 30 seconds', _balanced(30.0)),
    Step('hold the tool where it is with impedance control for 10 seconds', _held_under_push(PUSH_DIRECTION),
         push=PUSH_DIRECTION),
    Step('move the tool around a circle of 4 cm radius once every 5 seconds for 10 seconds', _went_round(0.04, 10.0)),
)


class PlantRecorder(SimulatedClockSampler):
    """The cart's place, the pole's lean and the tool's position every `period` of simulated time, with the time."""

    def __init__(self, world, period: float = 0.01) -> None:
        self._samples: list[np.ndarray] = []  # time, cart, lean, tool x, y, z
        self._lock = threading.Lock()
        super().__init__(world, period, 'demo_plant')

    def _now(self) -> np.ndarray:
        with self.world.lock:  # one instant of the simulation
            (cart, lean), _ = self.world.joint_state(plants.CARTPOLE_JOINTS)
            return np.concatenate([[self.world.time, cart, lean], self.world.tcp_pose()[:3, 3]])

    def sample(self) -> None:
        row = self._now()
        with self._lock:
            self._samples.append(row)

    def take(self) -> np.ndarray:
        """The samples since the last take and one of now, a row each (time, cart, lean, tool x, y, z)."""
        with self._lock:
            samples, self._samples = self._samples, []
        return np.array(samples + [self._now()])


def run_demo(out_dir: pathlib.Path, backend: str = 'cassette', cassette: str = '', steps=STEPS,
             video: bool = True, log=print) -> dict:
    """Run the commands; return the summary (also written to out_dir/summary.json)."""
    from geometry_msgs.msg import Vector3

    from cap_interfaces.msg import GraphNames
    from cap_interfaces.srv import PushTool

    run = DemoRun(out_dir, len(steps), name='controllers_demo', log=log, video=video, domain='controllers',
                  seed=SEED, llm_backend=backend, cassette=cassette, camera_rate=0.0)
    push = run.service(PushTool, GraphNames.SIM_PUSH_TOOL_SERVICE)
    controller_node, lockstep = run.graph.nodes['controller_node'], run.graph.nodes['sim_bridge'].lockstep
    pushed: dict[str, float] = {}

    def push_once_running(direction: str) -> Callable[[Any], None]:
        """While the command runs: once the controller has driven the plant for PUSH_START_S, push the tool."""
        def during(result) -> None:
            wait_until(lambda: lockstep.active or result.done(), 120, 'a controller to take the arm over')
            took_over = run.world.time
            wait_until(lambda: run.world.time >= took_over + judging.PUSH_START_S or result.done(), 120,
                       'the controller to run for a second')
            if result.done():
                return
            force = judging.PUSH_FORCE * np.asarray(judging.PUSH_DIRECTIONS[direction], dtype=float)
            request = PushTool.Request(force=Vector3(x=force[0], y=force[1], z=force[2]),
                                       duration=judging.PUSH_DURATION_S)
            answer = result_of(push.call_async(request), 30, 'the push')
            if answer.success:
                pushed['at'] = run.world.time
        return during

    with run:
        run.wait_for_model()
        run.reset_scene(seed=SEED)
        recorder = PlantRecorder(run.world)
        run.closing(recorder.close)
        run.record_video(CAMERA)
        for step in steps:
            recorder.take()
            controller_node.last_result = None
            pushed.clear()
            ran = run.run_command(step.command, push_once_running(step.push) if step.push else None)
            samples = recorder.take()
            seen = Seen(samples[:, 0], samples[:, 1], samples[:, 2], samples[:, 3:], ran.said,
                        '' if ran.outcome == 'done' else ran.message or ran.outcome, controller_node.last_result,
                        pushed.get('at'))
            problems = outcome_problems(ran) + [p for p in [step.check(seen)] if p and p != seen.failure]
            if seen.run is None:
                run.report(ran, problems)
            else:
                run.report(ran, problems, f'the controller ran {seen.run.simulated_time:.1f} s in {seen.run.calls} '
                           'calls', controller_seconds=seen.run.simulated_time, controller_calls=seen.run.calls)
    return run.summary


def main(argv=None) -> int:
    parser = demo_parser('cap demo controllers', __doc__.split('\n\n')[0], 'controllers',
                         "cassette to replay [the controllers domain's reference one]")
    return run_main(parser, argv, lambda args: run_demo(args.out, args.backend, args.cassette,
                                                        video=not args.no_video),
                    'did what was asked', 'The video and summary.json are')


if __name__ == '__main__':
    sys.exit(main())
