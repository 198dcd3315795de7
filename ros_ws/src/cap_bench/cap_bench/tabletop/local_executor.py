"""`cap bench tabletop --executor local` (the default): the run's jobs as processes on this machine, each with a
graph of its own on a DDS domain and a CPU of its own, taking the episodes from one queue."""
from __future__ import annotations

import multiprocessing
import pathlib
import queue
import signal
from typing import Callable

from cap_bench.episode_runs import write_record
from cap_bench.ros_domains import use_own_domain
from cap_bench.tabletop.options import TabletopOptions
from cap_bench.tabletop.runner import TabletopRunner, run_episodes


def _worker(index: int, keys, options: TabletopOptions, cassette: str | None, results: str, progress) -> None:
    """Job `index`: run the episodes it takes from the queue `keys` (until it takes None) on a graph of its own."""
    # Ctrl-C reaches every process of the terminal's group: the parent alone decides, and ends workers by SIGTERM
    # (which closes the graph: see cap_bringup.graph.Graph).
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # Each worker is a graph of its own: keep it on a DDS domain of its own.
    use_own_domain(options.first_domain_id + index)
    # Job i on CPU i: each job's threads share one interpreter lock (see cap_bringup.cpu_affinity).
    with open(results, 'a', encoding='utf-8') as out:
        def write(record: dict) -> None:
            write_record(out, record)
            if progress is not None:
                progress.put(record['success'])

        run_episodes(iter(keys.get, None), options,
                     lambda: TabletopRunner(options, pathlib.Path(cassette) if cassette else None, cpu=index), write)


def run_jobs(keys: list[str], jobs: int, options: TabletopOptions, cassette: pathlib.Path | None,
             out_dir: pathlib.Path, count: Callable[[bool], None]) -> None:
    """Run `keys` on `jobs` worker processes, each taking the next episode from one queue when it is free, writing
    each record of job i to out_dir/episodes-<i>.jsonl and counting it with `count(success)`.

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
    except BaseException:  # Ctrl-C, SIGTERM (see cap_bench.graph_cli): end the workers, each closing its graph
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
