"""Run benchmark items over parallel sessions: one JSON line per item as it ends, resume, a progress bar.

Each job is a thread with an evaluator of its own (its own sandbox process); the jobs take items from one queue,
so `--jobs N` keeps N model requests in flight. Records are appended to items.jsonl under a lock as each item ends:
an interrupted run keeps what it finished, and `--resume` skips the keys already there. Without `--resume` a run
starts from an empty items.jsonl. run.json keeps the settings of the run; `--resume` with other settings is refused.
"""
from __future__ import annotations

import json
import pathlib
import queue
import threading
from typing import Any, Callable, Mapping, Protocol, Sequence

from cap_bench.language.policy import PolicyOptions, open_client
from cap_lmp.llm import LLMClient

ITEMS_FILE = 'items.jsonl'
SETTINGS_FILE = 'run.json'


class Evaluator(Protocol):
    """Judges one item; `close` ends what it started (its sandbox process)."""

    def evaluate(self, key: str) -> dict[str, Any]:
        ...

    def close(self) -> None:
        ...


def load_records(out_dir: pathlib.Path) -> dict[str, dict[str, Any]]:
    """The records of items.jsonl by key (a line cut short by an interruption is skipped)."""
    path = out_dir / ITEMS_FILE
    records: dict[str, dict[str, Any]] = {}
    if not path.exists():
        return records
    for line in path.read_text(encoding='utf-8').splitlines():
        try:
            record = json.loads(line)
        except ValueError:
            continue
        if isinstance(record, dict) and isinstance(record.get('key'), str):
            records[record['key']] = record
    return records


def run_items(keys: Sequence[str], make_evaluator: Callable[[], Evaluator], out_dir: pathlib.Path, *,
              jobs: int = 1, resume: bool = False, show_progress: bool = True, label: str = 'items',
              settings: Mapping[str, Any] | None = None,
              passed: Callable[[Mapping[str, Any]], bool] = lambda record: bool(record.get('passed'))
              ) -> list[dict[str, Any]]:
    """Evaluate every key not yet done; return the records of all `keys`, in their order.

    `settings` (JSON values: policy, sampling, limits) are kept in run.json; a resumed run must have the same ones,
    so that one report never mixes items judged differently."""
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / ITEMS_FILE
    settings_path = out_dir / SETTINGS_FILE
    settings = json.loads(json.dumps(dict(settings or {})))
    if resume and settings_path.exists():
        before = json.loads(settings_path.read_text(encoding='utf-8'))
        changed = sorted(key for key in set(before) | set(settings) if before.get(key) != settings.get(key))
        if changed:
            raise ValueError(f'the run in {out_dir} was made with other settings ({", ".join(changed)}): resume it '
                             'with the same ones, or choose another --out')
    settings_path.write_text(json.dumps(settings, indent=2), encoding='utf-8')
    done = load_records(out_dir) if resume else {}
    if not resume and path.exists():
        path.unlink()
    todo: queue.Queue[str] = queue.Queue()
    for key in keys:
        if key not in done:
            todo.put(key)
    lock = threading.Lock()
    stop = threading.Event()
    errors: list[BaseException] = []
    wanted = set(keys)
    counts = {'finished': len(keys) - todo.qsize(), 'passed': sum(passed(r) for k, r in done.items() if k in wanted)}
    if path.exists() and path.stat().st_size:
        with path.open('rb+') as stream:  # a line cut short by an interruption stays alone
            stream.seek(-1, 2)
            if stream.read(1) != b'\n':
                stream.write(b'\n')
    bar, task = _progress(show_progress, label, len(keys), counts['finished'])

    def work() -> None:
        try:
            evaluator = make_evaluator()
        except BaseException as error:  # a session that cannot start ends the run, reported below
            errors.append(error)
            stop.set()
            return
        try:
            while not stop.is_set():
                try:
                    key = todo.get_nowait()
                except queue.Empty:
                    return
                record = {'key': key, **evaluator.evaluate(key)}
                with lock:
                    with path.open('a', encoding='utf-8') as stream:
                        stream.write(json.dumps(record) + '\n')
                    done[key] = record
                    counts['finished'] += 1
                    counts['passed'] += passed(record)
                    if bar is not None:
                        bar.update(task, completed=counts['finished'],
                                   ok=f"{counts['passed']}/{counts['finished']} passed")
        except BaseException as error:
            errors.append(error)
            stop.set()
        finally:
            evaluator.close()

    threads = [threading.Thread(target=work, name=f'bench-job-{index}', daemon=True)
               for index in range(max(1, min(jobs, todo.qsize() or 1)))]
    try:
        for thread in threads:
            thread.start()
        for thread in threads:
            while thread.is_alive():
                thread.join(0.2)
    except BaseException:  # Ctrl-C, SIGTERM: the jobs stop after their current item; what ended is kept
        stop.set()
        for thread in threads:
            thread.join(30)
        raise
    finally:
        if bar is not None:
            bar.stop()
    if errors:
        raise RuntimeError(f'a benchmark job failed: {type(errors[0]).__name__}: {errors[0]} '
                           '(the items finished so far are kept; continue with --resume)') from errors[0]
    return [done[key] for key in keys if key in done]


def run_with_policy(benchmark: str, options: PolicyOptions, answers: Sequence[tuple[str, str]],
                    keys: Sequence[str], make_evaluator: Callable[[LLMClient], Evaluator], out_dir: pathlib.Path, *,
                    jobs: int = 1, resume: bool = False, show_progress: bool = True,
                    settings: Mapping[str, Any] | None = None) -> tuple[list[dict[str, Any]], str]:
    """run_items with the policy's client (for the oracle, its server lives as long as the run); the records and
    the line that names the policy. The policy and `settings` are the run's settings (run.json)."""
    with open_client(options, answers) as client:
        policy = options.describe(client)
        records = run_items(keys, lambda: make_evaluator(client), out_dir, jobs=jobs, resume=resume,
                            show_progress=show_progress, label=benchmark,
                            settings={'benchmark': benchmark, 'policy': policy, **(settings or {})})
    return records, policy


def _progress(show: bool, label: str, total: int, completed: int) -> tuple[Any, Any]:
    if not show:
        return None, None
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn
    bar = Progress(TextColumn(f'[bold]cap bench {label}'), BarColumn(), MofNCompleteColumn(),
                   TextColumn('{task.fields[ok]}'), TimeRemainingColumn())
    bar.start()
    task = bar.add_task(label, total=total, completed=completed, ok='')
    return bar, task
