"""`cap bench reasoning`: spatial-geometric reasoning with code versus natural language, as in the paper.

Each of the 51 questions (28 object selections, 23 position selections, written here) is answered three ways by
the same model: as code through the project's engine (the program sets `ret_val` from `objects`; it runs in the
sandbox process and a test program hands `ret_val` to the host), as a vanilla language answer, and as a
chain-of-thought language answer whose last line is parsed. An object answer must name the right object; a
position answer must lie within 1 cm of the right point (the paper's rule).
"""
from __future__ import annotations

import argparse
import pathlib
import time
from typing import Any, Callable, Mapping, Sequence

from cap_bench.language.cli import add_common_arguments, choose, policy_of, run_main
from cap_bench.language.policy import PolicyOptions
from cap_bench.language.report import ReportRow, write_report
from cap_bench.language.runner import run_with_policy
from cap_bench.language.session import EvaluationSession, ModelCall, harness_lmp
from cap_bench.reasoning.answers import (LANGUAGE_STOP, code_query, context_line, judge, language_prompt,
                                         normalise_code_answer, parse_answer)
from cap_bench.reasoning.questions import KINDS, QUESTIONS, STYLES, Question, question
from cap_lmp.engine import Engine, LMPConfig
from cap_lmp.llm import CompletionRequest, LLMClient
from cap_lmp.prompts import load_prompt
from cap_lmp.sandbox import SandboxLimits

PROMPTS_DIR = pathlib.Path(__file__).with_name('prompts')
CODE_LMP = 'reasoning_code'
CODE_STOP = ('#', 'objects = {')
# The paper's figures (code-davinci-002), % correct over both sets.
PAPER = {'vanilla': 35.0, 'cot': 58.0, 'code': 98.0}
MAX_LANGUAGE_TOKENS = 384


def build_engine(api: Mapping[str, Callable[..., Any]], client: LLMClient, limits: SandboxLimits | None = None,
                 **engine_options: Any) -> Engine:
    """The session's engine in the sandbox process: the code LMP (its `ret_val` stays in the session for the
    test program; no function generation, as in the paper's comparison) and the harness LMP."""
    lmps = [LMPConfig(CODE_LMP, load_prompt(PROMPTS_DIR, 'code'), stop=CODE_STOP, maintain_session=True),
            harness_lmp()]
    return Engine(lmps, client, dict(api), limits=limits, default_lmp=CODE_LMP, fgen_lmp=None, **engine_options)


def language_request(item: Question, style: str) -> CompletionRequest:
    prompt = language_prompt(item, style, load_prompt(PROMPTS_DIR, style))
    return CompletionRequest(lmp=f'reasoning_{style}', prompt=prompt, query=item.question, stop=LANGUAGE_STOP,
                             max_tokens=MAX_LANGUAGE_TOKENS)


class ReasoningEvaluator:
    """One job: a sandbox session for the code answers (started when first needed), the client for the others."""

    def __init__(self, client: LLMClient, limits: SandboxLimits, jail: str) -> None:
        self.client, self.limits, self.jail = client, limits, jail
        self._session: EvaluationSession | None = None

    def session(self) -> EvaluationSession:
        if self._session is None:
            self._session = EvaluationSession(build_engine, self.client, limits=self.limits, jail=self.jail)
        return self._session

    def evaluate(self, key: str) -> dict[str, Any]:
        style, qid = key.split('/')
        item = question(qid)
        started = time.monotonic()
        if style == 'code':
            value, text, calls, problem = self._code_answer(item)
        else:
            value, text, calls, problem = self._language_answer(item, style)
        passed, reason = judge(item, value) if not problem else (False, problem)
        return {'benchmark': 'reasoning', 'variant': style, 'style': style, 'question': qid, 'kind': item.kind,
                'text': item.question, 'expected': item.answer, 'answer': value, 'answer_text': text,
                'passed': passed, 'reason': reason, 'calls': [call.as_dict() for call in calls],
                'prompt_tokens': sum(c.prompt_tokens for c in calls),
                'completion_tokens': sum(c.completion_tokens for c in calls),
                'model_s': round(sum(c.latency_s for c in calls), 4), 'wall_s': round(time.monotonic() - started, 4)}

    def _code_answer(self, item: Question) -> tuple[Any, str, list[ModelCall], str]:
        session = self.session()
        session.reset()
        answer = session.ask(code_query(item), context=context_line(item))
        if not answer.success:
            return None, answer.code, session.client.take_calls(), f'the code did not run: {answer.message}'
        result, reports = session.run_program('report(ret_val)\n')
        calls = session.client.take_calls()
        if not result.success or len(reports) != 1:
            return None, answer.code, calls, f'the code set no ret_val: {result.message}'
        return normalise_code_answer(item, reports[0]), answer.code, calls, ''

    def _language_answer(self, item: Question, style: str) -> tuple[Any, str, list[ModelCall], str]:
        request = language_request(item, style)
        started = time.monotonic()
        try:
            completion = self.client.complete(request)
        except Exception as error:  # the endpoint's failure is this item's, reported
            call = ModelCall(request.lmp, request.query, request.prompt, '', 0, 0, time.monotonic() - started,
                             f'{type(error).__name__}: {error}')
            return None, '', [call], f'the model gave no answer: {error}'
        call = ModelCall(request.lmp, request.query, request.prompt, completion.text, completion.prompt_tokens,
                         completion.completion_tokens, completion.latency_s or time.monotonic() - started)
        value = parse_answer(item, style, completion.text)
        return value, completion.text, [call], '' if value is not None else 'no answer could be read from the text'

    def close(self) -> None:
        if self._session is not None:
            self._session.close()


