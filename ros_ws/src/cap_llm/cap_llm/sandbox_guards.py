"""Checked versions of the operations generated code may use, and the wrappers around what it may call.

This file is not imported as a module by the engine: `cap_llm.sandbox` compiles its source under the sandbox's own
file name and executes it once per Sandbox with the names LIMITS (a SandboxLimits) and ResourceLimitError bound.
Compiled that way, every call into these helpers is seen by the sandbox's tracer, so the wall-clock limit and the
cancel request are checked each time generated code calls an operator, a NumPy function or a robot API function,
and inside the Python-level loops below (sum, join).

Each guard estimates the size of a result *before* the C-level work happens and raises ResourceLimitError when it
would exceed LIMITS; the message names the operation and the limit.
"""
import math
import operator
import re
import string

import numpy

from shapely.geometry.base import BaseGeometry

LIMITS = None  # bound by the sandbox
ResourceLimitError = None  # bound by the sandbox
OperationRefused = None  # bound by the sandbox

_SEQUENCES = (str, bytes, bytearray, list, tuple)
_ARRAYS = (numpy.ndarray, numpy.generic)


def refuse(what):
    raise ResourceLimitError(what)


def forbid(what):
    raise OperationRefused(what)


# ---------------------------------------------------------------------------------------------------- sizes
def _len_or_none(value):
    try:
        return len(value)
    except Exception:
        return None


def _array_size_estimate(value):
    """Element count numpy would make of `value` (nested lists are estimated from their first element)."""
    if isinstance(value, _ARRAYS):
        return int(value.size)
    if isinstance(value, (list, tuple)):
        if not value:
            return 0
        inner = _array_size_estimate(value[0])
        return len(value) * max(inner, 1)
    return 1


def check_elements(count, what):
    if count > LIMITS.max_array_elements:
        refuse(f'{what} would have {count:,} elements; the sandbox allows at most '
               f'{LIMITS.max_array_elements:,}')


def check_length(length, what):
    if length > LIMITS.max_sequence_length:
        refuse(f'{what} would have length {length:,}; the sandbox allows at most {LIMITS.max_sequence_length:,}')


def check_int_bits(bits, what):
    if bits > LIMITS.max_int_bits:
        refuse(f'{what} would be an integer of about {bits:,} bits; the sandbox allows at most '
               f'{LIMITS.max_int_bits:,}')


def _check_broadcast(a, b, what):
    if isinstance(a, _ARRAYS) or isinstance(b, _ARRAYS):
        shape_a = numpy.shape(a) if isinstance(a, (_ARRAYS, list, tuple)) else ()
        shape_b = numpy.shape(b) if isinstance(b, (_ARRAYS, list, tuple)) else ()
        try:
            shape = numpy.broadcast_shapes(shape_a, shape_b)
        except ValueError:
            return  # numpy raises its own clear error
        check_elements(math.prod(shape), what)


# ---------------------------------------------------------------------------------------------------- operators
def _repeat_check(a, b, what):
    """Sequence repetition (`'ab' * n`, `[0] * n`)."""
    if isinstance(a, _SEQUENCES) and isinstance(b, int):
        check_length(len(a) * max(b, 0), what)
    elif isinstance(b, _SEQUENCES) and isinstance(a, int):
        check_length(len(b) * max(a, 0), what)


def op_mult(a, b):
    if type(a) is int and type(b) is int:
        check_int_bits(a.bit_length() + b.bit_length(), 'this multiplication')
    else:
        _repeat_check(a, b, 'this repetition')
        _check_broadcast(a, b, 'this array product')
    return a * b


def op_imult(a, b):
    if type(a) is int and type(b) is int:
        check_int_bits(a.bit_length() + b.bit_length(), 'this multiplication')
    else:
        _repeat_check(a, b, 'this repetition')
        _check_broadcast(a, b, 'this array product')
    a *= b
    return a


def _pow_check(a, b):
    if isinstance(a, int) and isinstance(b, int) and b > 0 and abs(a) > 1:
        check_int_bits(int(b * math.log2(abs(a))) + 1, 'this power')
    _check_broadcast(a, b, 'this array power')


def op_pow(a, b):
    _pow_check(a, b)
    return a ** b


def op_ipow(a, b):
    _pow_check(a, b)
    a **= b
    return a


