"""What the HumanEval harness allows on top of the sandbox's rules, which stay as they are.

HumanEval programs import a few standard modules, use a bare `except:` now and then, and one reference solution
(HumanEval/160) calls `eval` on an arithmetic expression. The robot sandbox refuses all three. Before a program
is checked, `adapt` rewrites it: imports of the modules in ALLOWED_MODULES are removed (their names are in the
scope, from `harness_names`), `from m import x` reads the member from the stand-in, `except:` catches Exception,
and `eval(text)` becomes the arithmetic evaluator. Every other import is refused, and everything else runs under
the sandbox's rules unchanged.

A module stand-in is a SafeNamespace of allow-listed public members, never the module: modules reach other
modules (and the operating system) through their attributes. Built-in functions are wrapped in plain functions
(a built-in's `__self__` is its module), and members that could build values past the sandbox's limits in one
call (factorials, Counter.elements, deque repetition, random.choices, re.sub) check the limit first.
"""
from __future__ import annotations

import ast
import bisect
import builtins
import collections
import copy
import functools
import hashlib
import heapq
import math
import numbers
import operator
import random
import re
import string
import symtable
from dataclasses import dataclass
from typing import Any, Callable, Mapping

from cap_lmp.errors import ResourceLimitError
from cap_lmp.sandbox.limits import SandboxLimits
from cap_lmp.sandbox.names import NUMPY_CONSTANTS, NUMPY_FUNCTIONS, SafeNamespace

# The stand-ins bound what they build by the sandbox's default limits.
_LIMITS = SandboxLimits()
# Tests draw their inputs from this seed: every run of the benchmark sees the same inputs.
RANDOM_SEED = 0
# The name `eval(...)` calls are rewritten to.
EVALUATOR_NAME = 'evaluate_arithmetic'
MAX_EXPRESSION_LENGTH = 10_000


@dataclass(frozen=True)
class AllowedModule:
    """A module the harness provides: its members, the name the program sees it under, and why."""

    members: tuple[str, ...]
    why: str
    scope_name: str = ''  # '' means the module's own name

    def name_in(self, module: str) -> str:
        return self.scope_name or module


_TYPING_NAMES = ('Any', 'Callable', 'DefaultDict', 'Deque', 'Dict', 'FrozenSet', 'Generator', 'Iterable',
                 'Iterator', 'List', 'Mapping', 'Optional', 'Sequence', 'Set', 'Tuple', 'Union')
_REGEX_FLAGS = ('A', 'ASCII', 'DOTALL', 'I', 'IGNORECASE', 'M', 'MULTILINE', 'S', 'VERBOSE', 'X')