def item_keys(styles: Sequence[str], limit: int = 0) -> list[str]:
    chosen = [item for kind in KINDS for item in [q for q in QUESTIONS if q.kind == kind][:limit or None]]
    return [f'{style}/{item.id}' for style in styles for item in chosen]


def oracle_answers(overrides: Mapping[tuple[str, str], str] | None = None) -> list[tuple[str, str]]:
    """(prompt suffix, answer) of every question in every style; `overrides[(style, id)]` replaces one."""
    overrides = overrides or {}
    answers = []
    for item in QUESTIONS:
        reference = {'code': item.reference_code, 'vanilla': item.reference_vanilla, 'cot': item.reference_cot}
        answers.append((f'{context_line(item)}\n# {code_query(item)}.\n',
                        overrides.get(('code', item.id), reference['code'])))
        for style in ('vanilla', 'cot'):
            answers.append((language_request(item, style).prompt, overrides.get((style, item.id), reference[style])))
    return answers


def summarise(records: Sequence[Mapping[str, Any]], styles: Sequence[str]) -> list[ReportRow]:
    rows = []
    for style in styles:
        mine = [r for r in records if r['style'] == style]
        for kind in KINDS:
            group = [r for r in mine if r['kind'] == kind]
            if group:
                rows.append(ReportRow(style, kind, len(group), sum(r['passed'] for r in group)))
        if mine:
            rows.append(ReportRow(style, 'all', len(mine), sum(r['passed'] for r in mine), PAPER[style]))
    return rows


def run(options: PolicyOptions, out: pathlib.Path, *, styles: Sequence[str] = STYLES, jobs: int = 1,
        resume: bool = False, limit: int = 0, time_limit_s: float = 10.0, jail: str = 'required',
        show_progress: bool = True, answers: Sequence[tuple[str, str]] | None = None) -> dict[str, Any]:
    """Run (or resume) the benchmark; write the report; return report.json's content. `answers` replaces the
    oracle's (prompt suffix, answer) pairs."""
    keys = item_keys(styles, limit)
    limits = SandboxLimits(time_limit_s=time_limit_s)
    started = time.monotonic()
    records, policy = run_with_policy('reasoning', options, oracle_answers() if answers is None else answers, keys,
                                      lambda client: ReasoningEvaluator(client, limits, jail), out, jobs=jobs,
                                      resume=resume, show_progress=show_progress,
                                      settings={'time_limit_s': time_limit_s})
    notes = ['Questions written here in the paper\'s two sets; positions correct within 1 cm. Paper figures: '
             'Code as Policies, code-davinci-002 (vanilla 35 %, chain of thought 58 %, code 98 %).']
    return write_report(out, f'Spatial-geometric reasoning ({len(QUESTIONS)} questions): code vs. language',
                        policy, summarise(records, styles), notes,
                        {'wall_s': round(time.monotonic() - started, 2), 'items': len(records)}, records)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog='cap bench reasoning', description=__doc__.split('\n\n')[0])
    add_common_arguments(parser, out='output/bench-reasoning', time_limit_s=10.0)
    parser.add_argument('--styles', default=','.join(STYLES), help='code, vanilla, cot [all three]')
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    styles = choose(args.styles, STYLES, '--styles', 'cap bench reasoning')
    return run_main(lambda: run(policy_of(args), pathlib.Path(args.out), styles=styles, jobs=args.jobs,
                                resume=args.resume, limit=args.limit, time_limit_s=args.time_limit, jail=args.jail,
                                show_progress=not args.no_progress), args.out, args)
