"""The sandbox's size rules by meaning: arguments bound the way the function binds them (by position and by name),
outputs bounded as well as inputs, truth values tested as the function tests them, and every way to a big integer
guarded. Each finding of an outside attack run is refused before its C call; ordinary calls still run.

Sizes are just past the limits (a 1 x 1,500 svd input rather than the 1 x 15,000 one found): the rule is the same,
and a rule that regressed would cost the test run megabytes, not gigabytes.
"""
from __future__ import annotations

import inspect

import numpy
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cap_lmp.errors import CodeRejected, OperationRefused, ResourceLimitError, SandboxError
from cap_lmp.sandbox import Sandbox
from cap_lmp.sandbox.binding import binder
from cap_lmp.sandbox.names import NUMPY_FUNCTIONS, NUMPY_LINALG, NUMPY_RANDOM
from cap_lmp.testing.sandbox_programs import TEST_LIMITS as LIMITS, run_program as run

BIG_MATRIX = numpy.ones((501, 501))  # 251,001 elements: past the cubic limit of 250,000
HUGE_INT = 1 << 200_000  # an integer from outside the program (the robot API), twice the integer limit


@pytest.fixture(scope='module')
def sandbox() -> Sandbox:
    return Sandbox(LIMITS)


def verdict(sandbox: Sandbox, source: str, **names: object) -> str:
    """'ran', or the name of the SandboxError that ended the program."""
    try:
        run(sandbox, source, **names)
    except SandboxError as error:
        assert 'sandbox' in str(error) or isinstance(error, CodeRejected), str(error)  # a message that says why
        return type(error).__name__
    return 'ran'