ALLOWED_MODULES: Mapping[str, AllowedModule] = {
    'typing': AllowedModule(_TYPING_NAMES, 'prompts annotate with List, Tuple, Optional and Any; annotations only '
                            '(inert stand-ins that can be subscripted: the real aliases reach `register` of the '
                            'abstract collections, which changes isinstance for the whole process)'),
    'math': AllowedModule(
        ('acos', 'asin', 'atan', 'atan2', 'ceil', 'comb', 'copysign', 'cos', 'degrees', 'dist', 'e', 'exp', 'fabs',
         'factorial', 'floor', 'fmod', 'fsum', 'gcd', 'hypot', 'inf', 'isclose', 'isfinite', 'isinf', 'isnan',
         'isqrt', 'lcm', 'log', 'log10', 'log2', 'modf', 'nan', 'perm', 'pi', 'pow', 'prod', 'radians', 'sin',
         'sqrt', 'tan', 'tau', 'trunc'),
        'solutions and tests use sqrt, floor, ceil, fabs and pow; the rest are numeric functions of the same kind '
        '(factorial, comb, perm, prod and lcm refuse results larger than the sandbox\'s integer limit)'),
    'random': AllowedModule(
        ('Random', 'choice', 'choices', 'randint', 'random', 'randrange', 'sample', 'seed', 'shuffle', 'uniform'),
        'tests draw inputs with randint, choice and Random(seed); the test gets a generator of its own (see '
        f'test_program), the completion one seeded with {RANDOM_SEED} when the process starts; Random(seed) gives '
        'a generator of the same members'),
    'string': AllowedModule(
        ('ascii_letters', 'ascii_lowercase', 'ascii_uppercase', 'digits', 'hexdigits', 'octdigits', 'printable',
         'punctuation', 'whitespace'),
        'tests use ascii_lowercase; the module\'s text constants only'),
    'collections': AllowedModule(
        ('Counter', 'OrderedDict', 'defaultdict', 'deque'),
        'a solution counts with Counter; the other containers are what solutions of such problems use '
        '(Counter.elements and deque repetition are bounded by the sandbox\'s sequence limit)'),
    'copy': AllowedModule(('copy', 'deepcopy'), 'tests pass copies of their inputs with deepcopy'),
    're': AllowedModule(
        ('escape', 'findall', 'fullmatch', 'match', 'search', 'split', 'sub', 'subn') + _REGEX_FLAGS,
        'a solution splits with re.split; matching and substitution functions (sub and subn bound their output '
        'by the sandbox\'s sequence limit; matching time and a match\'s pattern (.re) are bounded by the sandbox '
        'process\'s limits only)'),
    'hashlib': AllowedModule(('md5', 'sha1', 'sha256'), 'a solution returns an md5 digest'),
    'functools': AllowedModule(('cache', 'cmp_to_key', 'lru_cache', 'reduce'),
                               'helpers solutions commonly use; their work is bounded by the program\'s own calls'),
    'heapq': AllowedModule(('heapify', 'heappop', 'heappush', 'heappushpop', 'heapreplace', 'nlargest',
                            'nsmallest'), 'heap operations on the program\'s own lists'),
    'bisect': AllowedModule(('bisect', 'bisect_left', 'bisect_right', 'insort', 'insort_left', 'insort_right'),
                            'binary search on the program\'s own lists'),
    'numpy': AllowedModule(NUMPY_FUNCTIONS + NUMPY_CONSTANTS + ('linalg', 'random'),
                           'the sandbox\'s allow-listed NumPy, already in scope as np', scope_name='np'),
}

# Names the harness also puts in the scope directly: what `from typing import ...` and the benchmark's own
# `from math import floor, ceil` and `from random import randint, choice` bind (name -> module).
TOP_LEVEL_NAMES: Mapping[str, str] = {
    **{name: 'typing' for name in _TYPING_NAMES},
    'floor': 'math', 'ceil': 'math', 'randint': 'random', 'choice': 'random',
}

# Why some modules are refused, for the message; others: not needed by the benchmark's programs.
_REFUSED_BECAUSE = {
    **dict.fromkeys(('os', 'sys', 'subprocess', 'shutil', 'pathlib', 'io', 'socket', 'signal', 'tempfile', 'glob',
                     'multiprocessing', 'threading', 'asyncio', 'pickle', 'marshal'),
                    'it reaches the file system, processes or the network'),
    **dict.fromkeys(('builtins', 'importlib', 'inspect', 'types', 'gc', 'ctypes', 'code', 'codeop', 'operator',
                     'weakref', 'abc'),
                    'it reaches the interpreter\'s internals, past the sandbox\'s checks'),
    'itertools': 'its iterators do unbounded work inside a single C call (list(permutations(range(12))), count()), '
                 'out of the time limit\'s reach',
}

_PROVIDED_TEXT = ', '.join(sorted(ALLOWED_MODULES))

