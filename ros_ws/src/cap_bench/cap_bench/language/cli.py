"""Command-line options every language-side benchmark shares, and the signal handling of a run."""
from __future__ import annotations

import argparse
import contextlib
import signal
import sys
from typing import Any, Callable, Iterator, Sequence

from cap_bench.language.policy import PolicyOptions
from cap_lmp.errors import CapLLMError
from cap_lmp.isolated_engine import JAIL_MODES

EXIT_INTERRUPTED = {signal.SIGINT: 130, signal.SIGTERM: 143}


def add_common_arguments(parser: argparse.ArgumentParser, *, out: str, time_limit_s: float) -> None:
    parser.add_argument('--policy', choices=('oracle', 'llm'), default='oracle',
                        help='oracle: the reference answers, served over HTTP on 127.0.0.1; llm: the model at '
                             '--base-url / CAP_LLM_BASE_URL [oracle]')
    parser.add_argument('--backend', choices=('http', 'local'), default='http',
                        help='for --policy llm: http (--base-url) or local (the llama.cpp server and model of `make '
                             'model`, started for the run and stopped after it) [http]')
    parser.add_argument('--model-file', default='', help='with --backend local: a GGUF file [the default model]')
    parser.add_argument('--model-threads', type=int, default=2,
                        help='with --backend local: server threads [2: no simulator runs beside it]')
    parser.add_argument('--base-url', default='', help='for --policy llm; default CAP_LLM_BASE_URL')
    parser.add_argument('--model', default='', help='for --policy llm; default CAP_LLM_MODEL')
    parser.add_argument('--api', choices=('completions', 'chat'), default='completions',
                        help='the endpoint protocol [completions]')
    parser.add_argument('--chat-system', choices=('project', 'model'), default='project',
                        help='with --api chat: the project\'s system prompt, or none so that the model\'s chat '
                             'template puts in its own default [project]')
    parser.add_argument('--request-timeout', type=float, default=120.0, help='seconds per HTTP attempt [120]')
    parser.add_argument('--jobs', type=int, default=1, help='parallel sessions, i.e. requests in flight [1]')
    parser.add_argument('--out', default=out, help=f'output folder [{out}]')
    parser.add_argument('--resume', action='store_true', help='keep the items already in --out/items.jsonl')
    parser.add_argument('--limit', type=int, default=0, help='only the first N items of each variant [all]')
    parser.add_argument('--time-limit', type=float, default=time_limit_s,
                        help=f'seconds each test program may run in the sandbox [{time_limit_s:g}]')
    parser.add_argument('--jail', choices=JAIL_MODES, default='required',
                        help='the sandbox process\' OS jail (Landlock + seccomp) [required]')
    parser.add_argument('--no-progress', action='store_true', help='no progress bar')


def choose(text: str, allowed: Sequence[str], option: str, prog: str) -> list[str]:
    """The comma-separated choices of an option; a usage error (exit 2) naming what was wrong otherwise."""
    chosen = [part.strip() for part in text.split(',') if part.strip()]
    unknown = [part for part in chosen if part not in allowed]
    if unknown or not chosen:
        print(f'{prog}: error: {option} takes {", ".join(allowed)} (comma-separated), not {text!r}', file=sys.stderr)
        raise SystemExit(2)
    return chosen


def policy_of(args: argparse.Namespace) -> PolicyOptions:
    return PolicyOptions(policy=args.policy, base_url=args.base_url, model=args.model, api=args.api,
                         timeout_s=args.request_timeout, chat_system=args.chat_system)


class Interrupted(Exception):
    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


def _raise_interrupted(signum: int, _frame: Any) -> None:
    raise Interrupted(signum)


@contextlib.contextmanager
def local_model(args: argparse.Namespace | None) -> Iterator[None]:
    """With --policy llm --backend local: the local model server for the whole run, its endpoint put into `args`
    (policy_of reads it); otherwise nothing."""
    if args is None or args.policy != 'llm' or getattr(args, 'backend', 'http') != 'local':
        yield
        return
    from cap_lmp.local_server import LocalModelServer, ServerSettings

    if args.jobs != 1:
        raise ValueError('--backend local answers one request at a time: use --jobs 1')
    server = LocalModelServer(ServerSettings(model_file=args.model_file, threads=args.model_threads),
                              on_event=lambda message: print(message, file=sys.stderr))
    server.start()  # stops the server itself if it cannot start
    try:
        args.base_url, args.model = server.base_url, server.model_name  # --api as given: the server has both
        yield
    finally:
        server.stop()


def run_main(run: Callable[[], dict[str, Any]], out: str, args: argparse.Namespace | None = None) -> int:
    """Run a benchmark with SIGINT/SIGTERM ending it cleanly (exit 130/143; --resume continues), print the
    report's path; a failure is one line and exit 1. With `args` of --backend local, the local model server runs
    around it."""
    previous = {signum: signal.signal(signum, _raise_interrupted) for signum in EXIT_INTERRUPTED}
    try:
        with local_model(args):
            summary = run()
    except Interrupted as interrupted:
        print(f'interrupted: the items finished so far are in {out}/items.jsonl; continue with --resume',
              file=sys.stderr)
        return EXIT_INTERRUPTED[signal.Signals(interrupted.signum)]
    except (RuntimeError, ValueError, OSError, CapLLMError) as error:
        print(f'error: {error}', file=sys.stderr)
        return 1
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    print(f"{summary['title']}\npolicy: {summary['policy']}")
    for row in summary['rows']:
        percent = '—' if row['percent'] is None else f"{row['percent']:.1f}%"
        paper = '' if row['paper'] is None else f"  (paper {row['paper']:g}%)"
        print(f"  {row['variant']:<44} {row['group']:<10} {row['metric']:<7} {row['passed']:>4}/{row['items']:<4} "
              f"{percent:>7}{paper}")
    print(f'report: {out}/report.md, report.json, report.png; items: {out}/items.jsonl')
    return 0
