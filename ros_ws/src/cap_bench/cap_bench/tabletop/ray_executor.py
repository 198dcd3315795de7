"""`cap bench tabletop --executor ray`: the run's jobs as tasks on a Ray cluster, on one machine or several.

Why Ray: spreading a run over machines is a distributed engine's work (placing tasks where CPUs are free, streaming
results back, cancelling); Ray is an established one, so the project keeps no engine of its own.

Job i of the run is one Ray task. Like the local executor's worker process, the task brings up a graph of its own
on ROS_DOMAIN_ID first + i, takes the run's episodes one at a time from a queue that every job shares (a Ray queue
actor), runs each on its graph and sends its record back as it ends (a Ray generator task). The driver writes the
records to episodes-<i>.jsonl in --out, so --resume and the report are the local executor's. The ids are distinct
across the run, hence among the tasks that share a machine; DDS discovery stays on each machine's loopback
(ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST), so graphs on different machines never meet whatever their ids.

Without an address the run starts a Ray instance of its own on 127.0.0.1, with one CPU per job (every job runs at
once, as with the local executor), no dashboard and no usage statistics, and stops it at the end. With an address
(host:6379, a cluster's head) it joins that cluster, whose free CPUs decide how many jobs run at once (one CPU per
job), and leaves it running.

Ctrl-C or SIGTERM cancels the running tasks (each closes its graph) and stops the run; the episodes whose records
arrived stay in episodes*.jsonl.
"""
from __future__ import annotations

import logging
import os
import pathlib
import signal
import sys
import tempfile
import time
from types import ModuleType
from typing import Callable, Iterator, Sequence

from cap_bench.episode_runs import write_record
from cap_bench.ros_domains import use_own_domain
from cap_bench.tabletop.options import TabletopOptions
from cap_bench.tabletop.runner import TabletopRunner, episode_graph
from cap_bench.tabletop.sampling import episode_for_key

CANCEL_TIMEOUT_S = 30.0  # for a cancelled task to close its graph before it is killed


def _run_job(index: int, keys, options: TabletopOptions, cassette_text: str | None, domain_id: int) -> Iterator[dict]:
    """In a Ray worker: bring up a graph and yield the record of each episode it takes from the run's queue `keys`
    (a ray.util.queue.Queue), until it takes None."""
    # Before rclpy starts: a DDS domain of this job's own, discovery on this machine's loopback only.
    use_own_domain(domain_id)
    os.environ.pop('ROS_LOCALHOST_ONLY', None)
    # This task may run on a machine without the driver's --out: the oracle cassette travels as text.
    with tempfile.TemporaryDirectory(prefix='cap-bench-') as folder:
        cassette = None
        if cassette_text is not None:
            cassette = pathlib.Path(folder) / 'oracle_cassette.yaml'
            cassette.write_text(cassette_text, encoding='utf-8')
        # Pinned to CPU i of this machine (modulo its CPUs), as local job i is (see cap_bringup.cpu_affinity).
        graph = episode_graph(options, lambda: TabletopRunner(options, cassette, cpu=index))
        try:
            for key in iter(keys.get, None):
                yield graph.run(episode_for_key(key))
        finally:  # also on cancellation (KeyboardInterrupt raised in the task)
            graph.close()


def start(address: str, jobs: int) -> ModuleType:
    """Connect this process to the cluster at `address`, or start a Ray instance on loopback for `jobs` jobs; return
    the ray module."""
    # Both read when Ray is imported, and inherited by the processes it starts.
    os.environ['RAY_USAGE_STATS_ENABLED'] = '0'  # no usage statistics sent anywhere
    if not address:
        # A one-machine instance: without this, Ray swaps the node address 127.0.0.1 for the address of the
        # interface that routes towards a public address, and its servers listen on every interface.
        os.environ['RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER'] = '0'
    import ray

    previous = signal.getsignal(signal.SIGTERM)  # ray.init installs its own SIGTERM handler in the driver
    try:
        if address:
            ray.init(address=address, logging_level=logging.WARNING)
        else:
            # address='local': a new instance, never one found on the machine (RAY_ADDRESS, `ray start`).
            ray.init(address='local', _node_ip_address='127.0.0.1', include_dashboard=False, num_cpus=jobs,
                     logging_level=logging.WARNING)
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
    return ray