POLICY_TEXT = (
    'HumanEval programs run in the robot sandbox, whose rules stay as they are; before the check the harness:\n'
    f'- removes imports of {_PROVIDED_TEXT} (numpy is the sandbox\'s np) and provides stand-ins holding allow-listed '
    'members only; `from m import x` reads x from the stand-in; any other import is refused;\n'
    '- turns a bare `except:` into `except Exception:`;\n'
    f'- turns `eval(text)` into {EVALUATOR_NAME}(text): numbers, + - * / // % ** and parentheses only '
    '(HumanEval/160);\n'
    '- gives the test its own random generator, seeded per item with a seed recorded in items.jsonl (the '
    f'completion\'s `random` is another generator, seeded with {RANDOM_SEED} when the sandbox process starts), '
    'and defines the prompt\'s helper functions again for the test, from the package\'s text;\n'
    '- bounds math.factorial/comb/perm/prod/lcm, Counter.elements, deque repetition, random.choices/sample and '
    're.sub/subn by the sandbox\'s size limits (regular-expression matching time, and the methods of a match\'s '
    'pattern, are bounded only by the sandbox process\'s time and memory limits);\n'
    '- fails a completion that rebinds at top level a builtin, a harness name, check, candidate or METADATA, or '
    'redefines a function of the prompt.'
)


class PolicyRefusal(ValueError):
    """A program the harness does not run: a module it does not provide, a syntax error, `eval` with scopes."""

    def __init__(self, message: str, line: int | None = None) -> None:
        super().__init__(message if line is None else f'{message} (line {line})')
        self.line = line


# ---------------------------------------------------------------------------------------------------- adapt
def _refusal_for_module(module: str, line: int) -> PolicyRefusal:
    why = _REFUSED_BECAUSE.get(module.split('.')[0], 'the benchmark\'s programs do not need it')
    return PolicyRefusal(f'importing {module!r} is not allowed: {why}; the harness provides {_PROVIDED_TEXT}', line)


def _name(identifier: str) -> ast.Name:
    return ast.Name(id=identifier, ctx=ast.Load())


def _assign(target: str, value: ast.expr) -> ast.Assign:
    return ast.Assign(targets=[ast.Name(id=target, ctx=ast.Store())], value=value)


class _Adapter(ast.NodeTransformer):
    """Rewrites imports, bare `except:` and `eval(...)`; records whether anything changed."""

    def __init__(self) -> None:
        self.changed = False

    def visit_Import(self, node: ast.Import) -> list[ast.stmt]:
        self.changed = True
        replacements: list[ast.stmt] = []
        for alias in node.names:
            allowed = ALLOWED_MODULES.get(alias.name)
            if allowed is None:
                raise _refusal_for_module(alias.name, node.lineno)
            bound, provided = alias.asname or alias.name, allowed.name_in(alias.name)
            if bound != provided:  # `import numpy` / `import math as m`: bind the stand-in under that name
                replacements.append(ast.copy_location(_assign(bound, _name(provided)), node))
        return replacements

    def visit_ImportFrom(self, node: ast.ImportFrom) -> list[ast.stmt]:
        self.changed = True
        module = node.module or ''
        if node.level:
            raise PolicyRefusal('relative imports are not allowed: the program is not part of a package', node.lineno)
        allowed = ALLOWED_MODULES.get(module)
        if allowed is None:
            raise _refusal_for_module(module, node.lineno)
        if [alias.name for alias in node.names] == ['*']:
            bindings = [(member, member) for member in allowed.members]
        else:
            bindings = [(alias.name, alias.asname or alias.name) for alias in node.names]
        replacements: list[ast.stmt] = []
        for member, target in bindings:
            if member not in allowed.members:
                raise PolicyRefusal(f'{module}.{member} is not provided by the harness; its {module} has '
                                    f'{", ".join(allowed.members)}', node.lineno)
            if target == member and TOP_LEVEL_NAMES.get(member) == module:
                continue  # already in the scope, the same object
            value = ast.Attribute(value=_name(allowed.name_in(module)), attr=member, ctx=ast.Load())
            replacements.append(ast.copy_location(_assign(target, value), node))
        return replacements

    def visit_ExceptHandler(self, node: ast.ExceptHandler) -> ast.ExceptHandler:
        self.generic_visit(node)
        if node.type is None:
            self.changed = True
            node.type = ast.copy_location(_name('Exception'), node)
        return node

    def visit_Call(self, node: ast.Call) -> ast.AST:
        if isinstance(node.func, ast.Name) and node.func.id == 'eval' and (len(node.args) != 1 or node.keywords
                                                                            or isinstance(node.args[0], ast.Starred)):
            raise PolicyRefusal('eval() is available for one arithmetic expression only (no globals or locals)',
                                node.lineno)
        return self.generic_visit(node)

    def visit_Name(self, node: ast.Name) -> ast.Name:
        if node.id == 'eval' and isinstance(node.ctx, ast.Load):
            self.changed = True
            return ast.copy_location(_name(EVALUATOR_NAME), node)
        return node