# -- the findings -----------------------------------------------------------------------------------------------
FINDINGS = {
    # the cubic limit skipped when the matrix is passed by keyword
    'np.linalg.eig(a=M)': 'x = np.linalg.eig(a=M)',
    'np.linalg.pinv(a=M)': 'x = np.linalg.pinv(a=M)',
    'np.linalg.solve(a=M, b=v)': 'x = np.linalg.solve(a=M, b=np.ones(501))',
    'np.linalg.solve(b=v, a=M)': 'x = np.linalg.solve(b=np.ones(501), a=M)',
    'np.linalg.inv(a=M)': 'x = np.linalg.inv(a=M)',
    'np.linalg.det(a=M)': 'x = np.linalg.det(a=M)',
    # outputs: svd's V of a one-row input is square in its length
    'np.linalg.svd of a one-row input': 'x = np.linalg.svd(np.ones((1, 1500)))',
    'np.linalg.svd(a=..., full_matrices=1)': 'x = np.linalg.svd(a=np.ones((1500, 1)), full_matrices=1)',
    'np.linalg.norm 2 of a big matrix': 'x = np.linalg.norm(M, 2)',
    'np.linalg.norm nuc by keyword': "x = np.linalg.norm(x=M, ord='nuc', axis=(0, 1))",
    # truth values, not identity
    'np.random.choice(..., replace=0)': 'x = np.random.choice(3000000, 3, replace=0)',
    'np.random.choice(..., replace=None)': 'x = np.random.choice(a=3000000, size=3, replace=None)',
    'np.random.choice(..., replace=a NumPy false)': 'x = np.random.choice(3000000, 3, np.zeros(1, dtype=bool)[0])',
    # integers
    'int.from_bytes on a value': "x = (5).from_bytes(b'ab' * 100000, 'big')",
    'int.from_bytes on True': "x = True.from_bytes(b'ab' * 100000, 'big')",
    'int.from_bytes on the class, by keyword': "x = int.from_bytes(bytes=b'ab' * 100000, byteorder='little')",
    'int.from_bytes of a list': 'x = int.from_bytes([255] * 100000)',
    'int() of binary text': "x = int('1' * 200000, 2)",
    'int() of hexadecimal text, base 0': "x = int('0x' + 'f' * 50000, base=0)",
    'int() of bytes': "x = int(b'1' * 200000, 2)",
    'doubling an integer by addition': 'x = 1 << 99990\nwhile True:\n    x = x + x',
    'doubling an integer in place': 'x = 1 << 99990\nwhile True:\n    x += x',
    'subtraction': 'x = -(1 << 99999) - (1 << 99999)',
    'round() with NumPy digits': 'x = round(1, np.int64(-10 ** 6))',
    # lists counted by the shape they convert to, before anything converts them
    'array sum with a nested list': 'row = [0.0] * 10 ** 5\nb = np.ones(1) + [row] * 100',
    'comparison with a nested list': 'row = [0.0] * 10 ** 5\nb = np.ones(1) < [row] * 100',
    'np.dot of a nested list': 'row = [0.0] * 10 ** 5\nb = np.dot([row] * 100, np.ones(10 ** 5))',
    'ndarray.dot of a nested list': 'row = [0.0] * 2000\nb = np.ones((2000, 2000 // 4)).T.dot([row] * 2000)',
    'np.repeat counts as a nested list': 'row = [1] * 10 ** 5\nb = np.repeat(np.zeros(5), [row] * 100)',
    # other rules of the same kind
    'np.arange(stop=...)': 'x = np.arange(stop=10 ** 12)',
    'np.arange(step=..., stop=...)': 'x = np.arange(step=1, stop=10 ** 12)',
    'a ufunc on Python objects': "x = np.sqrt(np.ones(3), signature='O->O')",
    'np.roll over a million shifts': 'x = np.roll(np.zeros(3), [1] * 10 ** 6, [0] * 10 ** 6)',
    'ndarray.view with a positional type': "x = np.zeros(2).view('f8', np.float64)",
    'str.join of an iterator': "x = ', '.join(iter(['abc'] * 300000))",
    'parallel_offset with a positional resolution':
        "x = LineString([(0, 0), (1, 1)]).parallel_offset(0.1, 'left', 10 ** 6)",
    'buffer with resolution by keyword': 'x = Point(0, 0).buffer(1.0, resolution=10 ** 6)',
    'buffer with distance by keyword': 'x = Point(0, 0).buffer(distance=np.ones(10 ** 6))',
}
# An integer the program did not make (from the robot API): the operations that cost more than its size refuse it.
OUTSIDE_INTEGER = {
    'divmod': 'y = divmod(x, 3)', 'floor division': 'y = x // 3', 'in-place floor division': 'x //= 3',
    'remainder': 'y = x % 7', 'in-place remainder': 'x %= 7', 'product': 'y = x * 1', 'power': 'y = x ** 1',
    'pow()': 'y = pow(x, 1)', 'pow() with a modulus': 'y = pow(x, 3, 7)', 'round()': 'y = round(x, -2)',
    'left shift': 'y = x << 0', 'sum': 'y = x + 1', 'difference': 'y = 1 - x',
}


@pytest.mark.parametrize('source', FINDINGS.values(), ids=list(FINDINGS))
def test_the_findings_are_refused_before_they_run(sandbox, source):
    assert verdict(sandbox, source, M=BIG_MATRIX) in ('ResourceLimitError', 'OperationRefused')


@pytest.mark.parametrize('source', OUTSIDE_INTEGER.values(), ids=list(OUTSIDE_INTEGER))
def test_big_integer_arithmetic_refuses_an_integer_from_outside(sandbox, source):
    assert verdict(sandbox, source, x=HUGE_INT) == 'ResourceLimitError'


def test_an_integer_literal_past_the_limit_is_refused_before_anything_runs(sandbox):
    with pytest.raises(CodeRejected) as refused:
        sandbox.compile('x = 0x' + 'f' * 30_000)
    assert '120,000 bits' in str(refused.value)
    sandbox.compile('x = 0x' + 'f' * 1000)


