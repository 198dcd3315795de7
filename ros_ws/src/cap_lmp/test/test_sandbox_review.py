"""Escapes found in a security review of the sandbox: each program must end in a SandboxError (or, for print, stay
bounded) in a host that survives. Programs that could crash or hang the host run in a child process
(`run_isolated`), so a regression fails one test instead of the test run."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy
import pytest

from cap_lmp.errors import CodeRejected, ExecutionStopped
from cap_lmp.llm import Completion
from cap_lmp.sandbox import Sandbox
from cap_lmp.testing.attack_programs import DISABLE_TRACING
from cap_lmp.testing.sandbox_programs import TEST_LIMITS as LIMITS, run_program as run
from cap_lmp.testing.toy_domain import build_engine
from cap_lmp.testing.toy_world import ToyWorld


@pytest.fixture(scope='module')
def sandbox() -> Sandbox:
    return Sandbox(LIMITS)


_CHILD = r'''
import json, resource, sys, time
resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))  # a missed limit fails with MemoryError, not an OOM
from cap_lmp.sandbox import Sandbox, SandboxLimits
from cap_lmp.testing.attack_programs import DISABLE_TRACING
sandbox = Sandbox(SandboxLimits(time_limit_s=1.0, max_memory_growth_bytes=256 << 20))
said = []
scope = sandbox.new_scope({'say': lambda text: said.append(str(text))})
started = time.monotonic()
try:
    sandbox.execute(sandbox.compile(sys.stdin.read()), scope)
    outcome = 'ran'
except BaseException as error:
    outcome = type(error).__name__
# VmHWM is this process' own peak (ru_maxrss would include the test process' size, inherited at fork)
peak_kb = int(next(line for line in open('/proc/self/status') if line.startswith('VmHWM')).split()[1])
print(json.dumps({'outcome': outcome, 'elapsed': time.monotonic() - started, 'said': said,
                  'peak_mb': peak_kb >> 10}))
'''
_SANDBOX_ERRORS = {'CodeRejected', 'OperationRefused', 'ResourceLimitError', 'ExecutionStopped'}


def run_isolated(source: str, timeout: float = 20.0) -> dict:
    """Run a program in a child process: a crash or hang of the host fails the test instead of the test run."""
    try:
        done = subprocess.run([sys.executable, '-c', _CHILD], input=source, capture_output=True, text=True,
                              timeout=timeout, env={**os.environ, 'PYTHONPATH': os.pathsep.join(sys.path)})
    except subprocess.TimeoutExpired:
        pytest.fail(f'the host hung: no result after {timeout} s (time limit 1 s)')
    assert done.returncode == 0, f'the host died (exit {done.returncode}): {done.stderr[-300:]}'
    return json.loads(done.stdout.splitlines()[-1])


_GENERATOR_FINALIZER = DISABLE_TRACING + 'while True:\n    pass\n'

# (description, source): every one must end with a SandboxError in a host that survives (no hang: the child has
# a hard timeout).
ISOLATED_ATTEMPTS = [
    # stop swallowed by a generator finalizer: the tracer is removed, the loop runs forever
    ('stop raised in a generator finalizer', _GENERATOR_FINALIZER),
    # C-level infinite loops that grow a list
    ('list.extend of an iterator over itself', 'x = [0]\nx.extend(iter(x))'),
    ('any(map(x.append, x))', 'x = [0]\nany(map(x.append, x))'),
    ('in-place add of a map over itself', 'x = [0]\nx += map(abs, x)'),
    ('NumPy Python loop: np.diff with huge n', 'd = np.diff(np.zeros(1), n=10 ** 15)'),
    ('object-array power', "a = np.array([7], dtype='O') ** (10 ** 9)"),
    ('object-array left shift', "a = np.array([1], dtype='O') << (8 * 3 * 10 ** 9)"),
    # memory safety
    ('ndarray.resize without refcheck frees a live view',
     'for i in range(50):\n    a = np.zeros(100000)\n    b = a[:]\n    a.resize(200000, refcheck=False)\n'
     '    keep = [str(j) * 3 for j in range(2000)]\n    b[:] = 1e300'),
    ('C stack overflow in nested map', 'x = iter([1])\nfor i in range(10 ** 5):\n    x = map(abs, x)\nv = next(x)'),
    ('C stack overflow in nested zip', 'x = [1]\nfor i in range(10 ** 5):\n    x = zip(x)\nv = list(x)'),
    ('C stack overflow in nested filter and enumerate',
     'x = [1]\nfor i in range(10 ** 5):\n    x = filter(None, enumerate(x))\nv = list(x)'),
    ('list.extend of a generator over the list', 'x = [0]\nx.extend(v for v in x)'),
    ('object view of float memory', "a = np.zeros(4).view('O')"),
    # Not contained in process (documented in the sandbox module): hashing a 3e5-deep nested tuple overflows the
    # C stack; quadratic C work on aliased data (QUADRATIC_ATTEMPTS) runs uninterrupted.
]

# Single calls that allocate gigabytes although 2,000,000 elements / 1,000,000 characters are the limits: each must be
# refused before it allocates (the memory sampler only sees the damage afterwards, or never when the program ends).
ALLOCATION_ATTEMPTS = [
    ('dtype with a long string', "a = np.ones(1000, dtype='U750000')"),
    ('dtype with a subarray', "a = np.ones(375, dtype=('f8', (1000, 1000)))"),
    ('astype to a long string', "a = np.zeros(1000).astype('U750000')"),
    ('np.full with a long string', "a = np.full(750, 'a' * 10 ** 6)"),
    ('np.random.random with a positional size', 'a = np.random.random(375000000)'),
    ('np.arange with step as keyword', 'a = np.arange(375000000, step=1)'),
    ('np.outer with keyword arguments', 'v = np.ones(20000)\na = np.outer(a=v, b=v)'),
    ('matmul broadcasting a batch dimension', 'a = np.ones((1, 1000, 1))\nb = np.ones((375, 1, 1000))\nc = a @ b'),
    ('linspace between arrays', 'a = np.linspace(np.zeros(10 ** 6), np.ones(10 ** 6), 375)'),
    ('np.array(object=...)', 'row = [0.0] * 20000\na = np.array(object=[row] * 18750)'),
    ('np.array of ranges', 'a = np.array([range(10 ** 6)] * 375)'),
    ('list times a NumPy integer', 'x = [0] * np.int64(375000000)'),
    ('str times a NumPy integer', "x = 'a' * np.int64(3 * 10 ** 9)"),
    ('repeat on a NumPy scalar', 'x = np.float64(1.0).repeat(375000000)'),
    ('ones_like with a shape', 'x = np.ones_like(np.zeros(2), shape=(375000000,))'),
    ('random.normal broadcasting its parameters', 'x = np.random.normal(np.zeros(10 ** 6), np.ones((375, 1)))'),
    ('random.choice without replacement', 'x = np.random.choice(375000000, 3, replace=False)'),
    ('str.format template repeated', "s = ('{0}' * 3000).format('a' * 10 ** 6)"),
    ('percent template repeated', "s = ('%s' * 3000) % (('a' * 10 ** 6,) * 3000)"),
    ('str.format widths repeated', "s = ('{0:9999}' * 125000).format(0)"),
    ('percent widths repeated', "s = ('%9999s' * 125000) % ((0,) * 125000)"),
    ('str.format keyword fields', "s = ('{a}' * 3000).format(a='a' * 10 ** 6)"),
    ('Shapely buffer with a NumPy segment count', 'p = Point(0, 0).buffer(1.0, np.int64(10 ** 6))'),
    ('Shapely buffer with an array of distances', 'p = Point(0, 0).buffer(np.ones(2 * 10 ** 6), 64)'),
    ('Shapely multi-geometry of one big line repeated',
     'L = LineString(np.ones((10 ** 6, 2)) * np.arange(10 ** 6)[:, None])\nm = MultiLineString([L] * 150)'),
]

# Quadratic C-level work on aliased structures; each input stays within the size limits.
QUADRATIC_ATTEMPTS = [
    ('str of an aliased nested list', 'row = [0] * 10 ** 6\ns = str([row] * 1000)'),
    ('hash of an aliased nested tuple', 't = (0,) * 10 ** 6\nh = hash((t,) * 20000)'),
    ('list.count comparing long lists', 'a = [0] * 10 ** 6\nc = ([a] * 20000).count(list(a))'),
    ('set of integers with one hash', 'xs = [i * (2 ** 61 - 1) for i in range(60000)]\ns = set(xs)'),
]


@pytest.mark.parametrize('description, source', ISOLATED_ATTEMPTS, ids=[a[0] for a in ISOLATED_ATTEMPTS])
def test_isolated_attempts_end_in_a_sandbox_error_in_time(description, source):
    result = run_isolated(source)
    assert result['outcome'] in _SANDBOX_ERRORS, result


@pytest.mark.parametrize('description, source', ALLOCATION_ATTEMPTS, ids=[a[0] for a in ALLOCATION_ATTEMPTS])
def test_large_single_allocations_are_refused_before_they_happen(description, source):
    result = run_isolated(source)
    assert result['outcome'] in ('ResourceLimitError', 'OperationRefused', 'CodeRejected'), result
    assert result['peak_mb'] < 512, result


def test_print_with_a_huge_separator_stays_bounded():
    result = run_isolated("print(*([''] * 3000), sep='a' * 10 ** 6)\nsay('printed')")
    assert result['said'] == ['printed'] and result['peak_mb'] < 512, result


@pytest.mark.parametrize('source', [
    "match '{0.__globals__[re].enum.sys.modules[os].environ[HOME]}':\n    case str(format=f):\n        say(f(say))",
    "match Point(0, 0):\n    case Point(x):\n        pass",
    "match 'x':\n    case str(a, b):\n        pass",
    "match 'x':\n    case str(ljust=f):\n        s = f(10)",
    "x = [0]\nmatch x:\n    case list(extend=e):\n        pass",
    "match 1:\n    case int(to_bytes=tb):\n        pass",
])
def test_class_patterns_cannot_fetch_unguarded_methods(sandbox, source):
    with pytest.raises(CodeRejected):
        run(sandbox, source)


def test_a_swallowed_stop_cannot_be_survived_by_a_program_that_ends(sandbox):
    """Even when the program finishes, a stop the tracer raised must be reported."""
    source = _GENERATOR_FINALIZER.replace('while True:\n    pass', 'i = 0\nwhile i < 200000:\n    i += 1')
    with pytest.raises(ExecutionStopped):
        run(sandbox, source)


class _ScriptedClient:
    def __init__(self, answers):
        self.answers = list(answers)

    def complete(self, request):
        return Completion(text=self.answers.pop(0))


def test_engine_bounds_the_message_of_a_programs_exception():
    """The engine formats the program's exception after the watchdog has ended: the text must be bounded."""
    engine = build_engine(ToyWorld.with_objects({'red block': (0, -0.5)}).api(),
                          _ScriptedClient(['row = [0] * 10 ** 6\nraise ValueError([row] * 20)']), limits=LIMITS)
    result = engine.run('fail loudly')
    assert not result.success and len(result.message) < 20_000


