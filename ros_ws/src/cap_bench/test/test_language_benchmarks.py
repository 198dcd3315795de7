"""The language-side benchmarks end to end: the oracle's answers over a real HTTP server on 127.0.0.1, the
project's engine, the sandbox process (jailed), the test programs, the host's verdicts, the reports.

Each run here is a whole `run()` as `cap bench <name>` does it: what a user would see is the report and the per-item
records, so the tests read those."""
from __future__ import annotations

import functools
import json
import os
import subprocess
import sys

import pytest

from cap_bench.codegen import bench as codegen
from cap_bench.codegen.problems import CATEGORIES, WRONG_SOURCES, problem
from cap_bench.humaneval import bench as humaneval
from cap_bench.language import session
from cap_bench.language.policy import PolicyOptions, open_client
from cap_bench.language.runner import ITEMS_FILE
from cap_bench.reasoning import bench as reasoning
from cap_bench.reasoning.questions import QUESTIONS
from cap_lmp.isolated_engine import IsolatedEngine
from cap_lmp.sandbox import SandboxLimits
from cap_lmp.testing.syscall_audit import SyscallAudit

ORACLE = PolicyOptions('oracle')


def _records(out) -> list[dict]:
    return [json.loads(line) for line in (out / ITEMS_FILE).read_text().splitlines()]


def _all_row(summary, variant):
    return next(row for row in summary['rows'] if row['variant'] == variant and row['group'] == 'all')


def test_codegen_oracle_passes_every_problem_in_the_four_variants(tmp_path):
    summary = codegen.run(ORACLE, tmp_path, jobs=2, show_progress=False)
    failures = [(r['key'], r['reason']) for r in _records(tmp_path) if not r['passed']]
    assert failures == []
    for prompt in codegen.PROMPT_STYLES:
        for generation in codegen.GENERATIONS:
            row = _all_row(summary, codegen.variant_name(prompt, generation))
            assert (row['passed'], row['items']) == (37, 37)
    by_category = {row['group']: row['items'] for row in summary['rows'] if row['variant'].startswith('flat prompt, '
                                                                                                         'flat')}
    assert by_category == {**CATEGORIES, 'all': 37}
    report = (tmp_path / 'report.md').read_text()
    assert 'Policy: oracle' in report and '81.0' in report and '95.0' in report
    assert summary['policy'].startswith('oracle')
    record = _records(tmp_path)[0]
    assert record['calls'][0]['prompt'].endswith(f"# define function: {record['signature']}.\n")
    assert (tmp_path / 'report.png').stat().st_size > 1000



def test_the_jail_refuses_nothing_the_language_benchmarks_run(tmp_path, monkeypatch):
    """The three benchmarks' sandbox processes with the jail's filter audited (cap_lmp.testing.syscall_audit): every
    call it would refuse is let through and counted. Each item passes, and the filter refused nothing."""
    with SyscallAudit('refusals') as audit:
        monkeypatch.setattr(session, 'IsolatedEngine',
                            functools.partial(IsolatedEngine, child_command=audit.child_command))
        summaries = [codegen.run(ORACLE, tmp_path / 'codegen', prompts=('flat',), show_progress=False),
                     humaneval.run(ORACLE, tmp_path / 'humaneval', limit=20, show_progress=False),
                     reasoning.run(ORACLE, tmp_path / 'reasoning', show_progress=False)]
    rows = [(row['variant'], row['passed'], row['items']) for summary in summaries for row in summary['rows']
            if row['group'] == 'all']
    assert len(rows) == 7 and all(passed == items > 0 for _, passed, items in rows), rows
    assert audit.errors == []
    assert dict(audit.calls) == {}

def test_codegen_catches_a_wrong_solution_in_every_category(tmp_path):
    wrong = {name: source for name, source in WRONG_SOURCES.values()}
    assert {problem(name).category for name in wrong} == set(CATEGORIES)
    codegen.run(ORACLE, tmp_path, prompts=('flat',), generations=('flat',), show_progress=False,
                answers=codegen.oracle_answers(wrong))
    failed = {r['problem']: r['reason'] for r in _records(tmp_path) if not r['passed']}
    assert set(failed) == set(wrong)
    assert all(reason.startswith('case ') for reason in failed.values())  # judged on outputs, not a crash