_MAX_MODULAR_BITS = 4096


def guarded_pow(base, exp, mod=None):
    if mod is None:
        _pow_check(base, exp)
        return pow(base, exp)
    if isinstance(exp, int) and isinstance(mod, int) and \
            max(abs(exp).bit_length(), abs(mod).bit_length()) > _MAX_MODULAR_BITS:
        refuse(f'pow() with a modulus or exponent over {_MAX_MODULAR_BITS} bits is not allowed in the sandbox')
    return pow(base, exp, mod)


def guarded_round(number, ndigits=None):
    """round(); an integer rounded to -n digits computes 10 ** n first, so n is bounded."""
    if ndigits is None:
        return round(number)
    if isinstance(ndigits, int) and abs(ndigits) > LIMITS.max_format_width:
        refuse(f'round() to {ndigits} digits is not allowed in the sandbox')
    return round(number, ndigits)


def _lshift_check(a, b):
    if isinstance(a, int) and isinstance(b, int) and a != 0:
        check_int_bits(a.bit_length() + max(b, 0), 'this left shift')
    _check_broadcast(a, b, 'this array shift')


def op_lshift(a, b):
    _lshift_check(a, b)
    return a << b


def op_ilshift(a, b):
    _lshift_check(a, b)
    a <<= b
    return a


def _concat_check(a, b):
    if isinstance(a, _SEQUENCES) and isinstance(b, _SEQUENCES):
        check_length(len(a) + len(b), 'this concatenation')
    else:
        _check_broadcast(a, b, 'this array sum')


def op_add(a, b):
    _concat_check(a, b)
    return a + b


def op_iadd(a, b):
    _concat_check(a, b)
    a += b
    return a


_PERCENT_FIELD = re.compile(r'%(?:\([^)]*\))?[-#0 +]*(\*|\d+)?(?:\.(\*|\d+))?')


def _check_percent_format(template):
    text = template.decode('latin-1') if isinstance(template, (bytes, bytearray)) else template
    for width, precision in _PERCENT_FIELD.findall(text):
        for number in (width, precision):
            if number == '*':
                forbid("'%' formatting with a '*' width is not allowed in the sandbox")
            if number and int(number) > LIMITS.max_format_width:
                refuse(f"'%' formatting width {number} exceeds the sandbox's {LIMITS.max_format_width}")


def op_mod(a, b):
    if isinstance(a, (str, bytes, bytearray)):
        _check_percent_format(a)
    else:
        _check_broadcast(a, b, 'this array remainder')
    return a % b


def op_imod(a, b):
    if isinstance(a, (str, bytes, bytearray)):
        _check_percent_format(a)
    else:
        _check_broadcast(a, b, 'this array remainder')
    a %= b
    return a


def _make_array_op(function, name):
    def checked(a, b):
        _check_broadcast(a, b, f'this array {name}')
        return function(a, b)
    return checked


op_sub = _make_array_op(operator.sub, 'difference')
op_isub = _make_array_op(operator.isub, 'difference')
op_truediv = _make_array_op(operator.truediv, 'quotient')
op_itruediv = _make_array_op(operator.itruediv, 'quotient')
op_floordiv = _make_array_op(operator.floordiv, 'quotient')
op_ifloordiv = _make_array_op(operator.ifloordiv, 'quotient')
op_rshift = _make_array_op(operator.rshift, 'shift')
op_irshift = _make_array_op(operator.irshift, 'shift')
op_and = _make_array_op(operator.and_, 'bitwise and')
op_iand = _make_array_op(operator.iand, 'bitwise and')
op_or = _make_array_op(operator.or_, 'bitwise or')
op_ior = _make_array_op(operator.ior, 'bitwise or')
op_xor = _make_array_op(operator.xor, 'bitwise xor')
op_ixor = _make_array_op(operator.ixor, 'bitwise xor')
cmp_eq = _make_array_op(operator.eq, 'comparison')
cmp_ne = _make_array_op(operator.ne, 'comparison')
cmp_lt = _make_array_op(operator.lt, 'comparison')
cmp_le = _make_array_op(operator.le, 'comparison')
cmp_gt = _make_array_op(operator.gt, 'comparison')
cmp_ge = _make_array_op(operator.ge, 'comparison')