def _fill_empty_blocks(tree: ast.AST) -> None:
    """A block whose only statement was an import still needs a statement."""
    for node in ast.walk(tree):
        if not isinstance(node, ast.Module) and isinstance(getattr(node, 'body', None), list) and not node.body:
            node.body.append(ast.copy_location(ast.Pass(), node))
        if isinstance(node, ast.Try) and not node.handlers and not node.finalbody:
            node.finalbody.append(ast.copy_location(ast.Pass(), node))


def adapt(source: str) -> str:
    """The program as it will run in the sandbox: imports of allowed modules removed (or bound from the stand-ins),
    bare `except:` catching Exception, `eval(...)` calling the arithmetic evaluator. Raises PolicyRefusal for other
    imports and for a syntax error. A program that needs no change is returned as it is."""
    try:
        tree = ast.parse(source)
    except SyntaxError as error:
        raise PolicyRefusal(f'the program has a syntax error: {error.msg}', error.lineno) from None
    except (ValueError, RecursionError, MemoryError) as error:
        raise PolicyRefusal(f'the program could not be parsed: {error}') from None
    adapter = _Adapter()
    try:
        tree = adapter.visit(tree)
    except RecursionError:
        raise PolicyRefusal('the program is nested too deeply') from None
    if not adapter.changed:
        return source
    _fill_empty_blocks(tree)
    return ast.unparse(ast.fix_missing_locations(tree)) + '\n'


# ---------------------------------------------------------------------------------------------------- rebinding
_BUILTIN_NAMES = frozenset(name for name in dir(builtins) if not name.startswith('_'))
HARNESS_NAMES = frozenset({module for module, allowed in ALLOWED_MODULES.items() if not allowed.scope_name}
                          | set(TOP_LEVEL_NAMES) | {EVALUATOR_NAME})
_TEST_NAMES = frozenset({'check', 'candidate', 'METADATA'})
PROTECTED_NAMES = _BUILTIN_NAMES | HARNESS_NAMES | _TEST_NAMES


class _TopLevelBindings(ast.NodeVisitor):
    """Names a program binds in its global scope: (name, line, kind), not descending into function bodies."""

    def __init__(self) -> None:
        self.bindings: list[tuple[str, int, str]] = []

    def bind(self, name: str | None, node: ast.AST, kind: str) -> None:
        if name:
            self.bindings.append((name, getattr(node, 'lineno', 0), kind))

    def visit_FunctionDef(self, node: ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef) -> None:
        self.bind(node.name, node, 'def')
        arguments = getattr(node, 'args', None)
        defaults = (arguments.defaults + [d for d in arguments.kw_defaults if d is not None]) if arguments else []
        for expression in node.decorator_list + defaults:  # evaluated in the global scope
            self.visit(expression)

    visit_AsyncFunctionDef = visit_FunctionDef
    visit_ClassDef = visit_FunctionDef

    def visit_Lambda(self, node: ast.Lambda) -> None:
        # Its parameters are its own; its defaults are evaluated in the enclosing scope (a walrus there binds).
        for expression in node.args.defaults + [d for d in node.args.kw_defaults if d is not None]:
            self.visit(expression)

    def visit_comprehension(self, node: ast.comprehension) -> None:
        self.visit(node.iter)  # the target is the comprehension's own; a walrus in a condition is not
        for condition in node.ifs:
            self.visit(condition)

    def visit_Name(self, node: ast.Name) -> None:
        if not isinstance(node.ctx, ast.Load):
            self.bind(node.id, node, 'assignment')

    def visit_Import(self, node: ast.Import) -> None:
        for alias in node.names:
            allowed = ALLOWED_MODULES.get(alias.name)
            bound = alias.asname or alias.name.split('.')[0]
            if allowed is None or bound != allowed.name_in(alias.name):
                self.bind(bound, node, 'import')

    def visit_ImportFrom(self, node: ast.ImportFrom) -> None:
        module = node.module if node.level == 0 else None
        if [alias.name for alias in node.names] == ['*']:
            allowed = ALLOWED_MODULES.get(module or '')
            bindings = [(member, member) for member in (allowed.members if allowed else ())]
        else:
            bindings = [(alias.name, alias.asname or alias.name) for alias in node.names]
        for member, bound in bindings:
            if not (bound == member and TOP_LEVEL_NAMES.get(member) == module):
                self.bind(bound, node, 'import')

    def visit_ExceptHandler(self, node: ast.ExceptHandler) -> None:
        self.bind(node.name, node, 'assignment')
        self.generic_visit(node)

    def visit_MatchAs(self, node: ast.MatchAs) -> None:
        self.bind(node.name, node, 'assignment')
        self.generic_visit(node)

    def visit_MatchStar(self, node: ast.MatchStar) -> None:
        self.bind(node.name, node, 'assignment')

    def visit_MatchMapping(self, node: ast.MatchMapping) -> None:
        self.bind(node.rest, node, 'assignment')
        self.generic_visit(node)


