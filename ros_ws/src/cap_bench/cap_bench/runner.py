"""`cap bench tabletop`: the paper's simulated table-top benchmark through the real graph.

Every episode goes the way of a user's command: the scene is reset through the sim bridge's service, the
instruction is sent to lmp_node's /cap/execute action, the program (an oracle reference program replayed from a
cassette, or a model's code from an OpenAI-compatible endpoint) runs in the sandbox and drives perception and
pick-and-place over ROS, and the result is judged on the simulator's final state by cap_bench.success.

Results are appended to episodes.jsonl as each episode ends, so an interrupted run resumes where it stopped
(--resume). Parallel jobs run separate graphs in separate processes, each on its own ROS_DOMAIN_ID: with
ROS_DOMAIN_ID set in the environment, job i (0 <= i < --jobs) uses ROS_DOMAIN_ID + i, so `--jobs 4` with
ROS_DOMAIN_ID=20 occupies domains 20-23; without it the first id is derived from the process id (in 1..101, the
ids whose DDS ports stay below Linux's ephemeral range).

SIGINT (Ctrl-C) or SIGTERM stops the run: the workers close their graphs, the episodes finished so far stay in
episodes*.jsonl, and the command exits 130 or 143 (continue later with --resume).
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import multiprocessing
import os
import pathlib
import queue
import signal
import sys
import time
from typing import Any, Callable, Iterable, Iterator, Sequence

import numpy as np
import yaml

from cap_bench.episodes import Episode, sample_episode
from cap_bench.oracle import oracle_program
from cap_bench.report import write_report
from cap_bench.success import Verdict, check
from cap_bench.templates import GROUPS, TEMPLATES
from cap_lmp.errors import LLMError
from cap_lmp.local_server import MODEL_READY_TIMEOUT_S
from cap_lmp.safe_text import one_line, terminal_text
from cap_lmp.cassette import FORMAT as CASSETTE_FORMAT
from cap_tabletop.cameras import DEFAULT_CAMERA

SETTLE_S = 0.5  # simulated time the scene settles after the program before it is judged
# A graph's services answer in milliseconds; beside a model server on a loaded 2-core machine, seconds.
SERVICE_TIMEOUT_S = 60.0
MAX_DOMAIN_ID = 232  # the largest ROS_DOMAIN_ID whose DDS ports are valid


@dataclasses.dataclass
class BenchOptions:
    policy: str = 'oracle'  # or 'llm'
    groups: tuple[str, ...] = tuple(GROUPS)
    tasks: tuple[str, ...] = tuple(TEMPLATES)
    trials: int = 50
    perception: str = 'ground_truth'  # or 'rgbd'
    camera_rate: float = 0.0  # with perception rgbd [Hz of simulated time]; 0: RGBD_CAMERA_RATE
    base_seed: int = 0
    jobs: int = 1
    out: str = 'output/bench'
    resume: bool = False
    base_url: str = ''  # for policy=llm; empty: CAP_LLM_BASE_URL
    model: str = ''
    api: str = 'chat'
    episode_timeout_s: float = 900.0
    first_domain_id: int | None = None  # job i runs on first_domain_id + i; None: see domain_ids()
    executor: str = 'local'  # or 'ray' (cap_bench.ray_executor)
    ray_address: str = ''  # for executor=ray: a cluster to join (host:6379); empty: a Ray instance for the run
    backend: str = 'http'  # for policy=llm: 'http' (base_url) or 'local' (a llama.cpp server started for the run)
    model_file: str = ''  # for backend=local; empty: the default model of `make model`
    model_threads: int = 1


# The benchmark's camera rate with the RGB-D detector. Perception analyses the newest frame only when asked, so a
# frame matters only at a question; rendering and sending a 640x480 colour and depth frame costs more than 15 steps
# of physics, and at 10 Hz it was a third of an RGB-D episode's wall time. At 2 Hz a question waits at most 0.5 s of
# simulated time for a frame newer than the last motion.
RGBD_CAMERA_RATE = 2.0


def rgbd_camera_rate(options: BenchOptions) -> float:
    """The bridge's camera rate for a run: 0 (no images) with ground truth."""
    if options.perception != 'rgbd':
        return 0.0
    return options.camera_rate or RGBD_CAMERA_RATE