def test_ordinary_uses_still_run(sandbox):
    source = '\n'.join([
        'm = np.array([[2.0, 1.0], [1.0, 3.0]])',
        'w, v = np.linalg.eig(a=m)',
        'x = np.linalg.solve(b=np.ones(2), a=m)',
        'u, s, vt = np.linalg.svd(m, full_matrices=True)',
        'row = np.linalg.svd(np.ones((1, 15000)), full_matrices=False)[1]',
        'wide = np.linalg.svd(a=np.ones((1, 500)))[2].shape',
        'p = np.linalg.pinv(a=m, rcond=1e-9)',
        'n = [float(np.linalg.norm(m, 2)), float(np.linalg.norm(x=np.ones(10 ** 6))), np.linalg.norm(M)]',
        'picked = np.random.choice(10, 3, replace=False)',
        'sample = np.random.choice(10 ** 9, 3)',
        'ints = [int("42"), int("ff", 16), int(b"12"), int(3.9), int.from_bytes(b"\\x01\\x00", "big"),',
        '        (0).from_bytes(b"\\x01", byteorder="little"), divmod(17, 5), -17 // 5, -17 % 5, 2 ** 100 % 7,',
        '        (1 << 200) >> 199, round(1234, -2), pow(3, 4, 5), isinstance(True, int), int.bit_length(255)]',
        'match 7:',
        '    case int(k):',
        '        matched = k',
        'typed = [np.zeros(2, dtype=int).dtype.kind, np.arange(3).astype(int).dtype.kind, str(int), str(int | None)]',
        "curve = LineString([(0, 0), (1, 1)]).parallel_offset(0.1, 'left')",
        'disc = Point(0, 0).buffer(distance=1.0, quad_segs=8)',
        "text = ', '.join(['red block', 'blue bowl']) + ''.join(str(i) for i in range(10))",
        'grid = np.arange(stop=5) + np.arange(1, 5, step=2).sum()',
        'rolled = [list(np.roll(np.arange(4), 1)), np.roll(np.eye(2), (1, 1), (0, 1)).tolist()]',
    ])
    scope = run(sandbox, source, M=BIG_MATRIX)
    assert numpy.allclose(scope['m'] @ scope['x'], [1.0, 1.0]) and scope['row'].shape == (1,)
    assert scope['wide'] == (500, 500) and len(scope['picked']) == 3
    assert scope['ints'] == [42, 255, 12, 3, 256, 1, (3, 2), -4, 3, 2, 2, 1200, 1, True, 8]
    assert scope['matched'] == 7 and scope['typed'] == ['i', 'i', "<class 'int'>", 'int | None']
    assert scope['curve'].length > 0 and scope['disc'].area > 3.0 and scope['text'].endswith('0123456789')
    assert list(scope['grid']) == [4, 5, 6, 7, 8]
    assert scope['rolled'] == [[3, 0, 1, 2], [[1.0, 0.0], [0.0, 1.0]]]


