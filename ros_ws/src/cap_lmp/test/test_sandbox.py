"""The sandbox refuses or stops every escape and exhaustion attempt, runs ordinary policy code; the host survives."""
from __future__ import annotations

import builtins
import math
import sys
import threading
import time

import numpy
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cap_lmp.errors import CodeRejected, ExecutionStopped, OperationRefused, ResourceLimitError, SandboxError
from cap_lmp.sandbox import Sandbox, check_code
from cap_lmp.testing.sandbox_programs import TEST_LIMITS as LIMITS, run_program as run


@pytest.fixture(scope='module')
def sandbox() -> Sandbox:
    return Sandbox(LIMITS)


# Escape and exhaustion attempts, by the SandboxError subclass that must end them (description: source).
ATTEMPTS_BY_ERROR = {
    CodeRejected: {
        'dunder traversal to object.__subclasses__': '().__class__.__bases__[0].__subclasses__()',
        'import a module': 'import os',
        'from-import': 'from subprocess import run',
        '__import__ by name': "__import__('os').system('true')",
        'eval of a string': "eval('1 + 1')",
        'exec of a string': "exec('x = 1')",
        'compile': "compile('1', 'f', 'eval')",
        'open a file': "open('/etc/passwd').read()",
        'getattr with a built string': "getattr((), '__cl' + 'ass__')",
        'globals()': "globals()['__builtins__']",
        'vars() and locals()': 'x = vars() or locals()',
        'builtins through a passed-in function': "say.__globals__['__builtins__']",
        'closure of a passed-in function': 'get_obj_pos.__closure__[0].cell_contents',
        'old-style function globals': 'say.func_globals',
        'code object of a lambda': '(lambda: 0).__code__.co_consts',
        'generator frame to caller globals': 'g = (x for x in [1])\nf = g.gi_frame.f_back.f_globals',
        'generator code attribute': 'def f():\n    yield 1\nc = f().gi_code',
        'traceback frame of a caught error':
            'try:\n    1 / 0\nexcept Exception as e:\n    t = e.__traceback__.tb_frame',
        'f-string dunder': "f'{say.__globals__}'",
        'format_map': "'{x}'.format_map({'x': 1})",
        'NumPy function globals': 'np.mean.__globals__',
        'exception class hierarchy': 'Exception.__subclasses__()',
        'the builtins mapping by name': "__builtins__['__import__']('os')",
        'type() to reach classes': 'type(1)',
        'mro without dunders': 'int.mro()',
        'NumPy raw memory through ctypes': 'p = np.zeros(3).ctypes.data',
        'NumPy writes a file': "np.zeros(3).tofile('/tmp/cap_sandbox_escape')",
        'NumPy module dict': 'np.__dict__',
        'class definition': 'class A:\n    pass',
        'with statement': "with x as y:\n    pass",
        'global escape': 'def f():\n    global say\n    say = None',
        'attribute assignment': 'say.x = 1',
        'match class pattern on a dunder': 'match 1:\n    case int(__class__=c):\n        pass',
        'bare except that would swallow a stop': 'while True:\n    try:\n        pass\n    except:\n        pass',
        'finally that would keep running': 'try:\n    pass\nfinally:\n    while True:\n        pass',
        'f-string width': "x = f'{1:>10000000000}'",
    },
    OperationRefused: {
        'format-string attribute access': "'{0.__class__.__base__}'.format(1)",
        'format-string generator frame': "'{0.gi_frame}'.format(x for x in [])",
        'format-string item lookup': "'{0[__builtins__]}'.format({})",
        'unbound str.format on the type': "str.format('{0.__class__}', 1)",
        'bound format kept for later': "fmt = '{0.__class__}'.format\nfmt(1)",
        'format field built from chr()': "f = '{0.' + chr(95) * 2 + 'class' + chr(95) * 2 + '}'\nf.format(1)",
        'C-level infinite iterator': 'all(iter(int, 1))',
    },
    ResourceLimitError: {
        'huge power': 'x = 10 ** 10 ** 10',
        'string repetition': "x = 'a' * 10 ** 10",
        'list repetition': 'x = [0] * 10 ** 9',
        'left shift': 'x = 1 << 10 ** 10',
        'squaring an integer forever': 'x = 2\nwhile True:\n    x = x * x',
        'materialised huge range': 'x = list(range(10 ** 12))',
        'NumPy huge allocation': 'x = np.zeros((100000, 100000))',
        'NumPy broadcast blow-up': 'a = np.ones(100000)\nb = a[:, None] * a[None, :]',
        'NumPy repeat method': 'a = np.arange(1000000)\nb = a.repeat(1000000)',
        'string padding': "x = 'x'.ljust(10 ** 10)",
        'string join of many copies': "x = ''.join(['a' * 10 ** 6] * 1000)",
        'percent-format width': "x = '%10000000000d' % 1",
        'str.replace blow-up': "x = ('a' * 10 ** 6).replace('', 'b' * 1000)",
        'int.to_bytes allocation': "x = (1).to_bytes(10 ** 10, 'big')",
        'big-int construction from bytes': "x = int.from_bytes(b'ab' * 500000, 'big')",
        'Shapely buffer resolution': 'p = Point(0, 0).buffer(1, 10 ** 7)',
        'quadratic sum of lists': 'x = sum([[0] * 10 ** 6] * 10 ** 6, [])',
        'list doubling by extend': 'x = [1] * 1000\nwhile True:\n    x.extend(x)',
        'integer rounded to a billion digits': 'x = round(1, -10 ** 9)',
        'modular power of huge numbers': 'x = 7 ** 30000\ny = pow(x, x, x + 2)',
        'cubic linear algebra on a big matrix': 'x = np.linalg.svd(np.ones((2000, 1000)))',
    },
    ExecutionStopped: {
        'infinite loop': 'while True:\n    pass',
        'infinite loop that catches errors':
            'while True:\n    try:\n        while True:\n            pass\n    except Exception:\n        pass',
        'infinite generator consumed in C': 'def g():\n    while True:\n        yield 1\nx = max(g())',
        'deep recursion': 'def f(n):\n    return f(n + 1)\nf(0)',
        'recursion through lambdas': '(lambda f: f(f))(lambda f: f(f))',
        'memory exhaustion in a loop': "x = []\nwhile True:\n    x.append('a' * 500000 + str(len(x)))",
    },
}
ATTEMPTS = [(description, source, error) for error, attempts in ATTEMPTS_BY_ERROR.items()
            for description, source in attempts.items()]