def _matmul_check(a, b):
    if isinstance(a, _ARRAYS) and isinstance(b, _ARRAYS) and a.ndim and b.ndim:
        rows = a.size // max(a.shape[-1], 1)
        cols = b.shape[-1] if b.ndim > 1 else 1
        check_elements(rows * cols, 'this matrix product')


def op_matmult(a, b):
    _matmul_check(a, b)
    return a @ b


def op_imatmult(a, b):
    _matmul_check(a, b)
    a @= b
    return a


def tick():
    """Called at the top of every loop body of generated code: the tracer checks limits on each call."""


def augmented_item(container, key, inplace_op, value):
    """`container[key] op= value` with container and key evaluated once."""
    container[key] = inplace_op(container[key], value)


# ---------------------------------------------------------------------------------------------------- builtins
def guarded_range(*args):
    span = range(*args)
    try:
        length = len(span)
    except OverflowError:
        length = LIMITS.max_sequence_length + 1
    check_length(length, 'this range')
    return span


def guarded_iter(*args):
    """iter() with one argument only: iter(callable, sentinel) can loop forever in C."""
    if len(args) != 1:
        forbid('iter() takes exactly one argument in the sandbox (iter(callable, sentinel) is not available)')
    return iter(args[0])


def guarded_sum(iterable, start=0):
    """sum() as a Python loop of checked additions: C-level sum of lists or arrays is neither bounded nor stoppable."""
    total = start
    for item in iterable:
        total = op_add(total, item)
    return total


# ---------------------------------------------------------------------------------------------------- methods
_FORMATTER = string.Formatter()


def _check_format_spec(spec, what):
    if '{' in spec:
        forbid(f'{what}: nested format fields are not allowed in the sandbox')
    for number in re.findall(r'\d+', spec):
        if int(number) > LIMITS.max_format_width:
            refuse(f'{what}: width {number} exceeds the sandbox limit of {LIMITS.max_format_width}')


def check_format_template(template):
    """str.format templates may name fields by position or keyword only: no `.attr` or `[key]` lookups."""
    for _literal, field, spec, _conversion in _FORMATTER.parse(template):
        if field is None:
            continue
        if '.' in field or '[' in field:
            forbid(f'format field {{{field}}} looks up an attribute or item; the sandbox allows plain fields only')
        if spec:
            _check_format_spec(spec, 'str.format')


def _string_method(obj, name):
    method = getattr(obj, name)
    if name in ('ljust', 'rjust', 'center', 'zfill'):
        def padded(width, *rest):
            check_length(width, f'str.{name}')
            return method(width, *rest)
        return padded
    if name == 'expandtabs':
        def expandtabs(tabsize=8):
            check_length(len(obj) + obj.count('\t' if isinstance(obj, str) else b'\t') * max(tabsize, 0),
                         'str.expandtabs')
            return method(tabsize)
        return expandtabs
    if name == 'replace':
        def replace(old, new, count=-1):
            hits = len(obj) + 1 if not old else obj.count(old)
            if count >= 0:
                hits = min(hits, count)
            check_length(len(obj) + hits * len(new), 'str.replace')
            return method(old, new, count)
        return replace
    if name == 'join':
        def join(iterable):
            parts = list(iterable)
            total = len(obj) * max(len(parts) - 1, 0)
            for part in parts:
                total += _len_or_none(part) or 0
            check_length(total, 'str.join')
            return method(parts)
        return join
    if name == 'format':
        def format_(*args, **kwargs):
            check_format_template(obj)
            return method(*args, **kwargs)
        return format_
    if name in ('format_map', 'translate', 'maketrans'):
        forbid(f'str.{name} is not available in the sandbox')
    return method


def _list_method(obj, name):
    method = getattr(obj, name)
    if name == 'extend':
        def extend(iterable):
            size = _len_or_none(iterable)
            if size is not None:
                check_length(len(obj) + size, 'list.extend')
            return method(iterable)
        return extend
    return method