def policy_name(options: BenchOptions) -> str:
    """Short: 'oracle programs' or the model's name."""
    if options.policy == 'oracle':
        return 'oracle programs'
    return f"model {options.model or os.environ.get('CAP_LLM_MODEL', '') or '(unnamed)'}"


def policy_description(options: BenchOptions) -> str:
    """Who wrote the programs, for reports."""
    if options.policy == 'oracle':
        return 'oracle: the reference program of each episode, replayed from a cassette (no model)'
    url = options.base_url or os.environ.get('CAP_LLM_BASE_URL', '') or '(CAP_LLM_BASE_URL)'
    return f'{policy_name(options)} at {url}, {options.api} API'


@contextlib.contextmanager
def model_endpoint(options: BenchOptions, domain: str = 'tabletop') -> Iterator[BenchOptions]:
    """The options with the model's endpoint filled in: for backend=local, one llama.cpp server on loopback for the
    whole run (its prompt cache stays warm across episodes, warmed with `domain`'s prompts), stopped at the end;
    otherwise the options as given."""
    if options.policy != 'llm' or options.backend != 'local':
        yield options
        return
    from cap_lmp.local_server import LocalModelClient, LocalModelServer, ServerSettings, warm_up
    from cap_lmp_ros.domains.registry import get_domain, prompt_heads

    # Graph job i runs on CPU i (see _worker): the server takes the CPUs after those, if there are any.
    allowed = sorted(os.sched_getaffinity(0)) if hasattr(os, 'sched_getaffinity') else []
    spare = tuple(allowed[max(1, options.jobs):])
    heads = prompt_heads(get_domain(domain))

    def read_prompts_again(generation: int) -> None:  # a restarted server has an empty prompt cache
        if generation > 1:
            try:
                print(f'warm-up after a restart: {warm_up(LocalModelClient(server), heads)}', file=sys.stderr)
            except LLMError as error:  # the episodes then meet the cold cache, or the server's errors
                print(f'warm-up after a restart failed: {error}', file=sys.stderr)

    server = LocalModelServer(ServerSettings(model_file=options.model_file, threads=options.model_threads,
                                             cpus=spare), on_event=lambda message: print(message, file=sys.stderr),
                              on_ready=read_prompts_again)
    server.start()  # stops the server itself if it cannot start
    try:
        print(f'warm-up: {warm_up(LocalModelClient(server), heads)}', file=sys.stderr)
        yield dataclasses.replace(options, backend='http', base_url=server.base_url, model=server.model_name,
                                  api='completions')
    finally:
        server.stop()


def domain_ids(jobs: int, first: int | None = None, environ: dict[str, str] | None = None) -> list[int]:
    """The ROS_DOMAIN_ID of each of `jobs` parallel graphs: consecutive ids from `first`, else from the
    environment's ROS_DOMAIN_ID, else from a process-id-dependent start in 1..101."""
    environ = os.environ if environ is None else environ
    jobs = max(1, jobs)
    if first is None and environ.get('ROS_DOMAIN_ID', '').strip():
        text = environ['ROS_DOMAIN_ID'].strip()
        if not text.isdigit():
            raise ValueError(f'ROS_DOMAIN_ID={text!r} is not a domain id (an integer in 0..{MAX_DOMAIN_ID})')
        first = int(text)
    if first is None:
        first = 1 + os.getpid() % max(1, 101 - jobs)
    if first < 0 or first + jobs - 1 > MAX_DOMAIN_ID:
        raise ValueError(f'{jobs} job(s) need ROS_DOMAIN_IDs {first}..{first + jobs - 1}, beyond 0..{MAX_DOMAIN_ID}:'
                         f' choose a smaller ROS_DOMAIN_ID or fewer --jobs')
    return list(range(first, first + jobs))


def plan(options: BenchOptions) -> list[Episode]:
    """Every episode of the run, trial by trial across all rows: a run stopped early has covered every row alike."""
    episodes = []
    for trial in range(options.trials):
        for group in options.groups:
            for template in (t for t in GROUPS[group][1] if t in options.tasks):
                episodes.append(sample_episode(group, template, options.base_seed + trial))
    return episodes