# -- properties: by position or by keyword, the same verdict ----------------------------------------------------
# (call, its parameters in order, how many of them are positional-only, a refused and an allowed set of values)
BINDING_CASES = [
    ('np.linalg.eig', ('a',), 0, {'a': BIG_MATRIX}, {'a': numpy.eye(3)}),
    ('np.linalg.inv', ('a',), 0, {'a': BIG_MATRIX}, {'a': numpy.eye(3)}),
    ('np.linalg.det', ('a',), 0, {'a': BIG_MATRIX}, {'a': numpy.eye(3)}),
    ('np.linalg.pinv', ('a', 'rcond', 'hermitian'), 0, {'a': BIG_MATRIX, 'rcond': None, 'hermitian': False},
     {'a': numpy.eye(3), 'rcond': None, 'hermitian': False}),
    ('np.linalg.solve', ('a', 'b'), 0, {'a': BIG_MATRIX, 'b': numpy.ones(501)},
     {'a': numpy.eye(3), 'b': numpy.ones(3)}),
    ('np.linalg.svd', ('a', 'full_matrices', 'compute_uv'), 0,
     {'a': numpy.ones((1, 1500)), 'full_matrices': True, 'compute_uv': True},
     {'a': numpy.ones((1, 1500)), 'full_matrices': False, 'compute_uv': True}),
    ('np.linalg.norm', ('x', 'ord', 'axis'), 0, {'x': BIG_MATRIX, 'ord': 2, 'axis': None},
     {'x': BIG_MATRIX, 'ord': None, 'axis': None}),
    ('np.random.choice', ('a', 'size', 'replace'), 0, {'a': 3_000_000, 'size': 3, 'replace': False},
     {'a': 3_000_000, 'size': 3, 'replace': True}),
    ('np.random.normal', ('loc', 'scale', 'size'), 0, {'loc': 0.0, 'scale': 1.0, 'size': 3_000_000},
     {'loc': 0.0, 'scale': 1.0, 'size': 3}),
    ('np.random.uniform', ('low', 'high', 'size'), 0, {'low': 0.0, 'high': 1.0, 'size': (2000, 2000)},
     {'low': 0.0, 'high': 1.0, 'size': (2, 2)}),
    ('np.random.randint', ('low', 'high', 'size'), 0, {'low': 0, 'high': 9, 'size': 3_000_000},
     {'low': 0, 'high': 9, 'size': 3}),
    ('np.random.random', ('size',), 0, {'size': 3_000_000}, {'size': 3}),
    ('np.zeros', ('shape', 'dtype'), 0, {'shape': (2000, 2000), 'dtype': 'float64'},
     {'shape': (2, 2), 'dtype': 'float64'}),
    ('np.full', ('shape', 'fill_value'), 0, {'shape': 3_000_000, 'fill_value': 1.0}, {'shape': 3, 'fill_value': 1.0}),
    ('np.zeros_like', ('a', 'dtype', 'order', 'subok', 'shape'), 0,
     {'a': numpy.ones(2), 'dtype': None, 'order': 'K', 'subok': True, 'shape': (2000, 2000)},
     {'a': numpy.ones(2), 'dtype': None, 'order': 'K', 'subok': True, 'shape': None}),
    ('np.linspace', ('start', 'stop', 'num'), 0, {'start': 0, 'stop': 1, 'num': 3_000_000},
     {'start': 0, 'stop': 1, 'num': 5}),
    ('np.arange', ('start', 'stop', 'step'), 0, {'start': 0, 'stop': 3_000_000, 'step': 1},
     {'start': 0, 'stop': 3, 'step': 1}),
    ('np.eye', ('N', 'M'), 0, {'N': 2000, 'M': 2000}, {'N': 2, 'M': 3}),
    ('np.outer', ('a', 'b'), 0, {'a': numpy.ones(2000), 'b': numpy.ones(2000)},
     {'a': numpy.ones(2), 'b': numpy.ones(2)}),
    ('np.kron', ('a', 'b'), 0, {'a': numpy.ones(2000), 'b': numpy.ones(2000)},
     {'a': numpy.ones(2), 'b': numpy.ones(2)}),
    ('np.tile', ('A', 'reps'), 0, {'A': numpy.ones(2000), 'reps': 2000}, {'A': numpy.ones(2), 'reps': 2}),
    ('np.repeat', ('a', 'repeats', 'axis'), 0, {'a': numpy.zeros((10, 0)), 'repeats': 10 ** 12, 'axis': 0},
     {'a': numpy.zeros((10, 2)), 'repeats': 2, 'axis': 0}),
    ('np.percentile', ('a', 'q', 'axis'), 0, {'a': numpy.zeros((10 ** 4, 1)), 'q': numpy.zeros(1000), 'axis': 1},
     {'a': numpy.zeros((10, 1)), 'q': [50], 'axis': 1}),
    ('np.diff', ('a', 'n'), 0, {'a': numpy.zeros(3), 'n': 10 ** 15}, {'a': numpy.zeros(3), 'n': 1}),
    ('np.dot', ('a', 'b'), 0, {'a': numpy.ones((2000, 1)), 'b': numpy.ones((1, 2000))},
     {'a': numpy.ones((2, 1)), 'b': numpy.ones((1, 2))}),
    ('pow', ('base', 'exp', 'mod'), 0, {'base': 7, 'exp': 1 << 5000, 'mod': 1 << 5000},
     {'base': 7, 'exp': 1 << 50, 'mod': 1 << 50}),
    ('round', ('number', 'ndigits'), 0, {'number': 1, 'ndigits': numpy.int64(-10 ** 6)},
     {'number': 1234, 'ndigits': numpy.int64(-2)}),
    ('int', ('x', 'base'), 1, {'x': '1' * 200_000, 'base': 2}, {'x': '101', 'base': 2}),
    ('int.from_bytes', ('bytes', 'byteorder'), 0, {'bytes': b'ab' * 100_000, 'byteorder': 'big'},
     {'bytes': b'ab', 'byteorder': 'big'}),
    ('(7).from_bytes', ('bytes', 'byteorder'), 0, {'bytes': b'ab' * 100_000, 'byteorder': 'big'},
     {'bytes': b'ab', 'byteorder': 'big'}),
    ('Point(0, 0).buffer', ('distance', 'quad_segs'), 0, {'distance': 1.0, 'quad_segs': 10 ** 6},
     {'distance': 1.0, 'quad_segs': 8}),
    ('LineString([(0, 0), (1, 1)]).parallel_offset', ('distance', 'side', 'resolution'), 0,
     {'distance': 0.1, 'side': 'left', 'resolution': 10 ** 6}, {'distance': 0.1, 'side': 'left', 'resolution': 8}),
]


