"""The command line of the benchmarks that run their episodes through a graph (`cap bench tabletop`, `devset`,
`whiteboard`, `mobile`, `controllers`): the options they share and the course of their main().

A benchmark describes itself with a GraphBench: its name and defaults, the options of its own, how the parsed
options become a run and what the run prints. main() parses the options, refuses a bad value with one line (exit
2), starts the local model server of --backend local for the whole run, says in one line why a model could not
start (exit 2), and stops cleanly on SIGINT (Ctrl-C) or SIGTERM: the graphs close, the episodes finished so far
stay in the output folder, and the command exits 130 or 143.
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import os
import signal
import sys
from typing import Any, Callable, Iterator, Sequence

from cap_bench.bench_options import BenchOptions
from cap_bench.episode_runs import EPISODES
from cap_bench.ros_domains import domain_ids
from cap_lmp.errors import LLMError
from cap_lmp.safe_text import one_line

MODEL_OPTIONS = ('backend', 'base_url', 'model', 'api', 'model_file', 'model_threads', 'feedback_rounds')


class Interrupted(BaseException):
    """SIGINT or SIGTERM arrived: stop the run (a BaseException, like KeyboardInterrupt: no handler swallows it)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.exit_code = 128 + signum


def raise_interrupted(signum: int, _frame: Any) -> None:
    raise Interrupted(signum)


def add_model_arguments(parser: argparse.ArgumentParser, default_api: str, backends: bool = True) -> None:
    """The options that choose the model of --policy llm (read back with model_settings); without `backends`, only
    an endpoint's (no local model server)."""
    served = 'for --backend http' if backends else 'for --policy llm'
    if backends:
        parser.add_argument('--backend', choices=('http', 'local'), default='http',
                            help='for --policy llm: http (--base-url) or local (the llama.cpp server and model of '
                                 '`make model`, started for the run; completions API) [http]')
    parser.add_argument('--base-url', default='', help=f'{served}; default CAP_LLM_BASE_URL')
    parser.add_argument('--model', default='', help=f'{served}; default CAP_LLM_MODEL')
    parser.add_argument('--api', choices=('chat', 'completions'), default=default_api,
                        help=f'{served}: the endpoint protocol [{default_api}]')
    parser.add_argument('--feedback-rounds', type=int, default=0,
                        help='for --policy llm: programs that failed while running are followed by one the model '
                             'writes from what happened, this many times per instruction; 0: the paper\'s '
                             'protocol [0]')
    if backends:
        parser.add_argument('--model-file', default='', help='with --backend local: a GGUF file [the default model]')
        parser.add_argument('--model-threads', type=int, default=1, help='with --backend local: server threads [1]')


def model_settings(args: argparse.Namespace) -> dict[str, Any]:
    """BenchOptions fields from the options of add_model_arguments."""
    return {name: getattr(args, name) for name in MODEL_OPTIONS if hasattr(args, name)}


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

    # Graph job i runs on CPU i (see cap_bench.tabletop.local_executor; one graph where a benchmark has no --jobs):
    # the server takes the CPUs after those.
    allowed = sorted(os.sched_getaffinity(0)) if hasattr(os, 'sched_getaffinity') else []
    spare = tuple(allowed[max(1, getattr(options, 'jobs', 1)):])
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


def comma_separated(text: str) -> list[str]:
    """The parts of a comma-separated option, stripped, empty ones left out."""
    return [part.strip() for part in text.split(',') if part.strip()]