def episode_key(group: str, template: str, seed: int) -> str:
    return f'{group}/{template}/{seed}'


def write_oracle_cassette(episodes: Iterable[Episode], path: pathlib.Path) -> None:
    """One reference program per distinct instruction (a program depends only on the instruction's attributes)."""
    entries = {}
    for episode in episodes:
        entries[episode.instruction.lower()] = {
            'lmp': 'tabletop_ui', 'query': episode.instruction, 'context': '*',
            'source': f'written by hand as a reference program (cap_bench oracle, {episode.template})',
            'completion': oracle_program(episode)}
    path.write_text(yaml.safe_dump({'format': CASSETTE_FORMAT, 'entries': list(entries.values())},
                                   sort_keys=False, width=120))


def _wait(predicate, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.005)
    return True


def failed_record(episode: Episode, options: BenchOptions, reason: str = '') -> dict:
    """An episode's record before it ran: not a success, with `reason`."""
    return {'key': episode_key(episode.group, episode.template, episode.seed), 'seed': episode.seed,
            'group': episode.group, 'template': episode.template, 'attributes': episode.attributes,
            'instruction': episode.instruction, 'policy': options.policy, 'perception': options.perception,
            'code': '', 'success': False, 'reason': reason, 'sim_seconds': 0.0, 'wall_seconds': 0.0,
            'model_calls': 0, 'prompt_tokens': 0, 'completion_tokens': 0}


def run_episodes(keys: Iterable[str], options: BenchOptions, make_runner: Callable[[], Any],
                 write: Callable[[dict], None]) -> int:
    """Run the episodes `keys` one after another on a graph from `make_runner()`, writing each record; return how
    many graphs were built (see EpisodeGraph)."""
    graph = EpisodeGraph(options, make_runner)
    try:
        for key in keys:
            write(graph.run(key))
    finally:
        graph.close()
    return graph.built


class EpisodeGraph:
    """Episodes run one at a time on a graph from `make_runner()`, built at once.

    A graph that stops answering (a service or a goal without an answer in time: TimeoutError) costs its episode,
    recorded as failed with the reason, not the rest of the run: it is closed, and the next episodes run on a new one.
    """

    def __init__(self, options: BenchOptions, make_runner: Callable[[], Any]) -> None:
        self.options, self.make_runner = options, make_runner
        self.runner = make_runner()
        self.built = 1

    def run(self, key: str) -> dict:
        """The record of the episode `key` ('group/template/seed')."""
        group, template, seed = key.split('/')
        episode = sample_episode(group, template, int(seed))
        try:
            return self.runner.run(episode)
        except TimeoutError as error:
            record = failed_record(episode, self.options, f'the graph stopped answering ({error}); the episodes '
                                                          'after it ran on a new graph')
            print(f'{record["key"]}: {record["reason"]}', file=sys.stderr)
            self.runner.close()
            self.runner = None
            self.runner = self.make_runner()
            self.built += 1
            return record

    def close(self) -> None:
        if self.runner is not None:
            self.runner.close()
            self.runner = None


