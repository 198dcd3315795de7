"""HumanEval in the sandbox: every reference solution passes its test there, wrong answers fail, and the harness
provides what the programs need and nothing that reaches a module, the file system or unbounded work."""
import ast
import random
import types

import pytest

from cap_bench.humaneval.policy import (ALLOWED_MODULES, EVALUATOR_NAME, HARNESS_NAMES, POLICY_TEXT, PolicyRefusal,
                                        adapt, evaluate_arithmetic, harness_names, rebinding_problem)
from cap_bench.humaneval.problems import (STOP, candidate_program, load_problems, oracle_completion,
                                          test_program)
from cap_lmp.errors import ResourceLimitError
from cap_lmp.sandbox import Sandbox, SandboxLimits
from cap_lmp.sandbox.names import SafeNamespace

PROBLEMS = load_problems()
BY_ID = {problem.task_id: problem for problem in PROBLEMS}
# Reference solutions that take seconds in the in-process sandbox (its checks cost some 100x on tight loops):
# HumanEval/75 about 41 s, /147 and /36 about 3 s. The fast test leaves them to the full run in the sandbox process
# (test_language_benchmarks.py).
SLOW_IN_SANDBOX = frozenset({'HumanEval/75', 'HumanEval/147', 'HumanEval/36'})
FAST = [problem.task_id for problem in PROBLEMS if problem.task_id not in SLOW_IN_SANDBOX]


def run(sandbox, problem, completion):
    """Candidate then test in one scope, as the harness runs them; raises what the program raised."""
    scope = sandbox.new_scope(harness_names())
    sandbox.execute(sandbox.compile(candidate_program(problem, completion), 'candidate'), scope)
    sandbox.execute(sandbox.compile(test_program(problem), 'test'), scope)


def run_in_sandbox(source):
    """The value the adapted program leaves in `out`."""
    sandbox = Sandbox(SandboxLimits(time_limit_s=10))
    scope = sandbox.new_scope(harness_names())
    sandbox.execute(sandbox.compile(adapt(source)), scope)
    return scope['out']


@pytest.fixture(scope='module')
def sandbox():
    return Sandbox(SandboxLimits(time_limit_s=10))


# ------------------------------------------------------------------------------------------------ problems
def test_the_164_problems_load_in_task_order():
    assert [p.task_id for p in PROBLEMS] == [f'HumanEval/{i}' for i in range(164)]
    for problem in PROBLEMS:
        defined = [node.name for node in ast.parse(problem.prompt).body if isinstance(node, ast.FunctionDef)]
        assert defined[-1] == problem.entry_point  # the completion continues the entry point's body
        assert oracle_completion(problem) == problem.canonical_solution


def test_helpers_of_the_prompt_stay_in_the_candidate():
    program = candidate_program(BY_ID['HumanEval/38'], oracle_completion(BY_ID['HumanEval/38']))
    assert 'def encode_cyclic' in program and 'def decode_cyclic' in program


def test_stop_sequences_leave_every_reference_solution_whole():
    assert all(stop not in problem.canonical_solution for problem in PROBLEMS for stop in STOP)


def test_every_reference_program_passes_the_sandbox_check():
    sandbox = Sandbox()
    for problem in PROBLEMS:
        sandbox.check(candidate_program(problem, oracle_completion(problem)))
        sandbox.check(test_program(problem))


@pytest.mark.parametrize('task_id', FAST)
def test_reference_solution_passes_its_test_in_the_sandbox(sandbox, task_id):
    run(sandbox, BY_ID[task_id], oracle_completion(BY_ID[task_id]))


def test_a_wrong_completion_fails_nearly_everywhere(sandbox):
    failed = 0
    for problem in PROBLEMS:
        try:
            run(sandbox, problem, '    return None\n')
        except Exception:  # a failed assertion mostly; a TypeError where the test computes with the answer
            failed += 1
    assert failed >= 150


def test_tests_draw_the_same_inputs_in_every_run():
    source = 'import random\nout = [random.randint(0, 10 ** 6) for _ in range(5)] + [random.choice("abcdef")]\n'
    assert run_in_sandbox(source) == run_in_sandbox(source)
    # Random(seed) draws what Python's generator of that seed draws (HumanEval/32 seeds its own).
    expected = random.Random(42)
    assert run_in_sandbox('import random\nr = random.Random(42)\nout = [r.randint(1, 4) for _ in range(9)]\n') == \
        [expected.randint(1, 4) for _ in range(9)]


# ------------------------------------------------------------------------------------------------ adapt
@pytest.mark.parametrize('source, module', [('import os\n', 'os'), ('import subprocess\n', 'subprocess'),
                                            ('from os import path\n', 'os'), ('import math, sys\n', 'sys'),
                                            ('def f():\n    import itertools\n', 'itertools')])
def test_imports_of_modules_not_provided_are_refused(source, module):
    with pytest.raises(PolicyRefusal, match=f"importing '{module}' is not allowed: "):
        adapt(source)


def test_members_not_provided_relative_imports_and_eval_with_scopes_are_refused():
    with pytest.raises(PolicyRefusal, match='math.system is not provided'):
        adapt('from math import system\n')
    with pytest.raises(PolicyRefusal, match='relative imports'):
        adapt('from . import helpers\n')
    with pytest.raises(PolicyRefusal, match='one arithmetic expression only'):
        adapt('x = eval("1", {})\n')