_SESSION_CHILD = r'''
import json
from cap_lmp.llm import Completion
from cap_lmp.sandbox import SandboxLimits
from cap_lmp.testing.toy_domain import build_engine
from cap_lmp.testing.toy_world import ToyWorld

class Client:
    def __init__(self, answers):
        self.answers = list(answers)

    def complete(self, request):
        return Completion(text=self.answers.pop(0))

keep = 'keep_{0} = [np.ones(2 * 10 ** 6) + i for i in range(6)]'
engine = build_engine(ToyWorld.with_objects({'red block': (0, -0.5)}).api(), Client([keep.format(i) for i in range(4)]),
                      limits=SandboxLimits(time_limit_s=5.0, max_memory_growth_bytes=256 << 20))
results = [engine.run(f'keep {i}') for i in range(4)]
print(json.dumps([[r.success, r.stop_reason, r.message] for r in results]))
'''


def test_session_variables_count_against_the_memory_limit():
    """Each command keeps 100 MB in the session: the third must be stopped (limit 256 MiB), not the host; the
    session, holding more than half the limit, is reset, and the fourth command runs again.

    Runs in a fresh process: the resident size of a long test process says little about new allocations."""
    done = subprocess.run([sys.executable, '-c', _SESSION_CHILD], capture_output=True, text=True, timeout=60,
                          env={**os.environ, 'PYTHONPATH': os.pathsep.join(sys.path)})
    assert done.returncode == 0, done.stderr[-300:]
    results = json.loads(done.stdout.splitlines()[-1])
    assert [r[:2] for r in results] == [[True, ''], [True, ''], [False, 'memory'], [True, '']], results
    assert 'memory' in results[2][2] and 'so it was reset' in results[2][2], results[2][2]