def call_source(call: str, parameters: tuple, positional: int, keyword_order: list[str]) -> str:
    """`result = call(arg_a, ..., name=arg_name, ...)`: the first `positional` parameters by position, the rest by
    keyword in `keyword_order`."""
    arguments = [f'arg_{name}' for name in parameters[:positional]] + [f'{name}=arg_{name}' for name in keyword_order]
    return f'result = {call}({", ".join(arguments)})'


@settings(max_examples=250, deadline=None)
@given(st.sampled_from(BINDING_CASES), st.booleans(), st.data())
def test_a_call_gets_the_same_verdict_by_position_or_by_keyword(sandbox, case, refused, data):
    call, parameters, positional_only, too_big, fine = case
    values = too_big if refused else fine
    positional = data.draw(st.integers(positional_only, len(parameters)), label='positional')
    keyword_order = data.draw(st.permutations(parameters[positional:]), label='keywords')
    names = {f'arg_{name}': value for name, value in values.items()}
    got = verdict(sandbox, call_source(call, parameters, positional, keyword_order), **names)
    assert got == verdict(sandbox, call_source(call, parameters, len(parameters), []), **names)
    assert (got != 'ran') == refused, got


_FALSE = [False, 0, 0.0, None, '', [], (), numpy.False_, numpy.int64(0)]
_TRUE = [True, 1, 2.5, 'yes', [0], (0,), numpy.True_, numpy.int64(3)]


@settings(max_examples=60, deadline=None)
@given(st.sampled_from(_FALSE + _TRUE), st.booleans())
def test_flags_are_read_by_their_truth_value(sandbox, flag, keyword):
    """replace=0 is no replacement, full_matrices='' no full matrices: what numpy's `if flag:` reads."""
    argument = 'replace=flag' if keyword else 'None, flag'
    choice = verdict(sandbox, f'x = np.random.choice(3000000, {argument})', flag=flag)
    assert (choice == 'ran') == bool(flag)
    argument = 'full_matrices=flag' if keyword else 'flag'
    svd = verdict(sandbox, f'x = np.linalg.svd(np.ones((1, 1500)), {argument})', flag=flag)
    assert (svd == 'ran') == (not flag)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2 * LIMITS.max_int_bits // 8), st.sampled_from(['int', '(0)', 'True', '(10 ** 30)']),
       st.booleans())
def test_int_from_bytes_gets_one_verdict_on_the_class_and_on_values(sandbox, length, owner, keyword):
    arguments = "bytes=data, byteorder='big'" if keyword else "data, 'big'"
    got = verdict(sandbox, f'x = {owner}.from_bytes({arguments})', data=b'\x01' * length)
    assert (got == 'ran') == (8 * length <= LIMITS.max_int_bits)


_STEPS = st.sampled_from(['x = x * x', 'x = x + x', 'x = x - 3 * x', 'x = x << 1000', 'x = x ** 3', 'x *= x',
                          'x = pow(x, 2)', 'x = x // 7 + x', 'x = divmod(x, 3)[0] * x', 'x = int(hex(x), 16) * 2',
                          'x = int.from_bytes(x.to_bytes(x.bit_length() // 8 + 1, "big") * 2, "big")',
                          'x = -x - x', 'x = round(x, -3) * 3'])