def rebinding_problem(candidate_source: str) -> str | None:
    """Why a candidate program (prompt + completion) must not run, or None.

    A completion may not rebind at top level a name the test relies on: a builtin, a name the harness provides,
    check, candidate or METADATA; nor define again (or assign) a function the program already defines, such as a
    helper of the prompt the test calls. Imports that bind the harness' own object are no rebinding. A program
    that does not parse gives None: the sandbox reports its syntax error.
    """
    try:
        tree = ast.parse(candidate_source)
    except (SyntaxError, ValueError, RecursionError, MemoryError):
        return None
    finder = _TopLevelBindings()
    try:
        finder.visit(tree)
        # The compiler's own scope analysis, for every way of binding a global this visitor might miss; on the
        # program as it runs (the allowed imports removed).
        try:
            adapted = adapt(candidate_source)
        except PolicyRefusal:
            adapted = candidate_source
        table = symtable.symtable(adapted, '<candidate>', 'exec')
    except (RecursionError, SyntaxError, ValueError, MemoryError):
        return 'the program is nested too deeply to check what it binds at top level'
    for symbol in table.get_symbols():
        name = symbol.get_name()
        if name in PROTECTED_NAMES and (symbol.is_assigned() or symbol.is_imported() or symbol.is_namespace()):
            if not any(bound == name for bound, _, _ in finder.bindings):
                return (f'the program rebinds {name!r} at top level; the test relies on it (a builtin, a name the '
                        'harness provides, or one of check, candidate, METADATA)')
    defined: set[str] = set()
    for name, line, kind in finder.bindings:
        if name in PROTECTED_NAMES:
            return (f'the program rebinds {name!r} at top level (line {line}); the test relies on it (a builtin, a '
                    'name the harness provides, or one of check, candidate, METADATA)')
        if name in defined:
            return f'the program defines {name!r} again at top level (line {line}); the test may call the first one'
        if kind == 'def':
            defined.add(name)
    return None


# ---------------------------------------------------------------------------------------------------- arithmetic
def _check_bits(bits: float, what: str) -> None:
    if bits > _LIMITS.max_int_bits:
        raise ValueError(f'{what} would be an integer of about {int(bits):,} bits; at most '
                         f'{_LIMITS.max_int_bits:,} are allowed')


def _arithmetic_mul(a: int | float, b: int | float) -> int | float:
    if isinstance(a, int) and isinstance(b, int):
        _check_bits(a.bit_length() + b.bit_length(), 'this product')
    return a * b


def _arithmetic_pow(a: int | float, b: int | float) -> int | float:
    if isinstance(a, int) and isinstance(b, int) and b > 0 and abs(a) > 1:
        _check_bits(b * math.log2(abs(a)), 'this power')
    return a ** b