def test_builtin_class_patterns_still_match(sandbox):
    source = ("def kind(v):\n    match v:\n        case int(n):\n            return 'int'\n"
              "        case str():\n            return 'str'\n        case _:\n            return 'other'\n"
              "say([kind(1), kind('a'), kind(2.5)])")
    assert run(sandbox, source)['said'] == ["['int', 'str', 'other']"]


def test_string_translate_is_refused(sandbox):
    with pytest.raises(CodeRejected):
        run(sandbox, "t = str.maketrans('a', 'b')\ns = 'abc'.translate(t)")


def test_a_stop_stays_in_force_once_raised(sandbox):
    """A run that swallowed its stop and ended anyway reports the stop; the next run starts fresh."""
    with pytest.raises(ExecutionStopped) as caught:
        run(sandbox, _GENERATOR_FINALIZER)
    assert caught.value.reason == 'recursion'  # raised inside a generator finalizer, where CPython swallowed it
    assert sys.gettrace() is None
    assert run(sandbox, "say('fresh')")['said'] == ['fresh']


def test_iteration_helpers_behave_like_the_builtins(sandbox):
    source = '''
a = list(map(abs, [-1, 2, -3]))
b = list(map(lambda x, y: x * y, [1, 2, 3], [4, 5]))
c = list(filter(None, [0, 1, '', 'x']))
d = list(filter(lambda v: v > 1, range(4)))
e = list(zip('ab', [1, 2, 3]))
f = list(enumerate('xy', start=5))
g = list(reversed([1, 2, 3]))
h = dict(zip(['k'], [1]))
try:
    list(zip([1], [1, 2], strict=True))
    i = 'no error'
except ValueError:
    i = 'ValueError'
j = list(zip([1, 2], 'ab', strict=True))
x = [1, 2]
x += map(abs, [-3])
x.extend(v * 2 for v in [5])
'''
    scope = run(sandbox, source)
    assert scope['a'] == [1, 2, 3] and scope['b'] == [4, 10] and scope['c'] == [1, 'x'] and scope['d'] == [2, 3]
    assert scope['e'] == [('a', 1), ('b', 2)] and scope['f'] == [(5, 'x'), (6, 'y')] and scope['g'] == [3, 2, 1]
    assert scope['h'] == {'k': 1} and scope['i'] == 'ValueError' and scope['x'] == [1, 2, 3, 10]
    assert scope['j'] == [(1, 'a'), (2, 'b')]


