"""`cap bench codegen`: robotics code generation, flat versus hierarchical, as in the paper's RoboCodeGen table.

Each problem is a function signature (`# define function: i, j = get_farthest_pair(points).`); the model answers
with a `def` through the project's engine, its code runs in the sandbox process, and a test program written here
calls the function on seeded inputs there and reports the outputs; the host compares them with the reference
solution's outputs (computed on the host, where the program cannot reach) by the problem's equivalence rule.

The paper's 2×2: the prompt is flat (every example self-contained) or hierarchical (examples call helpers they do
not define), and generation is flat (a call of an undefined function fails the problem) or hierarchical (the
engine's function generation asks the model to define it, depth first, as for a robot command).
"""
from __future__ import annotations

import argparse
import ast
import pathlib
import time
from typing import Any, Callable, Mapping, Sequence

from cap_bench.codegen.compare import equivalent
from cap_bench.codegen.literals import to_source
from cap_bench.codegen.problems import CATEGORIES, PROBLEMS, Problem, cases, problem, reference_output, \
    reference_source
from cap_bench.codegen.world import CodegenWorld
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
PROMPT_STYLES = ('flat', 'hierarchical')
GENERATIONS = ('flat', 'hierarchical')
CODEGEN_LMP, FGEN_LMP = 'codegen', 'fgen'
STOP = ('\n#', '\nif __name__', '\nprint(')
# The paper's RoboCodeGen figures (code-davinci-002): flat 81 %, hierarchical 95 % of 37 problems.
PAPER = {('flat', 'flat'): 81.0, ('hierarchical', 'hierarchical'): 95.0}
CASE_SEED = 0  # the seeded inputs of every problem


def variant_name(prompt: str, generation: str) -> str:
    return f'{prompt} prompt, {generation} generation'


def query(item: Problem) -> str:
    return f'define function: {item.signature}'


def build_engine(api: Mapping[str, Callable[..., Any]], client: LLMClient, limits: SandboxLimits | None = None, *,
                 prompt: str = 'hierarchical', hierarchical: bool = True, **engine_options: Any) -> Engine:
    """The session's engine in the sandbox process: the code-writing LMP (its definitions stay in the session,
    for the test program), the function-generation LMP when generation is hierarchical, and the harness LMP."""
    text = load_prompt(PROMPTS_DIR, prompt)
    lmps = [LMPConfig(CODEGEN_LMP, text, stop=STOP, maintain_session=True),
            LMPConfig(FGEN_LMP, text, stop=STOP), harness_lmp()]
    return Engine(lmps, client, dict(api), limits=limits, default_lmp=CODEGEN_LMP,
                  fgen_lmp=FGEN_LMP if hierarchical else None, **engine_options)


def test_program(item: Problem, inputs: Sequence[Any]) -> str:
    """Calls the model's function on every case and reports each output (geometry as WKT text, since only
    JSON-like values cross to the host); robot-API problems first load the case's scene and then report the
    robot's actions too."""
    lines = []
    for index, case in enumerate(inputs):
        call = f'{item.name}(*{to_source(tuple(case.args))})'
        if item.compare == 'geometry':
            call = f'({call}).wkt'
        if item.category == 'robot_api':
            lines += [f'begin_case({index})', f'report({call})', 'end_case()']
        else:
            lines.append(f'report({call})')
    return '\n'.join(lines) + '\n'


def defines(code: str, name: str) -> bool:
    """Does the model's code (checked by the sandbox already) define `name` at its top level?"""
    try:
        tree = ast.parse(code)
    except (SyntaxError, ValueError, RecursionError, MemoryError):
        return False
    return any(isinstance(node, ast.FunctionDef) and node.name == name for node in tree.body)


class CodegenEvaluator:
    """One job: a sandbox session per variant (started when first needed), the robot-API world both the sandbox
    and the reference use."""

    def __init__(self, client: LLMClient, limits: SandboxLimits, jail: str) -> None:
        self.client, self.limits, self.jail = client, limits, jail
        self.world = CodegenWorld()
        self.reference_world = CodegenWorld()
        self._cases: list[Any] = []
        self._actions: list[list[Any]] = []
        self._case: int | None = None  # the case begun and not yet ended
        self.sessions: dict[tuple[str, str], EvaluationSession] = {}

    def _testing(self) -> bool:
        return any(session.testing for session in self.sessions.values())  # one item at a time per job

    def _begin_case(self, index: int) -> None:
        # Only the test program, once per case and in order: a model's function that calls these fails the test.
        if not self._testing() or self._case is not None or index != len(self._actions):
            raise ValueError('begin_case() belongs to the test program')
        self._case = index
        self.world.begin_case(self._cases[index].scene)

    def _end_case(self) -> None:
        if not self._testing() or self._case is None:
            raise ValueError('end_case() belongs to the test program')
        self._actions.append(list(self.world.actions))
        self._case = None

    def session(self, prompt: str, generation: str) -> EvaluationSession:
        key = (prompt, generation)
        if key not in self.sessions:
            api = {**self.world.api(), 'begin_case': self._begin_case, 'end_case': self._end_case}
            self.sessions[key] = EvaluationSession(
                build_engine, self.client, api=api, limits=self.limits, jail=self.jail,
                engine_options={'prompt': prompt, 'hierarchical': generation == 'hierarchical'})
        return self.sessions[key]

    def evaluate(self, key: str) -> dict[str, Any]:
        prompt, generation, name = key.split('/')
        item = problem(name)
        session = self.session(prompt, generation)
        session.reset()
        started = time.monotonic()
        record: dict[str, Any] = {'benchmark': 'codegen', 'variant': variant_name(prompt, generation),
                                  'prompt_style': prompt, 'generation': generation, 'problem': name,
                                  'category': item.category, 'signature': item.signature}
        answer = session.ask(query(item))
        record.update(code=answer.code, generated_functions=answer.generated_functions)
        passed, reason = False, ''
        if not answer.success:
            reason = f'the answer did not run: {answer.message}'
        elif not defines(answer.code, name):
            reason = f'the answer does not define {name}()'
        else:
            passed, reason = self._test(session, item)
        calls = session.client.take_calls()
        record.update(passed=passed, reason=reason, calls=[call.as_dict() for call in calls],
                      prompt_tokens=sum(c.prompt_tokens for c in calls),
                      completion_tokens=sum(c.completion_tokens for c in calls),
                      model_s=round(sum(c.latency_s for c in calls), 4),
                      wall_s=round(time.monotonic() - started, 4))
        return record

    def _test(self, session: EvaluationSession, item: Problem) -> tuple[bool, str]:
        self._cases, self._actions, self._case = cases(item, CASE_SEED), [], None
        result, outputs = session.run_program(test_program(item, self._cases))
        if not result.success:
            return False, f'the test program failed: {result.message}'
        if len(outputs) != len(self._cases):
            return False, f'{len(outputs)} outputs for {len(self._cases)} cases'
        if item.category == 'robot_api' and len(self._actions) != len(self._cases):
            return False, f'{len(self._actions)} action logs for {len(self._cases)} cases'
        for index, (case, output) in enumerate(zip(self._cases, outputs)):
            expected = reference_output(item, case, self.reference_world)
            got = {'return': output, 'actions': self._actions[index]} if item.category == 'robot_api' else output
            same, why = equivalent(item.compare, expected, got)
            if not same:
                return False, f'case {index}: {why}'
        return True, ''

    def close(self) -> None:
        for session in self.sessions.values():
            session.close()