def test_hierarchical_generation_defines_the_helper_an_answer_calls(tmp_path):
    target = problem(WRONG_SOURCES['numpy'][0])
    arguments = target.signature.split('(', 1)[1].rstrip(')')
    answer = f'def {target.name}({arguments}):\n    return solve_it_for_me({arguments})\n'
    helper = codegen.reference_source(target).replace(f'def {target.name}(', 'def solve_it_for_me(', 1)
    helper_query = f'# define function: solve_it_for_me({arguments}).\n'
    answers = codegen.oracle_answers({target.name: answer}) + [(helper_query, helper)]
    codegen.run(ORACLE, tmp_path, prompts=('hierarchical',), show_progress=False, answers=answers)
    records = {(r['generation'], r['problem']): r for r in _records(tmp_path)}
    hierarchical, flat = records[('hierarchical', target.name)], records[('flat', target.name)]
    assert hierarchical['passed'], hierarchical['reason']
    assert hierarchical['generated_functions'] == ['solve_it_for_me']
    assert [call['query'] for call in hierarchical['calls']][-1] == f'define function: solve_it_for_me({arguments})'
    assert not flat['passed'] and 'solve_it_for_me' in flat['reason'] and 'not defined' in flat['reason']


def test_a_run_resumes_where_it_stopped(tmp_path):
    codegen.run(ORACLE, tmp_path, prompts=('flat',), generations=('flat',), limit=3, show_progress=False)
    first = _records(tmp_path)
    assert len(first) == 3
    summary = codegen.run(ORACLE, tmp_path, prompts=('flat',), generations=('flat',), resume=True,
                          show_progress=False)
    records = _records(tmp_path)
    assert len(records) == 37 == summary['items'] and records[:3] == first  # the first three were not run again
    assert _all_row(summary, codegen.variant_name('flat', 'flat'))['passed'] == 37


def test_humaneval_canonical_solutions_pass_in_the_sandbox_and_wrong_ones_fail(tmp_path):
    ids = list(humaneval.problems())
    assert len(ids) == 164
    wrong = {task_id: '    return None\n' for task_id in ids[:5]}
    summary = humaneval.run(ORACLE, tmp_path, generations=('flat',), jobs=2, limit=40, show_progress=False,
                            answers=humaneval.oracle_answers(wrong))
    failed = {r['task_id']: r['reason'] for r in _records(tmp_path) if not r['passed']}
    assert set(failed) == set(wrong)
    assert all('the test failed' in reason for reason in failed.values())
    row = _all_row(summary, 'flat')
    assert (row['passed'], row['items'], row['metric']) == (35, 40, 'greedy')
    report = (tmp_path / 'report.md').read_text()
    assert 'Policy: oracle' in report and '45.7' in report and 'import' in report  # the harness's policy is said


@pytest.mark.slow
def test_humaneval_oracle_passes_all_164_flat_and_hierarchical(tmp_path):
    summary = humaneval.run(ORACLE, tmp_path, jobs=2, show_progress=False)
    failures = [(r['key'], r['reason']) for r in _records(tmp_path) if not r['passed']]
    assert failures == []
    assert [(_all_row(summary, g)['passed'], _all_row(summary, g)['items']) for g in humaneval.GENERATIONS] == [
        (164, 164), (164, 164)]


def test_humaneval_hierarchical_generation_defines_a_called_helper(tmp_path):
    first = list(humaneval.problems())[0]  # has_close_elements(numbers, threshold)
    completion = '    return any_two_closer(numbers, threshold)\n'
    helper = ('def any_two_closer(numbers, threshold):\n    ordered = sorted(numbers)\n'
              '    return any(b - a < threshold for a, b in zip(ordered, ordered[1:]))\n')
    answers = humaneval.oracle_answers({first: completion}) + [
        ('# define function: any_two_closer(numbers, threshold).\n', helper)]
    humaneval.run(ORACLE, tmp_path, limit=1, show_progress=False, answers=answers)
    records = {r['generation']: r for r in _records(tmp_path)}
    assert records['hierarchical']['passed'], records['hierarchical']['reason']
    assert records['hierarchical']['generated_functions'] == ['any_two_closer']
    assert not records['flat']['passed'] and 'any_two_closer' in records['flat']['reason']