_ARITHMETIC_BINARY: Mapping[type, Callable[[Any, Any], Any]] = {
    ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: _arithmetic_mul, ast.Div: operator.truediv,
    ast.FloorDiv: operator.floordiv, ast.Mod: operator.mod, ast.Pow: _arithmetic_pow,
}
_ARITHMETIC_UNARY: Mapping[type, Callable[[Any], Any]] = {ast.USub: operator.neg, ast.UAdd: operator.pos}


def evaluate_arithmetic(expression: str) -> int | float:
    """The value of an arithmetic expression: int and float literals, + - * / // % ** and unary - +, parentheses.

    Anything else (names, calls, attributes, strings) raises ValueError, and so do an expression longer than
    MAX_EXPRESSION_LENGTH and an integer result past the sandbox's integer limit. Division by zero raises
    ZeroDivisionError, as Python's eval would.
    """
    if not isinstance(expression, str):
        raise ValueError('the arithmetic evaluator takes a text')
    if len(expression) > MAX_EXPRESSION_LENGTH:
        raise ValueError(f'the expression is longer than {MAX_EXPRESSION_LENGTH:,} characters')
    try:
        tree = ast.parse(expression.lstrip(' \t'), mode='eval')
    except (SyntaxError, ValueError, RecursionError, MemoryError) as error:
        raise ValueError(f'not an arithmetic expression: {error}') from None
    # Post-order with an explicit stack: a long chain (1+1+...+1) is nested deeper than Python's recursion limit.
    pending: list[tuple[ast.AST, bool]] = [(tree.body, False)]
    values: list[int | float] = []
    while pending:
        node, operands_done = pending.pop()
        if isinstance(node, ast.Constant) and type(node.value) in (int, float):
            values.append(node.value)
        elif isinstance(node, ast.BinOp) and type(node.op) in _ARITHMETIC_BINARY:
            if operands_done:
                right = values.pop()
                values.append(_ARITHMETIC_BINARY[type(node.op)](values.pop(), right))
            else:
                pending.extend(((node, True), (node.right, False), (node.left, False)))
        elif isinstance(node, ast.UnaryOp) and type(node.op) in _ARITHMETIC_UNARY:
            if operands_done:
                values.append(_ARITHMETIC_UNARY[type(node.op)](values.pop()))
            else:
                pending.extend(((node, True), (node.operand, False)))
        else:
            what = type(node.value).__name__ if isinstance(node, ast.Constant) else type(node).__name__.lower()
            raise ValueError(f'only numbers, + - * / // % ** and parentheses are allowed, not a {what} (column '
                             f'{getattr(node, "col_offset", 0) + 1})')
    return values[0]


# ---------------------------------------------------------------------------------------------------- stand-ins
class TypeHint:
    """An annotation stand-in (List, Optional, ...): subscripting gives it back, and it has nothing else to reach.

    Not callable, so the sandbox puts it into the scope as it is."""

    __slots__ = ('name',)

    def __init__(self, name: str) -> None:
        self.name = name

    def __getitem__(self, parameters: Any) -> TypeHint:
        return self

    def __repr__(self) -> str:
        return f'typing.{self.name}'


def _plain(function: Callable[..., Any]) -> Callable[..., Any]:
    """A plain function calling `function`: a built-in's `__self__` (its module) is not among its attributes."""
    def call(*args: Any, **kwargs: Any) -> Any:
        return function(*args, **kwargs)
    call.__name__ = call.__qualname__ = getattr(function, '__name__', 'function')
    call.__doc__ = getattr(function, '__doc__', None)
    return call


def _check_length(length: int, what: str) -> None:
    if length > _LIMITS.max_sequence_length:
        raise ResourceLimitError(f'{what} would have length {length:,}; the sandbox allows at most '
                                 f'{_LIMITS.max_sequence_length:,}')