class _EpisodeRunner:
    """One graph (in this process) running episodes one after another."""

    def __init__(self, options: BenchOptions, cassette: pathlib.Path | None, cpu: int = 0) -> None:
        import rclpy
        from cap_ros_common.actions import ActionClient
        from rclpy.context import Context
        from std_srvs.srv import Trigger

        from cap_interfaces.action import ExecuteCommand
        from cap_interfaces.msg import GraphNames
        from cap_interfaces.srv import ResetScene
        from cap_bringup.graph import Graph, GraphOptions

        self.options = options
        self.context = Context()
        rclpy.init(context=self.context)
        lmp: dict[str, Any] = {'time_limit_s': options.episode_timeout_s}
        backend = 'cassette' if options.policy == 'oracle' else options.backend
        if backend == 'local':  # lmp_node starts and supervises the model server itself
            lmp.update(model_file=options.model_file, model_threads=options.model_threads)
        elif options.policy == 'llm':
            lmp.update(api=options.api)
            if options.base_url:
                lmp['base_url'] = options.base_url
            if options.model:
                lmp['model'] = options.model
        self.graph = Graph(self.context, GraphOptions(
            perception=options.perception, llm_backend=backend,
            cassette=str(cassette) if cassette else '', camera_rate=rgbd_camera_rate(options),
            extra={'lmp_node': lmp, 'sim_bridge': {'cameras': [DEFAULT_CAMERA]}}, cpu=cpu))
        self.node = rclpy.create_node('cap_bench', context=self.context)
        self.graph.executor.add_node(self.node)
        self.execute = ActionClient(self.node, ExecuteCommand, GraphNames.EXECUTE_ACTION)
        self.reset = self.node.create_client(ResetScene, GraphNames.SIM_RESET_SERVICE)
        self.reset_session = self.node.create_client(Trigger, GraphNames.RESET_SESSION_SERVICE)
        self.forget = self.node.create_client(Trigger, GraphNames.PERCEPTION_FORGET_SERVICE)
        self.ExecuteCommand, self.ResetScene, self.Trigger = ExecuteCommand, ResetScene, Trigger
        if not _wait(lambda: self.execute.server_is_ready() and self.reset.service_is_ready()
                     and self.reset_session.service_is_ready() and self.forget.service_is_ready(), 60):
            raise RuntimeError('the graph did not come up within 60 s')
        if backend == 'local' and not self.graph.nodes['lmp_node'].model_ready.wait(MODEL_READY_TIMEOUT_S):
            raise RuntimeError(f'the local model was not ready within {MODEL_READY_TIMEOUT_S:.0f} s')

    def _call(self, future, timeout: float, what: str):
        if not _wait(future.done, timeout):
            raise TimeoutError(f'no answer from {what} within {timeout:.0f} s')
        return future.result()

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
        from geometry_msgs.msg import Point

        from cap_interfaces.msg import ObjectSpec

        world = self.graph.world
        record = failed_record(episode, self.options)
        wall_started = time.monotonic()
        request = self.ResetScene.Request(seed=episode.seed, objects=[
            ObjectSpec(name=o.name, category=o.category, color_name=o.color, use_position=True,
                       position=Point(x=o.xy[0], y=o.xy[1])) for o in episode.objects])
        answer = self._call(self.reset.call_async(request), 60, 'the scene reset')
        if not answer.success:
            record['reason'] = f'scene reset failed: {answer.message}'
            return record
        self._call(self.forget.call_async(self.Trigger.Request()), SERVICE_TIMEOUT_S, 'perception (forget)')
        self._call(self.reset_session.call_async(self.Trigger.Request()), SERVICE_TIMEOUT_S,
                   'lmp_node (reset session)')
        tolerance = 0.005 if self.options.perception == 'ground_truth' else 0.02
        if not _wait(lambda: not self._perception_mismatch(episode, tolerance), 30):
            record['reason'] = ('perception did not report the scene as reset within 30 s: '
                                + self._perception_mismatch(episode, tolerance))
            return record
        initial = {s.name: s.position for s in world.object_states()}
        sim_started = world.time
        codes, calls, prompt_tokens, completion_tokens = [], 0, 0, 0
        for instruction in instructions or (episode.instruction,):
            goal = self._call(self.execute.send_goal_async(self.ExecuteCommand.Goal(command=instruction)), 30,
                              'lmp_node (goal)')
            result_future = goal.get_result_async()
            if not _wait(result_future.done, self.options.episode_timeout_s + 60):
                goal.cancel_goal_async()
                _wait(result_future.done, 30)
                record['reason'] = f'no result within {self.options.episode_timeout_s:.0f} s'
                return record
            result = result_future.result().result
            codes.append(result.code)
            calls += result.model_calls
            prompt_tokens += result.prompt_tokens
            completion_tokens += result.completion_tokens
            if result.outcome != self.ExecuteCommand.Result.OUTCOME_DONE:
                break
        settle_until = world.time + SETTLE_S
        _wait(lambda: world.time >= settle_until, 30)
        final = {s.name: s.position for s in world.object_states()}
        verdict = judge(episode, initial, final)
        done = result.outcome == self.ExecuteCommand.Result.OUTCOME_DONE
        record.update(code='\n# ---\n'.join(codes), success=bool(done and verdict.success),
                      outcome=outcome_name(result.outcome),
                      sim_seconds=world.time - sim_started, wall_seconds=time.monotonic() - wall_started,
                      model_calls=calls, prompt_tokens=prompt_tokens, completion_tokens=completion_tokens,
                      final_state={k: [round(float(v), 4) for v in p] for k, p in final.items()})
        if not done:
            record['reason'] = f'{_outcome_reason(result.outcome)}: {result.message}'
        elif not verdict.success:
            record['reason'] = f'the final state is wrong: {verdict.reason}'
        return record

    def close(self) -> None:
        self.graph.close()
        self.node.destroy_node()
        self.context.try_shutdown()


