"""The client side of a benchmark's graph: a graph of one domain in this process, a client node beside it, and the
calls every graph benchmark makes on an episode (reset the scene and the session, wait for perception, send the
instructions to lmp_node's /cap/execute action one after another and wait for their results).

rclpy, the interfaces and the graph are imported when a client is made: planning and judging episodes never load
them.
"""
from __future__ import annotations

import pathlib
import time
from typing import Any, Callable, Iterable, Sequence

from cap_bench.bench_options import BenchOptions, lmp_parameters

# A graph's services answer in milliseconds; beside a model server on a loaded 2-core machine, seconds.
SERVICE_TIMEOUT_S = 60.0
READY_TIMEOUT_S = 60.0  # for a new graph's action and services to appear
GOAL_TIMEOUT_S = 30.0  # for lmp_node to accept a goal
PERCEPTION_TIMEOUT_S = 30.0  # for perception to report a reset scene


def wait(predicate: Callable[[], bool], timeout: float) -> bool:
    """Poll `predicate` until it holds (True) or `timeout` seconds have passed (False)."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.005)
    return True


def outcome_name(outcome: int) -> str:
    """lmp_node's name of an ExecuteCommand outcome (imported when first needed: it loads rclpy)."""
    from cap_lmp_ros.lmp_node import outcome_name as name_of

    return name_of(outcome)


def prediction_fields(results: Sequence[Any]) -> dict[str, Any]:
    """An episode's record of its rehearsals (ExecuteCommand results): whether its programs were rehearsed, and
    where the world differed from the twin's prediction."""
    rehearsed = [r for r in results if r.rehearsed]
    if not rehearsed:
        return {}
    return {'rehearsed': len(rehearsed), 'prediction': ' | '.join(r.prediction for r in rehearsed if r.prediction),
            'prediction_misses': [{'name': m.name, 'distance_m': round(m.distance, 4), 'unexpected': m.unexpected}
                                  for r in rehearsed for m in r.prediction_misses]}