def _array_method(obj, name):
    method = getattr(obj, name)
    if name == 'repeat':
        def repeat(repeats, *rest, **kwargs):
            check_elements(obj.size * int(numpy.max(repeats)) if numpy.size(repeats) else 0, 'ndarray.repeat')
            return method(repeats, *rest, **kwargs)
        return repeat
    if name == 'resize':
        def resize(*shape, **kwargs):
            dims = shape[0] if len(shape) == 1 and isinstance(shape[0], (tuple, list)) else shape
            check_elements(math.prod(int(d) for d in dims), 'ndarray.resize')
            return method(*shape, **kwargs)
        return resize
    if name in ('dot', 'outer'):
        def product(other, *rest, **kwargs):
            _matmul_check(obj, numpy.asarray(other))
            return method(other, *rest, **kwargs)
        return product
    return method


_MAX_QUAD_SEGS = 64


def _geometry_method(obj, name):
    method = getattr(obj, name)
    if name in ('buffer', 'offset_curve', 'parallel_offset'):
        def buffered(distance, *args, **kwargs):
            candidates = [kwargs.get('quad_segs'), kwargs.get('resolution')] + list(args)
            segments = max([int(c) for c in candidates if isinstance(c, (int, float)) and not isinstance(c, bool)],
                           default=0)
            if segments > _MAX_QUAD_SEGS:
                refuse(f'{name} with {segments} segments per quarter circle; the sandbox allows {_MAX_QUAD_SEGS}')
            return method(distance, *args, **kwargs)
        return buffered
    if name == 'segmentize':
        def segmentize(max_segment_length):
            if max_segment_length <= 0:
                forbid('segmentize needs a positive segment length')
            check_elements(int(obj.length / max_segment_length) + len(obj.bounds), 'segmentize')
            return method(max_segment_length)
        return segmentize
    return method


_REFUSED_ON_TYPES = frozenset(('format', 'format_map', 'ljust', 'rjust', 'center', 'zfill', 'expandtabs',
                               'replace', 'join', 'translate', 'maketrans', 'extend', 'repeat', 'resize',
                               'buffer', 'segmentize', 'to_bytes', 'from_bytes'))


def guarded_getattr(obj, name):
    """Attribute reads of generated code. Names were screened by the AST check; this adds checks on values."""
    if isinstance(obj, type):
        if name in _REFUSED_ON_TYPES:
            forbid(f'{obj.__name__}.{name} cannot be used unbound in the sandbox; call it on a value')
        return getattr(obj, name)
    if isinstance(obj, (str, bytes, bytearray)):
        return _string_method(obj, name)
    if isinstance(obj, list):
        return _list_method(obj, name)
    if isinstance(obj, numpy.ndarray):
        return _array_method(obj, name)
    if isinstance(obj, BaseGeometry):
        return _geometry_method(obj, name)
    if isinstance(obj, int) and name == 'to_bytes':
        def to_bytes(length=1, *args, **kwargs):
            check_length(length, 'int.to_bytes')
            return obj.to_bytes(length, *args, **kwargs)
        return to_bytes
    return getattr(obj, name)


# ---------------------------------------------------------------------------------------------------- wrappers
def wrap_callable(function):
    """A plain function that calls `function`: generated code sees no attributes of what it wraps."""
    def call(*args, **kwargs):
        return function(*args, **kwargs)
    return call


def _shape_count(shape):
    if isinstance(shape, (int, numpy.integer)):
        return int(shape)
    return math.prod(int(d) for d in shape)


def _rule_shape(args, kwargs):
    shape = kwargs.get('shape', args[0] if args else 0)
    return _shape_count(shape)


def _rule_shape_args(args, kwargs):
    """np.random.rand(2, 3) style: every positional argument is a dimension."""
    return math.prod(int(d) for d in args) if args else 1


def _rule_size_kw(args, kwargs, position=None):
    size = kwargs.get('size')
    if size is None and position is not None and len(args) > position:
        size = args[position]
    return 1 if size is None else _shape_count(size)


def _rule_arange(args, kwargs):
    values = list(args) + [kwargs[k] for k in ('start', 'stop', 'step') if k in kwargs]
    start, stop, step = 0, None, 1
    if len(values) == 1:
        stop = values[0]
    elif len(values) == 2:
        start, stop = values
    elif len(values) >= 3:
        start, stop, step = values[:3]
    if stop is None or step == 0:
        return 0
    return max(int(math.ceil((float(stop) - float(start)) / float(step))), 0)


def _rule_linspace(args, kwargs):
    return int(kwargs.get('num', args[2] if len(args) > 2 else 50))