def test_humaneval_pass_at_k_from_samples(tmp_path):
    ids = list(humaneval.problems())[:4]
    summary = humaneval.run(ORACLE, tmp_path, generations=('hierarchical',), samples=2, temperature=0.8, limit=4,
                            show_progress=False, answers=humaneval.oracle_answers({ids[0]: '    return None\n'}))
    row = next(r for r in summary['rows'] if r['metric'] == 'pass@1')
    assert row['items'] == 8 and row['passed'] == 6 and row['percent'] == pytest.approx(75.0) and row['paper'] == 39.8
    records = [{'task_id': 'a', 'passed': p} for p in (True, False, False, False)]
    assert humaneval.pass_at_k(records, 1) == pytest.approx(25.0)
    assert humaneval.pass_at_k(records, 2) == pytest.approx(50.0)  # 1 - C(3,2)/C(4,2)


def test_reasoning_oracle_answers_every_question_three_ways_and_wrong_answers_fail(tmp_path):
    first_object = next(q for q in QUESTIONS if q.kind == 'object')
    first_position = next(q for q in QUESTIONS if q.kind == 'position')
    other = next(name for name in first_object.objects if name != first_object.answer)
    x, y = first_position.answer
    overrides = {('code', first_object.id): f'ret_val = {other!r}',
                 ('vanilla', first_position.id): f'({x + 0.02:.3f}, {y:.3f})',
                 ('cot', first_object.id): f'It is the {other}.\nSo the answer is {other}.'}
    summary = reasoning.run(ORACLE, tmp_path, jobs=2, show_progress=False,
                            answers=reasoning.oracle_answers(overrides))
    failed = {(r['style'], r['question']) for r in _records(tmp_path) if not r['passed']}
    assert failed == {('code', first_object.id), ('vanilla', first_position.id), ('cot', first_object.id)}
    for style in ('code', 'vanilla', 'cot'):
        row = _all_row(summary, style)
        assert row['items'] == 51 and row['passed'] == 50
    assert 'Policy: oracle' in (tmp_path / 'report.md').read_text()


def _cap(*args, env=None):
    return subprocess.run([sys.executable, '-m', 'cap_bringup.cli', *args], capture_output=True, text=True,
                          timeout=300, env={**os.environ, **(env or {})})


def test_the_commands_print_their_report_and_fail_in_one_line_without_a_model(tmp_path):
    done = _cap('bench', 'codegen', '--prompts', 'flat', '--generation', 'hierarchical', '--limit', '2',
                '--no-progress', '--out', str(tmp_path / 'codegen'))
    assert done.returncode == 0, done.stderr
    assert 'policy: oracle' in done.stdout and '2/2' in done.stdout
    assert (tmp_path / 'codegen' / 'report.md').exists()
    no_model = _cap('bench', 'reasoning', '--policy', 'llm', '--no-progress', '--out', str(tmp_path / 'r'),
                    env={'CAP_LLM_MODEL': '', 'CAP_LLM_BASE_URL': 'http://127.0.0.1:9/v1'})
    assert no_model.returncode == 1
    assert no_model.stderr.strip().count('\n') == 0 and 'CAP_LLM_MODEL' in no_model.stderr
    wrong = _cap('bench', 'humaneval', '--generation', 'sideways')
    assert wrong.returncode == 2 and "not 'sideways'" in wrong.stderr