def test_ordinary_numpy_and_shapely_calls_still_work(sandbox):
    source = '''
a = np.diff(np.arange(5.0), n=2)
b = np.zeros(3).astype('int32')
c = np.ones(4)
c.resize(2)
d = np.outer(a=np.ones(2), b=np.ones(3))
e = np.arange(1, 7, step=2)
f = np.ones((2, 2, 3)) @ np.ones((3, 4))
g = np.random.normal(np.zeros(3), 1.0)
h = '{} and {name}'.format('x', name='y') + ' %s' % 'z'
p = Point(0, 0).buffer(1.0, np.int64(8))
m = MultiLineString([LineString([(0, 0), (1, 1)])] * 3)
r = [0] * np.int64(3)
'''
    scope = run(sandbox, source)
    assert scope['a'].tolist() == [0.0, 0.0, 0.0] and scope['b'].dtype == numpy.int32 and scope['c'].shape == (2,)
    assert scope['d'].shape == (2, 3) and scope['e'].tolist() == [1, 3, 5] and scope['f'].shape == (2, 2, 4)
    assert scope['g'].shape == (3,) and scope['h'] == 'x and y z' and scope['p'].area > 3.0
    assert len(scope['m'].geoms) == 3 and scope['r'] == [0, 0, 0]


def test_a_shadowed_api_name_is_restored_for_the_next_command():
    world = ToyWorld.with_objects({'red block': (0, -0.5)})
    engine = build_engine(world.api(), _ScriptedClient([
        'say = lambda text: None\nnp = None', "say('still here')\nx = np.zeros(2)"]), limits=LIMITS)
    first, second = engine.run('shadow'), engine.run('speak')
    assert first.success and second.success, (first.message, second.message)