_OUTCOME_REASONS = {'error': 'the program failed', 'cancelled': 'the command was cancelled',
                    'refused': 'the command was refused', 'model_error': 'the model gave no usable answer'}


def outcome_name(outcome: int) -> str:
    """lmp_node's name of an ExecuteCommand outcome (imported when first needed: it loads rclpy)."""
    from cap_lmp_ros.lmp_node import outcome_name as name_of

    return name_of(outcome)


def _outcome_reason(outcome: int) -> str:
    name = outcome_name(outcome)
    return _OUTCOME_REASONS.get(name, f'the command ended with outcome {name}')


def _worker(index: int, keys, options: BenchOptions, cassette: str | None, results: str, progress) -> None:
    """Job `index`: run the episodes it takes from the queue `keys` (until it takes None) on a graph of its own."""
    # Ctrl-C reaches every process of the terminal's group: the parent alone decides, and ends workers by SIGTERM
    # (which closes the graph: see cap_bringup.graph.Graph).
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # Each worker is a graph of its own: keep it on a DDS domain of its own.
    os.environ['ROS_DOMAIN_ID'] = str(options.first_domain_id + index)
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    # Job i on CPU i: each job's threads share one interpreter lock (see cap_bringup.cpu_affinity).
    with open(results, 'a', encoding='utf-8') as out:
        def write(record: dict) -> None:
            write_record(out, record)
            if progress is not None:
                progress.put(record['success'])

        run_episodes(iter(keys.get, None), options,
                     lambda: _EpisodeRunner(options, pathlib.Path(cassette) if cassette else None, cpu=index), write)


def write_record(out, record: dict) -> None:
    """Append `record` to an episodes*.jsonl file, at once (a run stopped later keeps it)."""
    out.write(json.dumps(record) + '\n')
    out.flush()


def load_records(out_dir: pathlib.Path) -> list[dict]:
    records = {}
    for path in sorted(out_dir.glob('episodes*.jsonl')):
        for line in path.read_text(encoding='utf-8').splitlines():
            if line.strip():
                record = json.loads(line)
                records[record['key']] = record
    return list(records.values())