@pytest.mark.parametrize('description, source, expected', ATTEMPTS, ids=[a[0] for a in ATTEMPTS])
def test_escape_and_exhaustion_attempts_are_refused_or_stopped(sandbox, description, source, expected):
    with pytest.raises(expected) as caught:
        run(sandbox, source, get_obj_pos=lambda name: numpy.zeros(2))
    assert str(caught.value)  # a message a person can read
    if expected is ExecutionStopped:
        assert caught.value.reason in ('timeout', 'recursion', 'memory')


def test_there_are_at_least_thirty_attempts():
    assert len(ATTEMPTS) >= 30


def test_the_host_keeps_working_after_the_attempts(sandbox):
    for _description, source, _expected in ATTEMPTS:
        with pytest.raises(SandboxError):
            run(sandbox, source, get_obj_pos=lambda name: numpy.zeros(2))
    assert sys.gettrace() is None  # the watchdog is gone
    assert builtins.len([1, 2]) == 2 and 'open' in vars(builtins)  # the real builtins are untouched
    assert not hasattr(numpy, 'cap_sandbox_marker')
    scope = run(sandbox, "total = sum(range(10))\nsay(f'total {total}')")
    assert scope['said'] == ['total 45']


def test_stop_message_names_the_time_limit(sandbox):
    with pytest.raises(ExecutionStopped) as caught:
        run(sandbox, 'i = 0\nwhile True:\n    i += 1')
    assert caught.value.reason == 'timeout'
    assert 'time limit of 1 s' in str(caught.value)


def test_cancel_from_another_thread_stops_the_program(sandbox):
    cancel = threading.Event()
    scope = sandbox.new_scope({})
    program = sandbox.compile('while True:\n    pass')
    timer = threading.Timer(0.1, cancel.set)
    timer.start()
    with pytest.raises(ExecutionStopped) as caught:
        sandbox.execute(program, scope, cancel)
    timer.join()
    assert caught.value.reason == 'cancelled'
    assert 'cancelled' in str(caught.value)


def test_ordinary_policy_code_runs(sandbox):
    source = '\n'.join([
        "names = ['red block', 'blue block', 'red bowl']",
        "blocks = [n for n in names if 'block' in n]",
        "pts = np.array([[0.0, 0.0], [0.1, 0.0], [0.1, 0.1]])",
        "center = pts.mean(axis=0)",
        "dist = float(np.linalg.norm(pts[1] - center))",
        "poly = Polygon(pts)",
        "moved = np.array(translate(LineString(pts), xoff=0.1).coords)",
        "counts = {}",
        "for b in blocks:",
        "    counts[b] = counts.get(b, 0) + 1",
        "counts['red block'] += 2",
        "def area_of(p):",
        "    return round(p.area, 4)",
        "say(f'{len(blocks)} blocks, area {area_of(poly)}, {sorted(counts.items())}')",
        "say('%s and %d' % ('text', 3))",
        "say('{} {}'.format('a', 'b'))",
        "say(', '.join(blocks).upper())",
        "x = 3\nx **= 2\nx <<= 2",
        "total = sum([1, 2, 3]) + pow(2, 10) + pow(3, 4, 5) + round(2.5) + round(1234, -2)",
        "print('printing goes to the log')",
    ])
    scope = run(sandbox, source)
    assert scope['said'] == ['2 blocks, area 0.005, [(\'blue block\', 1), (\'red block\', 3)]', 'text and 3',
                             'a b', 'RED BLOCK, BLUE BLOCK']
    assert scope['x'] == 36 and scope['total'] == 1030 + 1 + 2 + 1200
    assert numpy.allclose(scope['moved'][0], [0.1, 0.0])