def run_jobs(keys: Sequence[str], jobs: int, options: TabletopOptions, cassette: pathlib.Path | None,
             out_dir: pathlib.Path, count: Callable[[bool], None]) -> None:
    """Run the episodes `keys` on `jobs` Ray tasks, each taking the next episode from one queue when it is free,
    writing each record of job i to out_dir/episodes-<i>.jsonl and counting it with `count(success)`; raise
    RuntimeError naming the jobs that failed."""
    ray = start(options.ray_address, jobs)
    from ray.util.queue import Queue  # after start(): it makes an actor on the cluster

    # One CPU per job; a fresh worker process for each (max_calls=1: no rclpy state carried from one job to another);
    # no retry, which would run a failed job's episodes again (--resume does that, for the episodes without a record).
    job = ray.remote(num_cpus=1, max_calls=1, max_retries=0)(_run_job)
    queued = None
    try:
        # The queue is an actor holding only the keys (no CPU of its own: every CPU is for a job). Machines and
        # episodes differ in speed; a job that is free takes the next episode, as the local executor's jobs do.
        queued = Queue(actor_options={'num_cpus': 0})
        queued.put_nowait_batch(list(keys) + [None] * jobs)  # one end mark per job
        cassette_text = cassette.read_text(encoding='utf-8') if cassette else None
        streams = {job.remote(i, queued, options, cassette_text, options.first_domain_id + i): i
                   for i in range(jobs)}
        failures = _collect(ray, streams, out_dir, count)
    finally:
        if queued is not None:
            queued.shutdown(force=True)  # on a joined cluster it would outlive the run
        ray.shutdown()  # stops the instance this run started; leaves a joined cluster running
    if failures:
        raise RuntimeError(f'{len(failures)} benchmark job(s) failed ({"; ".join(failures)}). '
                           f'Run again with --resume to continue.')


def _collect(ray: ModuleType, streams: dict, out_dir: pathlib.Path, count: Callable[[bool], None]) -> list[str]:
    """Write every record as it arrives until every task has ended; return what made jobs fail."""
    files = {i: open(out_dir / f'episodes-{i}.jsonl', 'a', encoding='utf-8') for i in streams.values()}
    running, failures = dict(streams), []
    try:
        while running:
            ready, _ = ray.wait(list(running), num_returns=1, timeout=0.5)  # returns to let signals in
            for stream in ready:
                index = running[stream]
                try:
                    record = ray.get(next(stream))
                except StopIteration:
                    del running[stream]
                    continue
                except ray.exceptions.RayError as error:
                    failures.append(f'job {index}: {_first_line(error)}')
                    print(f'benchmark job {index} failed: {error}', file=sys.stderr)
                    del running[stream]
                    continue
                write_record(files[index], record)
                count(record['success'])
    except BaseException:  # Ctrl-C, SIGTERM: each task closes its graph (KeyboardInterrupt in the task)
        _cancel(ray, list(running))
        raise
    finally:
        for file in files.values():
            file.close()
    return failures


def _cancel(ray: ModuleType, streams: list) -> None:
    for stream in streams:
        ray.cancel(stream)
    ends = {stream.completed(): stream for stream in streams}
    deadline = time.monotonic() + CANCEL_TIMEOUT_S
    while ends and time.monotonic() < deadline:
        done, _ = ray.wait(list(ends), num_returns=len(ends), timeout=0.5)
        for end in done:
            del ends[end]
    for stream in ends.values():  # a task that did not close its graph in time
        ray.cancel(stream, force=True)


def _first_line(error: BaseException) -> str:
    lines = [line for line in str(error).splitlines() if line.strip()]
    return lines[-1].strip() if lines else type(error).__name__