# ------------------------------------------------------------------------------------------ answers that cheat
PREDICT_THE_TEST = '''    value = upcoming[0]
    upcoming.clear()
    upcoming.append(draw())
    return value
upcoming = []
shadow = random.Random(7)
alphabet = string.ascii_lowercase
draw = lambda: ''.join(shadow.choice(alphabet) for i in range(shadow.randint(10, 20)))
random.seed(7)
upcoming.append(draw())
'''
HUMANEVAL_CHEATS = {
    # a walrus in a lambda's default rebinds a builtin the test's comparison uses
    'HumanEval/4': '    return 12345.0\nkeep = lambda v=(abs := (lambda x: 0)): v\n',
    # ... or the prompt's helper the test calls
    'HumanEval/32': '    return 12345.0\nkeep = lambda v=(poly := (lambda xs, x: 0)): v\n',
    # predicts the test's random inputs from the random generator it shares (decode_cyclic without decoding)
    'HumanEval/38': PREDICT_THE_TEST,
    # reports to the host from its own code
    'HumanEval/2': '    return number % 1.0\nreport(0.5)\n',
}


def _evaluate(evaluator_of, answers, keys):
    with open_client(ORACLE, answers) as client:
        evaluator = evaluator_of(client)
        try:
            return {key: evaluator.evaluate(key) for key in keys}
        finally:
            evaluator.close()


def test_humaneval_completions_that_tamper_with_the_test_fail():
    keys = [f'flat/{task}/0' for task in HUMANEVAL_CHEATS]
    records = _evaluate(lambda client: humaneval.HumanEvalEvaluator(client, SandboxLimits(30), 'required', 0.0),
                        humaneval.oracle_answers(HUMANEVAL_CHEATS), keys)
    outcomes = {key.split('/', 1)[1][:-2]: (r['passed'], r['reason']) for key, r in records.items()}
    assert not any(passed for passed, _ in outcomes.values()), outcomes
    assert "rebinds 'abs'" in outcomes['HumanEval/4'][1] and "'poly'" in outcomes['HumanEval/32'][1]
    assert 'the test failed' in outcomes['HumanEval/38'][1]
    assert 'report() belongs to the test program' in outcomes['HumanEval/2'][1]


def test_codegen_answers_that_flood_or_steer_the_host_fail():
    robot = problem(WRONG_SOURCES['robot_api'][0])
    numeric = problem(WRONG_SOURCES['numpy'][0])
    numeric_arguments = numeric.signature.split('(', 1)[1].rstrip(')')
    lines = codegen.reference_source(robot).splitlines()
    cheats = {
        robot.name: '\n'.join([lines[0], '    end_case()', *lines[1:]]) + '\n',  # ends the case early: its actions
        numeric.name: (f'def {numeric.name}({numeric_arguments}):\n    for i in range(200):\n'
                       '        report(i)\n    return 0\n'),
    }
    records = _evaluate(lambda client: codegen.CodegenEvaluator(client, SandboxLimits(10), 'required'),
                        codegen.oracle_answers(cheats), [f'flat/flat/{name}' for name in cheats])
    reasons = {key.rsplit('/', 1)[1]: r['reason'] for key, r in records.items() if not r['passed']}
    assert set(reasons) == set(cheats)
    assert 'end_case() belongs to the test program' in reasons[robot.name]
    assert 'more than 100 reports' in reasons[numeric.name]


def test_a_huge_text_answer_is_judged_in_bounded_time_and_fails():
    position = next(q for q in QUESTIONS if q.kind == 'position')
    records = _evaluate(lambda client: reasoning.ReasoningEvaluator(client, SandboxLimits(10), 'required'),
                        reasoning.oracle_answers({('code', position.id): "ret_val = '1' * 200000\n"}),
                        [f'code/{position.id}'])
    record = records[f'code/{position.id}']
    assert not record['passed'] and record['answer'] is None


def test_a_resumed_run_keeps_its_settings(tmp_path):
    codegen.run(ORACLE, tmp_path, prompts=('flat',), generations=('flat',), limit=1, show_progress=False)
    with pytest.raises(ValueError, match='other settings'):
        codegen.run(ORACLE, tmp_path, prompts=('flat',), generations=('flat',), resume=True, time_limit_s=3.0,
                    show_progress=False)