def test_programs_errors_come_back_as_their_own_exceptions(sandbox):
    with pytest.raises(KeyError):
        run(sandbox, "d = {}\nd['missing']")
    with pytest.raises(NameError):
        run(sandbox, 'undefined_name + 1')


def test_a_refusal_names_the_line(sandbox):
    with pytest.raises(CodeRejected) as caught:
        sandbox.compile('x = 1\ny = x.__class__')
    assert caught.value.line == 2
    assert 'y = x.__class__' in str(caught.value)


# -- properties ---------------------------------------------------------------------------------------------
@settings(max_examples=60, deadline=None)
@given(st.from_regex(r'_[A-Za-z0-9_]{0,12}', fullmatch=True))
def test_any_underscore_attribute_is_refused(name):
    with pytest.raises(CodeRejected):
        check_code(f'x = say.{name}')


@settings(max_examples=60, deadline=None)
@given(st.sampled_from(['gi_', 'f_', 'cr_', 'ag_', 'tb_', 'co_']), st.from_regex(r'[a-z]{1,10}', fullmatch=True))
def test_frame_and_code_attributes_are_refused(prefix, rest):
    with pytest.raises(CodeRejected):
        check_code(f'x = thing.{prefix}{rest}')


_SCALARS = st.one_of(st.integers(-1000, 1000), st.floats(-1e3, 1e3, allow_nan=False), st.booleans())
_OPERATORS = ['+', '-', '*', '/', '//', '%', '**', '<<', '>>', '&', '|', '^', '<', '<=', '==', '!=', '>', '>=']


@settings(max_examples=200, deadline=None)
@given(_SCALARS, st.sampled_from(_OPERATORS), _SCALARS)
def test_guarded_operators_give_pythons_results(sandbox, left, operator, right):
    """Rewritten operators compute what Python computes (or refuse), for any small operands."""
    source = f'result = ({left!r}) {operator} ({right!r})'
    try:
        expected = eval(source.split('=', 1)[1], {})  # the reference: plain Python on constants we generated
    except (ArithmeticError, TypeError, ValueError) as error:
        with pytest.raises(type(error)):
            run(sandbox, source)
        return
    try:
        got = run(sandbox, source)['result']
    except ResourceLimitError:
        assert isinstance(expected, int) and expected.bit_length() > LIMITS.max_int_bits // 2
        return
    if isinstance(expected, float) and math.isnan(expected):
        assert math.isnan(got)
    else:
        assert got == expected and type(got) is type(expected)


@settings(max_examples=50, deadline=None)
@given(st.lists(st.integers(-5, 5), max_size=8), st.integers(0, 4), st.lists(st.integers(-5, 5), max_size=4))
def test_guarded_sequence_operations_match_python(sandbox, items, times, more):
    scope = run(sandbox, f'a = {items!r} * {times}\nb = a + {more!r}\nb += [0]\nc = sum(b)\nd = b[:]\nd *= 2')
    a = items * times
    assert scope['a'] == a and scope['b'] == a + more + [0] and scope['c'] == sum(a + more)
    assert scope['d'] == (a + more + [0]) * 2


def test_model_waiting_time_does_not_count(sandbox):
    """A nested model call pauses the clock: a program waiting longer than the limit in total still finishes."""
    def slow_model_call() -> int:
        with sandbox.watchdog.paused():
            time.sleep(LIMITS.time_limit_s * 0.6)
        return 1

    scope = run(sandbox, 'total = 0\nfor i in range(2):\n    total += ask()', ask=slow_model_call)
    assert scope['total'] == 2


_ATOMS = st.sampled_from(['say', 'np', 'np.linalg', '()', '[]', '{}', "''", '1', '10 ** 5', 'x', 'str', 'int',
                          'Exception', '(i for i in [1])', 'lambda: 0', 'get_obj_pos', 'Point(0, 0)'])
_TRAILERS = st.sampled_from(['.__class__', '.__globals__', '.gi_frame', '.f_back', '.mro()', '.__subclasses__()',
                             '()', '(1)', "('a')", '[0]', '.format', ".format('{0.__class__}')", '.upper()',
                             '.mean()', '.buffer(1)', ' * 10 ** 9', ' ** 99999', '.ljust(10 ** 12)', ' + x'])


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(_ATOMS, st.lists(_TRAILERS, max_size=4)), min_size=1, max_size=4))
def test_random_escape_chains_never_reach_the_host(sandbox, chains):
    """Random chains of attribute, call and operator tricks: refused, stopped or an ordinary error; never more."""
    source = 'x = 1\n' + '\n'.join(f'x = {atom}{"".join(trailers)}' for atom, trailers in chains)
    try:
        run(sandbox, source, get_obj_pos=lambda name: numpy.zeros(2))
    except SandboxError:
        pass
    except Exception as error:  # the program's own error (TypeError, AttributeError, ...): reported, harmless
        assert not isinstance(error, (SystemExit, KeyboardInterrupt))
    assert sys.gettrace() is None
    assert 'open' in vars(builtins) and builtins.len('ab') == 2