def _check_int_bits(bits: float, what: str) -> None:
    if bits > _LIMITS.max_int_bits:
        raise ResourceLimitError(f'{what} would be an integer of about {int(bits):,} bits; the sandbox allows at '
                                 f'most {_LIMITS.max_int_bits:,}')


def _log2_falling_factorial(n: int, k: int) -> float:
    """An upper bound of log2(n! / (n - k)!), the size of perm(n, k) (and of comb(n, k))."""
    bound = k * math.log2(max(n, 2))
    if n < 2 ** 40:  # lgamma is precise enough here
        bound = min(bound, (math.lgamma(n + 1) - math.lgamma(n - k + 1)) / math.log(2) + 64)
    return bound


def _math_members() -> dict[str, Any]:
    members = _module_members(math, ALLOWED_MODULES['math'].members)

    def factorial(n: int) -> int:
        if isinstance(n, int) and n > 2:
            _check_int_bits(_log2_falling_factorial(n, n), 'math.factorial')
        return math.factorial(n)

    def comb(n: int, k: int) -> int:
        if isinstance(n, int) and isinstance(k, int) and 0 < k < n:
            _check_int_bits(_log2_falling_factorial(n, min(k, n - k)), 'math.comb')
        return math.comb(n, k)

    def perm(n: int, k: int | None = None) -> int:
        if isinstance(n, int) and n > 2 and (k is None or isinstance(k, int) and 0 < k <= n):
            _check_int_bits(_log2_falling_factorial(n, n if k is None else k), 'math.perm')
        return math.perm(n, k)

    def prod(iterable: Any, *, start: Any = 1) -> Any:
        total = start
        for item in iterable:  # numbers only: math.prod of a text and a count would repeat the text unchecked
            if not isinstance(item, numbers.Number) or isinstance(total, (str, bytes, list, tuple)):
                raise TypeError('math.prod takes numbers in the sandbox')
            if isinstance(total, int) and isinstance(item, int):
                _check_int_bits(total.bit_length() + item.bit_length(), 'math.prod')
            total = total * item
        return total

    def lcm(*integers: int) -> int:
        _check_int_bits(sum(abs(operator.index(i)).bit_length() for i in integers), 'math.lcm')
        return math.lcm(*integers)

    members.update(factorial=factorial, comb=comb, perm=perm, prod=prod, lcm=lcm)
    return members


def _generator_members(generator: random.Random) -> dict[str, Any]:
    members = {name: _plain(getattr(generator, name))
               for name in ('choice', 'randint', 'random', 'randrange', 'seed', 'shuffle', 'uniform')}

    def choices(population: Any, weights: Any = None, *, cum_weights: Any = None, k: int = 1) -> list[Any]:
        _check_length(operator.index(k), 'random.choices')
        return generator.choices(population, weights, cum_weights=cum_weights, k=k)

    def sample(population: Any, k: int, *, counts: Any = None) -> list[Any]:
        _check_length(operator.index(k), 'random.sample')
        return generator.sample(population, k, counts=counts)

    def Random(seed: Any = None) -> SafeNamespace:
        """A generator of its own, seeded with `seed`, with the same members."""
        return SafeNamespace(**_generator_members(random.Random(seed)))

    members.update(choices=choices, sample=sample, Random=Random)
    return members


class BoundedCounter(collections.Counter):
    """collections.Counter whose elements() refuses more items than the sandbox's sequence limit (a count of
    10 ** 12 would be listed in one C call), and whose arithmetic keeps that rule."""

    def elements(self) -> Any:
        _check_length(sum(count for count in self.values() if isinstance(count, int) and count > 0),
                      'Counter.elements()')
        return super().elements()

    def __add__(self, other: Any) -> Any:
        return BoundedCounter(super().__add__(other))

    def __sub__(self, other: Any) -> Any:
        return BoundedCounter(super().__sub__(other))

    def __or__(self, other: Any) -> Any:
        return BoundedCounter(super().__or__(other))

    def __and__(self, other: Any) -> Any:
        return BoundedCounter(super().__and__(other))

    def __pos__(self) -> Any:
        return BoundedCounter(super().__pos__())

    def __neg__(self) -> Any:
        return BoundedCounter(super().__neg__())