def test_a_syntax_error_is_refused_with_its_line():
    with pytest.raises(PolicyRefusal, match=r'syntax error.*\(line 2\)') as refusal:
        adapt('def f(x):\n    return (x\n')
    assert refusal.value.line == 2


def test_adapted_programs_use_the_harness_names():
    source = ('import math\nimport collections as c\nfrom typing import List\nfrom math import sqrt as root, floor\n'
              'def f(xs: List[int]) -> int:\n    import re\n    try:\n        return eval("1 + 2")\n'
              '    except:\n        return 0\n')
    adapted = adapt(source)
    Sandbox().check(adapted)
    assert 'import' not in adapted and 'except Exception:' in adapted
    assert f'{EVALUATOR_NAME}(' in adapted and 'eval(' not in adapted.replace(EVALUATOR_NAME, '')
    assert 'c = collections' in adapted and 'root = math.sqrt' in adapted
    assert run_in_sandbox(adapted + 'out = (f([1]), root(16.0), floor(2.5), c.Counter("aab")["a"])\n') == \
        (3, 4.0, 2, 2)


def test_a_program_that_needs_no_change_is_returned_as_it_is():
    source = 'def f(x):\n    # a comment stays\n    return x + 1\n'
    assert adapt(source) == source


# ------------------------------------------------------------------------------------------------ arithmetic
def test_the_arithmetic_evaluator_computes_like_python():
    assert evaluate_arithmetic('2 + 3 * 4 - 5 // 2') == 12
    assert evaluate_arithmetic('2 ** 3 * 4 + 5') == 37
    assert evaluate_arithmetic('-(7 % 4) / 2') == -1.5
    with pytest.raises(ZeroDivisionError):
        evaluate_arithmetic('1 // 0')


@pytest.mark.parametrize('expression', ["__import__('os')", 'x + 1', '(1).real', '9 ** 9 ** 9', "'a' * 3",
                                        '[1] * 2', '1 if 1 else 2', '1 << 2', '2 ** 100000 * 2 ** 100000',
                                        '1' * 10_001])
def test_the_arithmetic_evaluator_refuses_everything_else(expression):
    with pytest.raises(ValueError):
        evaluate_arithmetic(expression)


# ------------------------------------------------------------------------------------------------ rebinding
def test_a_completion_may_not_rebind_what_the_test_relies_on():
    assert 'abs' in rebinding_problem('abs = lambda x: 0\n')
    assert 'check' in rebinding_problem('def check(c):\n    pass\n')
    assert 'choice' in rebinding_problem('for choice in range(3):\n    pass\n')
    helper = BY_ID['HumanEval/38']
    assert 'encode_cyclic' in rebinding_problem(helper.prompt + '    return s\n\ndef encode_cyclic(s):\n    return s\n')


def test_normal_completions_are_no_rebinding():
    assert rebinding_problem('def f(x):\n    total = abs(x)\n    return total\n') is None
    assert rebinding_problem('from typing import List\nimport math\nfrom math import floor\n') is None
    assert rebinding_problem('def f(:\n') is None  # the sandbox reports the syntax error
    assert all(rebinding_problem(candidate_program(p, oracle_completion(p))) is None for p in PROBLEMS)


# ------------------------------------------------------------------------------------------------ harness names
def _attributes(value):
    for name in dir(value):
        try:
            yield name, getattr(value, name)
        except Exception:
            continue


def test_the_harness_names_hold_no_module_and_no_private_name():
    names = harness_names()
    assert set(names) == HARNESS_NAMES
    for key, value in names.items():
        assert not key.startswith('_') and not isinstance(value, types.ModuleType)
        for attribute, member in _attributes(value):  # every attribute, dunders included (a built-in's __self__)
            assert not isinstance(member, types.ModuleType), f'{key}.{attribute}'
        if isinstance(value, SafeNamespace):
            assert sorted(vars(value)) == sorted(ALLOWED_MODULES[key].members)
            for member_name, member in vars(value).items():
                assert not member_name.startswith('_')
                for attribute, inner in _attributes(member):
                    assert not isinstance(inner, types.ModuleType), f'{key}.{member_name}.{attribute}'


def test_the_policy_text_names_every_provided_module():
    assert all(module in POLICY_TEXT for module in ALLOWED_MODULES)


@pytest.mark.parametrize('source', [
    'import math\nout = math.factorial(10 ** 6)\n',
    'import math\nout = math.comb(10 ** 6, 5 * 10 ** 5)\n',
    'from collections import Counter\nout = list((Counter({"a": 10 ** 12}) + Counter("a")).elements())\n',
    'from collections import deque\nout = deque([1, 2]) * 10 ** 9\n',
    'import re\nout = re.sub("", "x" * 1000, "a" * 10000)\n',
    'import random\nout = random.choices([1], k=10 ** 9)\n',
])
def test_stand_ins_refuse_results_past_the_sandbox_limits(source):
    with pytest.raises(ResourceLimitError):
        run_in_sandbox(source)


def test_stand_ins_compute_what_the_reference_programs_need():
    source = ('import hashlib, math, re, string, copy\nfrom collections import Counter\n'
              'out = (hashlib.md5("password".encode()).hexdigest(), math.sqrt(16), re.split(r"[.?!]\\s*", "a. b?"),\n'
              '       string.ascii_lowercase[:3], copy.deepcopy([[1]]), Counter([1, 1, 2])[1], math.factorial(5))\n')
    assert run_in_sandbox(source) == ('5f4dcc3b5aa765d61d8327deb882cf99', 4.0, ['a', 'b', ''], 'abc', [[1]], 2, 120)