def run_benchmark(options: BenchOptions, show_progress: bool = True) -> dict:
    """Run (or resume) a benchmark; return the summary written to report.json / report.md / report.png."""
    out_dir = pathlib.Path(options.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    episodes = plan(options)
    done = {r['key'] for r in load_records(out_dir)} if options.resume else set()
    if not options.resume:
        for old in out_dir.glob('episodes*.jsonl'):
            old.unlink()
    todo = [e for e in episodes if episode_key(e.group, e.template, e.seed) not in done]
    cassette = None
    if options.policy == 'oracle':
        cassette = out_dir / 'oracle_cassette.yaml'
        write_oracle_cassette(episodes, cassette)
    options.first_domain_id = domain_ids(options.jobs, options.first_domain_id)[0]
    (out_dir / 'options.json').write_text(json.dumps(dataclasses.asdict(options), indent=2))
    started = time.monotonic()
    jobs = max(1, min(options.jobs, len(todo)))
    keys = [episode_key(e.group, e.template, e.seed) for e in todo]
    if todo:
        with progress_bar(show_progress, len(episodes), len(episodes) - len(todo)) as count:
            if options.executor == 'ray':
                from cap_bench import ray_executor  # only here: the local executor never loads Ray

                ray_executor.run_jobs(keys, jobs, options, cassette, out_dir, count)
            else:
                _run_local(keys, jobs, options, cassette, out_dir, count)
    records = [r for r in load_records(out_dir)
               if r['key'] in {episode_key(e.group, e.template, e.seed) for e in episodes}]
    title = (f"Table-top benchmark ({policy_name(options)}): perception {options.perception}, "
             f"{options.trials} trial(s) per row")
    summary = write_report(records, out_dir, title, policy_description(options))
    summary['wall_seconds_this_run'] = time.monotonic() - started
    summary['episodes'] = len(records)
    return summary


@contextlib.contextmanager
def progress_bar(show: bool, total: int, already: int) -> Iterator[Callable[[bool], None]]:
    """A function to call with each finished episode's success: a progress bar on the terminal when `show`."""
    if not show:
        yield lambda success: None
        return
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn
    bar = Progress(TextColumn('[bold]cap bench'), BarColumn(), MofNCompleteColumn(),
                   TextColumn('{task.fields[ok]}'), TimeRemainingColumn())
    task = bar.add_task('episodes', total=total, completed=already, ok='')
    finished, successes = already, 0

    def count(success: bool) -> None:
        nonlocal finished, successes
        finished += 1
        successes += bool(success)
        bar.update(task, completed=finished, ok=f'{successes}/{finished - already} succeeded')

    bar.start()
    try:
        yield count
    finally:
        bar.stop()


def _run_local(keys: list[str], jobs: int, options: BenchOptions, cassette: pathlib.Path | None,
               out_dir: pathlib.Path, count: Callable[[bool], None]) -> None:
    """Run `keys` on `jobs` worker processes, each taking the next episode from one queue when it is free.

    A job does not get a fixed share: episodes differ in length and jobs in speed (in a 22 x 50 oracle run with
    fixed halves, one job needed 925 s and the other 744 s), and a shared queue keeps both busy to the end.
    """
    context = multiprocessing.get_context('spawn')
    progress, queued = context.Queue(), context.Queue()
    for key in keys:
        queued.put(key)
    for _ in range(jobs):
        queued.put(None)  # one end mark per job
    processes = [context.Process(target=_worker, args=(i, queued, options, str(cassette) if cassette else None,
                                                       str(out_dir / f'episodes-{i}.jsonl'), progress))
                 for i in range(jobs)]
    for process in processes:
        process.start()
    interrupted = False
    try:
        while any(p.is_alive() for p in processes) or not progress.empty():
            try:
                success = progress.get(timeout=0.5)
            except queue.Empty:  # nothing finished in this half second
                continue
            count(success)
    except BaseException:  # Ctrl-C, SIGTERM (see main): end the workers, each closing its graph
        interrupted = True
        for process in processes:
            if process.is_alive():
                process.terminate()
        raise
    finally:
        for process in processes:
            process.join(timeout=30 if interrupted else None)
            if process.is_alive():  # a worker that did not close in time
                process.kill()
                process.join()
    failed = [p.exitcode for p in processes if p.exitcode]
    if failed:
        raise RuntimeError(f'{len(failed)} benchmark worker(s) failed (exit codes {failed}); see the log above. '
                           f'Run again with --resume to continue.')


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog='cap bench tabletop', description='The paper\'s simulated table-top '
                                     'benchmark through the cap-ros graph.')
    parser.add_argument('--policy', choices=('oracle', 'llm'), default='oracle',
                        help='oracle: reference programs; llm: a model at an OpenAI-compatible endpoint')
    parser.add_argument('--groups', default=','.join(GROUPS), help='comma-separated: SA-SI, UA-SI, UA-UI')
    parser.add_argument('--tasks', default=','.join(TEMPLATES), help='comma-separated template names')
    parser.add_argument('--trials', type=int, default=50, help='episodes per row [50]')
    parser.add_argument('--perception', choices=('ground_truth', 'rgbd'), default='ground_truth')
    parser.add_argument('--camera-rate', type=float, default=RGBD_CAMERA_RATE,
                        help=f'with --perception rgbd: camera images per second of simulated time '
                             f'[{RGBD_CAMERA_RATE:g}]')
    parser.add_argument('--seed', type=int, default=0, help='base seed: trial i uses seed base + i [0]')
    parser.add_argument('--jobs', type=int, default=1,
                        help='parallel graphs (processes) [1]; job i uses ROS_DOMAIN_ID + i when ROS_DOMAIN_ID is '
                             'set, else consecutive ids from a start derived from the process id')
    parser.add_argument('--executor', choices=('local', 'ray'), default='local',
                        help='local: a process per job on this machine; ray: a task per job on a Ray cluster, on '
                             'one machine or several [local]')
    parser.add_argument('--ray-address', default='',
                        help='with --executor ray: the cluster to join (HEAD:6379, `ray start --head` on HEAD); '
                             'default: a Ray instance on 127.0.0.1 for this run')
    parser.add_argument('--out', default='output/bench', help='output folder [output/bench]')
    parser.add_argument('--resume', action='store_true', help='keep the episodes already in --out')
    add_model_arguments(parser, default_api='chat')
    parser.add_argument('--episode-timeout', type=float, default=900.0, help='per episode [s]')
    return parser