class BoundedDeque(collections.deque):
    """collections.deque whose repetition (`d * n`) is bounded like the sandbox bounds list repetition."""

    def __mul__(self, times: Any) -> Any:
        _check_length(len(self) * max(operator.index(times), 0), 'this deque repetition')
        return super().__mul__(times)

    __rmul__ = __mul__

    def __imul__(self, times: Any) -> Any:
        _check_length(len(self) * max(operator.index(times), 0), 'this deque repetition')
        return super().__imul__(times)


# repr() and error messages read as the originals'.
BoundedCounter.__name__ = BoundedCounter.__qualname__ = 'Counter'
BoundedDeque.__name__ = BoundedDeque.__qualname__ = 'deque'
BoundedCounter.__module__ = BoundedDeque.__module__ = 'collections'


def _bounded_substitution(repl: Any) -> Callable[[re.Match], Any]:
    """The replacement function of re.sub / re.subn that counts the text it produces."""
    produced = 0
    template = isinstance(repl, (str, bytes))
    literal = template and (b'\\' if isinstance(repl, bytes) else '\\') not in repl  # re.sub takes it as it is

    def replacement(match: re.Match) -> Any:
        nonlocal produced
        text = repl if literal else match.expand(repl) if template else repl(match)
        if isinstance(text, (str, bytes)):
            produced += len(text)
            _check_length(produced + len(match.string), 're.sub')
        return text
    return replacement


def _re_members() -> dict[str, Any]:
    members = _module_members(re, ALLOWED_MODULES['re'].members)

    def sub(pattern: Any, repl: Any, text: Any, count: int = 0, flags: int = 0) -> Any:
        return re.sub(pattern, _bounded_substitution(repl), text, count=count, flags=flags)

    def subn(pattern: Any, repl: Any, text: Any, count: int = 0, flags: int = 0) -> Any:
        return re.subn(pattern, _bounded_substitution(repl), text, count=count, flags=flags)

    members.update(sub=sub, subn=subn)
    return members


def _module_members(module: Any, names: tuple[str, ...]) -> dict[str, Any]:
    """Members as they are, built-in functions wrapped (their `__self__` is their module)."""
    members = {}
    for name in names:
        value = getattr(module, name)
        members[name] = value if isinstance(value, type) or not callable(value) else _plain(value)
    return members


def harness_names() -> dict[str, Any]:
    """The names the harness adds to a sandbox scope: module stand-ins, the typing names, the names the benchmark's
    `from ... import` statements bind, and the arithmetic evaluator. Build it in the process that runs the
    programs, once per process: the random generator starts from RANDOM_SEED (a test program rebinds its own,
    problems.test_program)."""
    generator = random.Random(RANDOM_SEED)
    modules: dict[str, dict[str, Any]] = {
        'typing': {name: TypeHint(name) for name in _TYPING_NAMES},
        'math': _math_members(),
        'random': _generator_members(generator),
        'string': {name: getattr(string, name) for name in ALLOWED_MODULES['string'].members},
        'collections': {'Counter': BoundedCounter, 'OrderedDict': collections.OrderedDict,
                        'defaultdict': collections.defaultdict, 'deque': BoundedDeque},
        'copy': {name: _plain(getattr(copy, name)) for name in ALLOWED_MODULES['copy'].members},
        're': _re_members(),
        'hashlib': _module_members(hashlib, ALLOWED_MODULES['hashlib'].members),
        'functools': _module_members(functools, ALLOWED_MODULES['functools'].members),
        'heapq': _module_members(heapq, ALLOWED_MODULES['heapq'].members),
        'bisect': _module_members(bisect, ALLOWED_MODULES['bisect'].members),
    }
    names: dict[str, Any] = {module: SafeNamespace(**members) for module, members in modules.items()}
    names.update({name: modules[module][name] for name, module in TOP_LEVEL_NAMES.items()})
    names[EVALUATOR_NAME] = evaluate_arithmetic
    return names