class GraphClient:
    """A graph in this process, running the run's policy (see bench_options.lmp_parameters), and a client node that
    resets its scene and session and sends it instructions. A call without an answer in time raises TimeoutError:
    the episode runners (cap_bench.episode_runs.EpisodeGraph) then go on with a new graph."""

    def __init__(self, options: BenchOptions, cassette: pathlib.Path | None, node: str, **graph: Any) -> None:
        """Bring up the graph (`graph`: GraphOptions fields besides the policy's; its `extra` parameters beside
        lmp_node's) and the client node `node`; the subclass adds its own clients, then calls wait_until_ready."""
        import rclpy
        from cap_ros_common.actions import ActionClient
        from rclpy.context import Context
        from std_srvs.srv import Trigger

        from cap_bringup.graph import Graph, GraphOptions
        from cap_interfaces.action import ExecuteCommand
        from cap_interfaces.msg import GraphNames
        from cap_interfaces.srv import ResetScene

        self.options = options
        self.context = Context()
        rclpy.init(context=self.context)
        self.backend, lmp = lmp_parameters(options)
        extra = {'lmp_node': lmp, **graph.pop('extra', {})}
        graph.setdefault('rehearse', options.rehearse)
        self.graph = Graph(self.context, GraphOptions(llm_backend=self.backend,
                                                      cassette=str(cassette) if cassette else '', extra=extra,
                                                      **graph))
        self.node = rclpy.create_node(node, context=self.context)
        self.graph.executor.add_node(self.node)
        self.execute = ActionClient(self.node, ExecuteCommand, GraphNames.EXECUTE_ACTION)
        self.reset = self.node.create_client(ResetScene, GraphNames.SIM_RESET_SERVICE)
        self.reset_session = self.node.create_client(Trigger, GraphNames.RESET_SESSION_SERVICE)
        self.ExecuteCommand, self.ResetScene, self.Trigger = ExecuteCommand, ResetScene, Trigger

    def wait_until_ready(self, what: str, *ready: Callable[[], bool]) -> None:
        """Wait for lmp_node's action, the reset services and the subclass's `ready` checks; RuntimeError naming
        `what` (e.g. 'the whiteboard graph') when they do not come up in time."""
        if not wait(lambda: self.execute.server_is_ready() and self.reset.service_is_ready()
                    and self.reset_session.service_is_ready() and all(check() for check in ready),
                    READY_TIMEOUT_S):
            raise RuntimeError(f'{what} did not come up within {READY_TIMEOUT_S:.0f} s')

    def call(self, future, timeout: float, what: str):
        """The answer of `future`; TimeoutError naming `what` when none comes within `timeout` seconds."""
        if not wait(future.done, timeout):
            raise TimeoutError(f'no answer from {what} within {timeout:.0f} s')
        return future.result()

    def reset_scene(self, seed: int, objects: Iterable[Any]) -> str:
        """Reset the simulator to `objects` (each with a name and xy; a category and colour where it has them) and
        the session; why the scene reset failed, or ''."""
        from geometry_msgs.msg import Point

        from cap_interfaces.msg import ObjectSpec

        request = self.ResetScene.Request(seed=seed, objects=[
            ObjectSpec(name=o.name, category=getattr(o, 'category', ''), color_name=getattr(o, 'color', ''),
                       use_position=True, position=Point(x=o.xy[0], y=o.xy[1])) for o in objects])
        answer = self.call(self.reset.call_async(request), SERVICE_TIMEOUT_S, 'the scene reset')
        return '' if answer.success else f'scene reset failed: {answer.message}'

    def new_session(self) -> None:
        """A fresh lmp_node session: no variables or history of the episode before."""
        self.call(self.reset_session.call_async(self.Trigger.Request()), SERVICE_TIMEOUT_S,
                  'lmp_node (reset session)')

    def perceived(self) -> set[str]:
        """The names of the objects perception reports now (none while it is not ready)."""
        try:
            return {obj.name for obj in self.graph.nodes['perception_node'].source.objects()}
        except Exception:  # noqa: BLE001 - perception not ready yet
            return set()

    def await_objects(self, names: set[str]) -> str:
        """Wait for perception to report exactly the objects `names`; why it did not, or ''."""
        if wait(lambda: self.perceived() == names, PERCEPTION_TIMEOUT_S):
            return ''
        return (f'perception did not report the reset scene within {PERCEPTION_TIMEOUT_S:.0f} s: '
                f'{sorted(self.perceived())}')

    def start_episode(self, episode: Any, record: dict) -> bool:
        """Reset the scene to the episode's objects and the session, and wait for perception to report the objects;
        False (with record['reason']) when one of these fails."""
        record['reason'] = self.reset_scene(episode.seed, episode.objects)
        if not record['reason']:
            self.new_session()
            self.scene_reset()
            record['reason'] = self.await_objects({o.name for o in episode.objects})
        return not record['reason']

    def scene_reset(self) -> None:
        """What else goes with the scene when it is reset (nothing here)."""

    def run_instructions(self, instructions: Sequence[str], record: dict) -> list | None:
        """Send `instructions` one after another in the session, stopping after the first that does not finish
        (outcome other than done), counting model calls and tokens into the record; their results, or None (with
        record['reason']) when one had no result within the episode's time limit (its goal is cancelled)."""
        results = []
        for instruction in instructions:
            goal = self.call(self.execute.send_goal_async(self.ExecuteCommand.Goal(command=instruction)),
                             GOAL_TIMEOUT_S, 'lmp_node (goal)')
            future = goal.get_result_async()
            if not wait(future.done, self.options.episode_timeout_s + 60):
                goal.cancel_goal_async()
                wait(future.done, 30)
                record['reason'] = f'no result within {self.options.episode_timeout_s:.0f} s'
                return None
            results.append(future.result().result)
            record['model_calls'] += results[-1].model_calls
            for field in ('prompt_tokens', 'completion_tokens'):
                record[field] = record.get(field, 0) + int(getattr(results[-1], field))
            if results[-1].outcome != self.ExecuteCommand.Result.OUTCOME_DONE:
                break
        return results

    def finished(self, results: Sequence[Any]) -> bool:
        """Whether the last instruction of `results` finished (outcome done)."""
        return bool(results) and results[-1].outcome == self.ExecuteCommand.Result.OUTCOME_DONE

    def close(self) -> None:
        self.graph.close()
        self.node.destroy_node()
        self.context.try_shutdown()