def item_keys(prompts: Sequence[str], generations: Sequence[str], limit: int = 0) -> list[str]:
    names = [item.name for item in PROBLEMS][:limit or None]
    return [f'{prompt}/{generation}/{name}' for prompt in prompts for generation in generations for name in names]


def oracle_answers(sources: Mapping[str, str] | None = None) -> list[tuple[str, str]]:
    """(prompt suffix, answer): every problem's reference solution, or `sources[name]` instead."""
    sources = sources or {}
    return [(f'# {query(item)}.\n', sources.get(item.name, reference_source(item))) for item in PROBLEMS]


def summarise(records: Sequence[Mapping[str, Any]], prompts: Sequence[str],
              generations: Sequence[str]) -> list[ReportRow]:
    rows = []
    for prompt in prompts:
        for generation in generations:
            variant = variant_name(prompt, generation)
            mine = [r for r in records if r['variant'] == variant]
            for category in CATEGORIES:
                group = [r for r in mine if r['category'] == category]
                if group:
                    rows.append(ReportRow(variant, category, len(group), sum(r['passed'] for r in group)))
            if mine:
                rows.append(ReportRow(variant, 'all', len(mine), sum(r['passed'] for r in mine),
                                      PAPER.get((prompt, generation))))
    return rows


def run(options: PolicyOptions, out: pathlib.Path, *, prompts: Sequence[str] = PROMPT_STYLES,
        generations: Sequence[str] = GENERATIONS, jobs: int = 1, resume: bool = False, limit: int = 0,
        time_limit_s: float = 10.0, jail: str = 'required', show_progress: bool = True,
        answers: Sequence[tuple[str, str]] | None = None) -> dict[str, Any]:
    """Run (or resume) the benchmark; write the report; return report.json's content. `answers` replaces the
    oracle's (prompt suffix, answer) pairs."""
    keys = item_keys(prompts, generations, limit)
    limits = SandboxLimits(time_limit_s=time_limit_s)
    started = time.monotonic()
    records, policy = run_with_policy('codegen', options, oracle_answers() if answers is None else answers, keys,
                                      lambda client: CodegenEvaluator(client, limits, jail), out, jobs=jobs,
                                      resume=resume, show_progress=show_progress,
                                      settings={'time_limit_s': time_limit_s})
    rows = summarise(records, prompts, generations)
    notes = ['Problems written here in the paper\'s categories and counts (16 NumPy, 4 controls, 10 Shapely, '
             '7 robot API); paper figures: Code as Policies, RoboCodeGen, code-davinci-002.',
             'A problem passes when the model\'s function gives the reference\'s outputs on every seeded case '
             '(np.allclose, equality or geometric equality), judged on the host.']
    return write_report(out, f'Robot code generation ({len(PROBLEMS)} problems)', policy, rows, notes,
                        {'wall_s': round(time.monotonic() - started, 2), 'items': len(records)}, records)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog='cap bench codegen', description=__doc__.split('\n\n')[0])
    add_common_arguments(parser, out='output/bench-codegen', time_limit_s=10.0)
    parser.add_argument('--prompts', default=','.join(PROMPT_STYLES), help='flat, hierarchical or both [both]')
    parser.add_argument('--generation', default=','.join(GENERATIONS), help='flat, hierarchical or both [both]')
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    prompts = choose(args.prompts, PROMPT_STYLES, '--prompts', 'cap bench codegen')
    generations = choose(args.generation, GENERATIONS, '--generation', 'cap bench codegen')
    return run_main(lambda: run(policy_of(args), pathlib.Path(args.out), prompts=prompts, generations=generations,
                                jobs=args.jobs, resume=args.resume, limit=args.limit, time_limit_s=args.time_limit,
                                jail=args.jail, show_progress=not args.no_progress), args.out, args)