@dataclasses.dataclass
class GraphBench:
    """One graph benchmark's command line, `cap bench NAME`: the shared options with its defaults; a subclass adds
    its own options (add_arguments) and says how a run goes (options, run, kept, show)."""
    name: str  # `cap bench NAME`
    description: str
    out: str  # the default --out
    domain: str = ''  # whose prompts warm a local model's cache ('': the name)
    trials: int | None = 10  # the default --trials (with --seed); None: neither option
    per: str = 'template'  # what --trials counts episodes of
    seed_aliases: tuple[str, ...] = ()  # other names of --seed
    resume: bool = True  # --resume
    episode_timeout: float = 300.0  # the default --episode-timeout
    timeout_per: str = 'instruction'  # what --episode-timeout limits
    default_api: str = 'completions'
    backends: bool = True  # --backend local (a model server for the run); False: an endpoint only

    @property
    def prog(self) -> str:
        return f'cap bench {self.name}'

    def build_parser(self) -> argparse.ArgumentParser:
        parser = argparse.ArgumentParser(prog=self.prog, description=self.description)
        parser.add_argument('--policy', choices=('oracle', 'llm'), default='oracle',
                            help='oracle: the reference programs; llm: a model at an OpenAI-compatible endpoint')
        add_model_arguments(parser, self.default_api, self.backends)
        if self.trials is not None:
            parser.add_argument('--trials', type=int, default=self.trials,
                                help=f'episodes per {self.per} [{self.trials}]')
            parser.add_argument('--seed', *self.seed_aliases, dest='seed', type=int, default=0,
                                help='seed of the first trial: trial i uses seed + i [0]')
        parser.add_argument('--out', default=self.out, help=f'output folder [{self.out}]')
        if self.resume:
            parser.add_argument('--resume', action='store_true', help='keep the episodes already in --out')
        parser.add_argument('--episode-timeout', type=float, default=self.episode_timeout,
                            help=f'seconds per {self.timeout_per} [{self.episode_timeout:g}]')
        parser.add_argument('--rehearse', choices=('off', 'always'), default='off',
                            help='always: rehearse every program on a twin of the scene before the robot moves, and '
                                 'record the prediction against the outcome per episode [off]')
        self.add_arguments(parser)
        return parser

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        """The benchmark's own options."""

    def options(self, args: argparse.Namespace) -> BenchOptions:
        """The run's options; ValueError says why an option's value is refused. Here: the shared options; the
        ROS_DOMAIN_IDs the run's graphs will take (see cap_bench.ros_domains) are checked now, taken when it starts."""
        domain_ids(getattr(args, 'jobs', 1))
        shared = {'trials': args.trials, 'base_seed': args.seed} if self.trials is not None else {}
        return BenchOptions(policy=args.policy, out=args.out, resume=getattr(args, 'resume', False),
                            episode_timeout_s=args.episode_timeout, rehearse=args.rehearse, **shared,
                            **model_settings(args))

    def run(self, options: BenchOptions, args: argparse.Namespace) -> dict:
        """Run the benchmark; its summary."""
        raise NotImplementedError

    def kept(self, args: argparse.Namespace) -> str:
        """Where the episodes finished before an interruption are."""
        return f'the episodes finished so far are in {args.out}/{EPISODES}'

    def show(self, summary: dict, args: argparse.Namespace) -> None:
        """What the finished run prints: its summary as JSON."""
        print(json.dumps(summary))

    def main(self, argv: Sequence[str] | None = None) -> int:
        args = self.build_parser().parse_args(argv)
        try:
            options = self.options(args)
        except ValueError as error:
            print(f'{self.prog}: error: {error}', file=sys.stderr)
            return 2
        for signum in (signal.SIGINT, signal.SIGTERM):
            signal.signal(signum, raise_interrupted)
        try:
            with model_endpoint(options, self.domain or self.name) as options:
                summary = self.run(options, args)
        except Interrupted as interrupted:
            print(f'interrupted ({interrupted}): {self.kept(args)}', file=sys.stderr)
            return interrupted.exit_code
        except LLMError as error:  # the local model could not start: one line saying why and what to do
            print(f'{self.prog}: error: {one_line(str(error))}', file=sys.stderr)
            return 2
        self.show(summary, args)
        return 0


@dataclasses.dataclass
class TemplateBench(GraphBench):
    """A benchmark of instruction templates run with cap_bench.episode_runs (the whiteboard's, the mobile
    kitchen's): --templates chooses them; `run_templates(options, templates, resume)` runs them."""
    templates: Sequence[str] = ()
    run_templates: Callable[[BenchOptions, Sequence[str], bool], dict] | None = None
    # The domain's development set (`--set dev`: its commands, --trials times), where it has one.
    run_devset: Callable[[BenchOptions, bool], dict] | None = None

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        parser.add_argument('--templates', default=','.join(self.templates),
                            help=f'comma-separated [{",".join(self.templates)}]')
        if self.run_devset is not None:
            parser.add_argument('--set', choices=('benchmark', 'dev'), default='benchmark',
                                help='benchmark: the templates\' episodes; dev: the development set the prompts are '
                                     'tuned on (--templates does not apply) [benchmark]')

    def options(self, args: argparse.Namespace) -> BenchOptions:
        unknown = [t for t in comma_separated(args.templates) if t not in self.templates]
        if unknown:
            raise ValueError(f'unknown templates {unknown}')
        if args.trials < 1:
            raise ValueError('--trials must be at least 1')
        return super().options(args)

    def run(self, options: BenchOptions, args: argparse.Namespace) -> dict:
        if getattr(args, 'set', 'benchmark') == 'dev':
            return self.run_devset(options, args.resume)
        return self.run_templates(options, comma_separated(args.templates), args.resume)

    def show(self, summary: dict, args: argparse.Namespace) -> None:
        print(json.dumps({key: summary[key] for key in ('overall', 'rows', 'wall_seconds')}))