@settings(max_examples=80, deadline=None)
@given(st.integers(2, 10 ** 6), st.lists(_STEPS, min_size=1, max_size=40))
def test_no_integer_a_program_makes_exceeds_the_limit(sandbox, start, steps):
    """Whatever integer arithmetic a program chains, each step stays within the limit or is refused before it runs."""
    source = f'x = {start}\n' + ''.join(f'{step}\nsizes.append(x.bit_length())\n' for step in steps)
    sizes: list[int] = []
    try:
        run(sandbox, source, sizes=sizes)
    except (ResourceLimitError, ArithmeticError, ValueError):  # refused, or the program's own error
        pass
    assert all(bits <= LIMITS.max_int_bits for bits in sizes)


# -- binding ------------------------------------------------------------------------------------------------------
def _numpy_functions():
    for module, names in ((numpy, NUMPY_FUNCTIONS), (numpy.linalg, NUMPY_LINALG), (numpy.random, NUMPY_RANDOM)):
        for name in names:
            yield getattr(module, name)


@settings(max_examples=200, deadline=None)
@given(st.sampled_from([f for f in _numpy_functions() if binder(f, 'f') is not None]), st.data())
def test_binding_agrees_with_the_signature(function, data):
    """The quick way of binding gives what inspect gives, and refuses what inspect refuses."""
    signature = inspect.signature(function)
    names = [p.name for p in signature.parameters.values() if p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]
    chosen = data.draw(st.lists(st.sampled_from(names + ['unknown']), unique=True, max_size=len(names) + 1))
    positional = data.draw(st.integers(0, len(chosen)))
    args = tuple(range(positional))
    kwargs = {name: index for index, name in enumerate(chosen[positional:], start=100)}
    try:
        expected = signature.bind(*args, **kwargs).arguments
    except TypeError:
        with pytest.raises(TypeError):
            binder(function, 'f', numpy._NoValue)(args, kwargs)
        return
    bound = binder(function, 'f', numpy._NoValue)(args, kwargs)
    flat: dict = {}
    for name, parameter in signature.parameters.items():
        if parameter.kind is parameter.VAR_KEYWORD:
            flat.update(expected.get(name, {}))
        elif name in expected:
            flat[name] = expected[name]
        elif parameter.kind is parameter.VAR_POSITIONAL:
            flat[name] = ()
        else:  # not given: its default, NumPy's "no value" read as None
            flat[name] = None if parameter.default is numpy._NoValue else parameter.default
    assert bound == flat


def test_every_size_rule_names_an_allowed_function(sandbox):
    allowed = set(NUMPY_FUNCTIONS) | set(NUMPY_LINALG) | set(NUMPY_RANDOM)
    assert set(sandbox._guards['SIZE_RULES']) <= allowed


def test_a_bad_call_is_the_programs_type_error(sandbox):
    with pytest.raises(TypeError, match=r'np\.linalg\.svd\(\).*matrix'):
        run(sandbox, 'x = np.linalg.svd(np.eye(2), matrix=True)')
    with pytest.raises(TypeError, match='multiple values'):
        run(sandbox, 'x = np.linalg.eig(np.eye(2), a=np.eye(2))')


def test_refusals_name_the_call_and_the_limit(sandbox):
    with pytest.raises(ResourceLimitError, match=r'np\.linalg\.eig on more than 250,000 elements'):
        run(sandbox, 'x = np.linalg.eig(a=M)', M=BIG_MATRIX)
    with pytest.raises(ResourceLimitError, match=r'np\.linalg\.svd would have 2,250,00\d elements'):
        run(sandbox, 'x = np.linalg.svd(np.ones((1, 1500)))')
    with pytest.raises(ResourceLimitError, match='int.from_bytes would be an integer of about 1,600,000 bits'):
        run(sandbox, "x = (5).from_bytes(b'ab' * 100000, 'big')")
    with pytest.raises(OperationRefused, match='signature'):
        run(sandbox, "x = np.sqrt(np.ones(3), signature='O->O')")
