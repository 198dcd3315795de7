"""One table-top graph in this process running episodes one after another, and the loop of a run's job: the
episodes it takes, each judged on the simulator's final state by cap_bench.tabletop.success."""
from __future__ import annotations

import pathlib
import sys
import time
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from cap_bench.episode_runs import EpisodeGraph, EpisodeRunner
from cap_bench.bench_options import feedback_rounds
from cap_bench.graph_client import SERVICE_TIMEOUT_S, GraphClient, outcome_name, prediction_fields, wait
from cap_bench.tabletop.episodes import Episode
from cap_bench.tabletop.options import TabletopOptions, rgbd_camera_rate
from cap_bench.tabletop.sampling import episode_for_key
from cap_bench.tabletop.success import Verdict, check
from cap_lmp.local_server import MODEL_READY_TIMEOUT_S
from cap_tabletop.cameras import DEFAULT_CAMERA

SETTLE_S = 0.5  # simulated time the scene settles after the program before it is judged

_OUTCOME_REASONS = {'error': 'the program failed', 'cancelled': 'the command was cancelled',
                    'refused': 'the command was refused', 'model_error': 'the model gave no usable answer'}


def failed_record(episode: Episode, options: TabletopOptions, reason: str = '') -> dict:
    """An episode's record before it ran: not a success, with `reason`."""
    return {'key': episode.key, 'seed': episode.seed,
            'group': episode.group, 'template': episode.template, 'attributes': episode.attributes,
            'instruction': episode.instruction, 'policy': options.policy, 'perception': options.perception,
            'feedback_rounds': feedback_rounds(options),
            'code': '', 'success': False, 'reason': reason, 'sim_seconds': 0.0, 'wall_seconds': 0.0,
            'model_calls': 0, 'prompt_tokens': 0, 'completion_tokens': 0}


class TabletopRunner(GraphClient):
    """One table-top graph (in this process) running episodes one after another."""

    def __init__(self, options: TabletopOptions, cassette: pathlib.Path | None, cpu: int = 0) -> None:
        from cap_interfaces.msg import GraphNames

        super().__init__(options, cassette, 'cap_bench', perception=options.perception,
                         camera_rate=rgbd_camera_rate(options), cpu=cpu,
                         extra={'sim_bridge': {'cameras': [DEFAULT_CAMERA]}})
        self.forget = self.node.create_client(self.Trigger, GraphNames.PERCEPTION_FORGET_SERVICE)
        self.wait_until_ready('the graph', self.forget.service_is_ready)
        if self.backend == 'local' and not self.graph.nodes['lmp_node'].model_ready.wait(MODEL_READY_TIMEOUT_S):
            raise RuntimeError(f'the local model was not ready within {MODEL_READY_TIMEOUT_S:.0f} s')

    def _perception_mismatch(self, episode: Episode, tolerance: float) -> str:
        """How perception differs from the episode's scene ('' when it matches)."""
        try:
            source = self.graph.nodes['perception_node'].source
            seen = {obj.name: obj for obj in source.objects()}
        except Exception as error:  # perception not ready: say why
            return f'no objects yet ({error})'
        wanted = {o.name: o for o in episode.objects}
        problems = [f'missing {name}' for name in sorted(set(wanted) - set(seen))]
        problems += [f'extra {name}' for name in sorted(set(seen) - set(wanted))]
        for name in sorted(set(wanted) & set(seen)):
            error = float(np.hypot(seen[name].position[0] - wanted[name].xy[0],
                                   seen[name].position[1] - wanted[name].xy[1]))
            if error >= tolerance:
                problems.append(f'{name} {error:.3f} m off')
        return ', '.join(problems)

    def run(self, episode: Episode, judge: Callable[[Episode, dict, dict], Verdict] = check,
            instructions: Sequence[str] = ()) -> dict:
        """Reset the scene to the episode's, send its instruction (or `instructions`, one after another in one
        session, stopping at the first that does not finish), and judge the final state with `judge`."""
        world = self.graph.world
        record = failed_record(episode, self.options)
        wall_started = time.monotonic()
        record['reason'] = self.reset_scene(episode.seed, episode.objects)
        if record['reason']:
            return record
        self.call(self.forget.call_async(self.Trigger.Request()), SERVICE_TIMEOUT_S, 'perception (forget)')
        self.new_session()
        tolerance = 0.005 if self.options.perception == 'ground_truth' else 0.02
        if not wait(lambda: not self._perception_mismatch(episode, tolerance), 30):
            record['reason'] = ('perception did not report the scene as reset within 30 s: '
                                + self._perception_mismatch(episode, tolerance))
            return record
        initial = {s.name: s.position for s in world.object_states()}
        sim_started = world.time
        results = self.run_instructions(instructions or (episode.instruction,), record)
        if results is None:
            return record
        settle_until = world.time + SETTLE_S
        wait(lambda: world.time >= settle_until, 30)
        final = {s.name: s.position for s in world.object_states()}
        verdict = judge(episode, initial, final)
        done = self.finished(results)
        record.update(code='\n# ---\n'.join(r.code for r in results), success=bool(done and verdict.success),
                      outcome=outcome_name(results[-1].outcome),
                      sim_seconds=world.time - sim_started, wall_seconds=time.monotonic() - wall_started,
                      prompt_tokens=sum(r.prompt_tokens for r in results),
                      completion_tokens=sum(r.completion_tokens for r in results),
                      final_state={k: [round(float(v), 4) for v in p] for k, p in final.items()},
                      **prediction_fields(results))
        if not done:
            record['reason'] = f'{_outcome_reason(results[-1].outcome)}: {results[-1].message}'
        elif not verdict.success:
            record['reason'] = f'the final state is wrong: {verdict.reason}'
        return record


def _outcome_reason(outcome: int) -> str:
    name = outcome_name(outcome)
    return _OUTCOME_REASONS.get(name, f'the command ended with outcome {name}')


def episode_graph(options: TabletopOptions, make_runner: Callable[[], EpisodeRunner]) -> EpisodeGraph:
    """Table-top episodes one at a time on a graph from `make_runner()`: one that stops answering costs its
    episode (recorded as failed, with the reason) and the episodes after it run on a new graph."""
    def failed(episode: Episode, error: TimeoutError) -> dict:
        record = failed_record(episode, options, f'the graph stopped answering ({error}); the episodes after it ran '
                                                 'on a new graph')
        print(f'{record["key"]}: {record["reason"]}', file=sys.stderr)
        return record

    return EpisodeGraph(make_runner, failed)


def run_episodes(keys: Iterable[str], options: TabletopOptions, make_runner: Callable[[], Any],
                 write: Callable[[dict], None]) -> int:
    """Run the episodes `keys` ('group/template/seed') one after another on a graph from `make_runner()`, writing
    each record; return how many graphs were built (see episode_graph)."""
    graph = episode_graph(options, make_runner)
    try:
        for key in keys:
            write(graph.run(episode_for_key(key)))
    finally:
        graph.close()
    return graph.built