def _rule_eye(args, kwargs):
    rows = int(kwargs.get('N', args[0] if args else 1))
    cols = kwargs.get('M', args[1] if len(args) > 1 else None)
    return rows * (rows if cols is None else int(cols))


def _rule_input(args, kwargs):
    return _array_size_estimate(args[0]) if args else 0


def _rule_join(args, kwargs):
    seq = args[0] if args else kwargs.get('arrays', ())
    return sum(_array_size_estimate(item) for item in seq)


def _rule_outer(args, kwargs):
    return _array_size_estimate(args[0]) * _array_size_estimate(args[1]) if len(args) > 1 else 0


def _rule_tile(args, kwargs):
    reps = args[1] if len(args) > 1 else kwargs.get('reps', 1)
    return _array_size_estimate(args[0]) * _shape_count(reps)


def _rule_repeat(args, kwargs):
    repeats = args[1] if len(args) > 1 else kwargs.get('repeats', 1)
    return _array_size_estimate(args[0]) * int(numpy.max(repeats) if numpy.size(repeats) else 0)


def _rule_meshgrid(args, kwargs):
    return math.prod(_array_size_estimate(a) for a in args) * max(len(args), 1)


def _rule_matmul(args, kwargs):
    if len(args) > 1:
        _matmul_check(numpy.asarray(args[0]), numpy.asarray(args[1]))
    return 0


def _rule_choice(args, kwargs):
    return _rule_size_kw(args, kwargs, position=1)


def _rule_uniform(args, kwargs):
    return _rule_size_kw(args, kwargs, position=2)


def _rule_randint(args, kwargs):
    return _rule_size_kw(args, kwargs, position=2)


SIZE_RULES = {
    'zeros': _rule_shape, 'ones': _rule_shape, 'empty': _rule_shape, 'full': _rule_shape,
    'arange': _rule_arange, 'linspace': _rule_linspace, 'eye': _rule_eye, 'identity': _rule_eye,
    'array': _rule_input, 'asarray': _rule_input,
    'concatenate': _rule_join, 'stack': _rule_join, 'vstack': _rule_join, 'hstack': _rule_join,
    'column_stack': _rule_join,
    'outer': _rule_outer, 'kron': _rule_outer, 'tile': _rule_tile, 'repeat': _rule_repeat,
    'meshgrid': _rule_meshgrid, 'dot': _rule_matmul, 'matmul': _rule_matmul,
    'rand': _rule_shape_args, 'randn': _rule_shape_args, 'random': _rule_size_kw, 'normal': _rule_uniform,
    'uniform': _rule_uniform, 'randint': _rule_randint, 'choice': _rule_choice,
}


# Cubic-time linear algebra: inputs are kept small so a single call stays well under a second.
MATRIX_FUNCTIONS = frozenset({'inv', 'det', 'solve', 'pinv', 'eig', 'svd'})
MAX_MATRIX_ELEMENTS = 250_000


def wrap_numpy_function(name, function):
    """NumPy function for generated code: result size checked before the call; array arguments broadcast-checked."""
    rule = SIZE_RULES.get(name)
    cubic = name in MATRIX_FUNCTIONS

    def call(*args, **kwargs):
        if cubic and args and _array_size_estimate(args[0]) > MAX_MATRIX_ELEMENTS:
            refuse(f'np.linalg.{name} on more than {MAX_MATRIX_ELEMENTS:,} elements is not allowed in the sandbox')
        if rule is not None:
            check_elements(rule(args, kwargs), f'np.{name}')
        arrays = [a for a in args if isinstance(a, _ARRAYS)]
        if len(arrays) >= 2 and rule is None:
            try:
                shape = numpy.broadcast_shapes(*(a.shape for a in arrays))
                check_elements(math.prod(shape), f'np.{name}')
            except ValueError:
                pass
        return function(*args, **kwargs)
    return call


def wrap_geometry_function(name, function):
    """Shapely constructors and functions: coordinate lists are bounded like sequences."""
    def call(*args, **kwargs):
        for arg in args:
            size = _len_or_none(arg) if not isinstance(arg, (str, bytes)) else None
            if size is not None:
                check_length(size, name)
        return function(*args, **kwargs)
    return call