def add_model_arguments(parser: argparse.ArgumentParser, default_api: str) -> None:
    """The options that choose the model of --policy llm (read back with model_settings)."""
    parser.add_argument('--backend', choices=('http', 'local'), default='http',
                        help='for --policy llm: http (--base-url) or local (the llama.cpp server and model of `make '
                             'model`, started for the run; completions API) [http]')
    parser.add_argument('--base-url', default='', help='for --backend http; default CAP_LLM_BASE_URL')
    parser.add_argument('--model', default='', help='for --backend http; default CAP_LLM_MODEL')
    parser.add_argument('--api', choices=('chat', 'completions'), default=default_api,
                        help=f'for --backend http: the endpoint protocol [{default_api}]')
    parser.add_argument('--model-file', default='', help='with --backend local: a GGUF file [the default model]')
    parser.add_argument('--model-threads', type=int, default=1, help='with --backend local: server threads [1]')


def model_settings(args: argparse.Namespace) -> dict[str, Any]:
    """BenchOptions fields from the options of add_model_arguments."""
    return {'backend': args.backend, 'base_url': args.base_url, 'model': args.model, 'api': args.api,
            'model_file': args.model_file, 'model_threads': args.model_threads}


class Interrupted(BaseException):
    """SIGINT or SIGTERM arrived: stop the run (a BaseException, like KeyboardInterrupt: no handler swallows it)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.exit_code = 128 + signum


def _raise_interrupted(signum, _frame) -> None:
    raise Interrupted(signum)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    groups = tuple(g.strip() for g in args.groups.split(',') if g.strip())
    tasks = tuple(t.strip() for t in args.tasks.split(',') if t.strip())
    unknown = [g for g in groups if g not in GROUPS] + [t for t in tasks if t not in TEMPLATES]
    if unknown:
        print(f'unknown groups or tasks: {", ".join(unknown)}; groups: {", ".join(GROUPS)}; tasks: '
              f'{", ".join(TEMPLATES)}', file=sys.stderr)
        return 2
    options = BenchOptions(policy=args.policy, groups=groups, tasks=tasks, trials=args.trials,
                           perception=args.perception, camera_rate=args.camera_rate, base_seed=args.seed,
                           jobs=args.jobs, out=args.out,
                           resume=args.resume, episode_timeout_s=args.episode_timeout, executor=args.executor,
                           ray_address=args.ray_address, **model_settings(args))
    try:
        domain_ids(options.jobs)
    except ValueError as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, _raise_interrupted)
    try:
        with model_endpoint(options) as options:
            summary = run_benchmark(options)
    except Interrupted as interrupted:
        done = len(load_records(pathlib.Path(args.out)))
        print(f'interrupted ({interrupted}): {done} episode(s) are in {args.out}; continue with --resume',
              file=sys.stderr)
        return interrupted.exit_code
    except LLMError as error:  # the local model could not start: one line saying why and what to do
        print(f'error: {one_line(str(error))}', file=sys.stderr)
        return 2
    # The report quotes the programs' messages: never a raw control character on the terminal.
    report = (pathlib.Path(args.out) / 'report.md').read_text(encoding='utf-8')
    print(terminal_text(report, limit=len(report)))
    print(json.dumps({'overall_percent': summary['overall']['percent'], 'episodes': summary['episodes'],
                      'wall_seconds': round(summary['wall_seconds_this_run'], 1), 'out': args.out}))
    return 0


if __name__ == '__main__':
    sys.exit(main())
