"""Checked versions of the operations generated code may use, and the wrappers around what it may call.

This file is not imported as a module by the engine: `cap_lmp.sandbox` compiles its source under the sandbox's own
file name and executes it once per Sandbox with the names LIMITS (a SandboxLimits), ResourceLimitError,
OperationRefused and checkpoint bound. Compiled that way, every call into these helpers is seen by the sandbox's
tracer, so the wall-clock limit and the cancel request are checked each time generated code calls an operator, a
NumPy function or a robot API function, and inside the Python-level loops below (sum, extend, the iteration
generators). `tick` and wrapped calls also call `checkpoint` explicitly, which works even when the trace function
was removed.

Each guard estimates the size of a result *before* the C-level work happens and raises ResourceLimitError when it
would exceed LIMITS; the message names the operation and the limit.
"""
import functools
import itertools
import math
import operator
import re
import string
from sys import gettrace as _gettrace

import numpy

import shapely
from shapely.geometry.base import BaseGeometry

from cap_lmp.sandbox.binding import binder

LIMITS = None  # bound by the sandbox
ResourceLimitError = None  # bound by the sandbox
OperationRefused = None  # bound by the sandbox
checkpoint = None  # bound by the sandbox: deadline, cancel and tracer check of the run on this thread

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


_MAX_NESTING = 32  # of nested lists a shape estimate follows (deeper values are numpy's own error)


def _shape_estimate(value):
    """The shape numpy would make of `value`: nested lists are estimated from their first element."""
    dims = []
    for _level in range(_MAX_NESTING):
        if isinstance(value, _ARRAYS):
            dims.extend(value.shape)
            break
        if not isinstance(value, (list, tuple, range)):
            break
        dims.append(len(value))
        if not value:
            break
        value = value[0]
    return tuple(dims)


def _array_size_estimate(value):
    """Element count numpy would make of `value` (nested lists are estimated from their first element; an empty
    inner list counts as one element, the work of visiting it)."""
    if isinstance(value, _ARRAYS):
        return int(value.size)
    shape = _shape_estimate(value)
    if not shape or not shape[0]:
        return 0 if shape else 1
    return math.prod(max(d, 1) for d in shape)


def check_dtype(value, what):
    """Object, string, void and subarray dtypes: unbounded per-element work or size, or raw memory reinterpretation."""
    if value is None:
        return
    try:
        dtype = numpy.dtype(value)
    except Exception:
        return  # not a dtype: numpy reports its own error
    if dtype.kind in 'OUSV' or dtype.subdtype is not None or dtype.fields is not None:
        forbid(f'{what}: the dtype {value!r} (objects, strings or raw records) is not available in the sandbox')


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
        if getattr(a, 'dtype', None) == object or getattr(b, 'dtype', None) == object:  # noqa: E721 (a dtype)
            forbid(f'{what} on an object array is not available in the sandbox (its elements grow without bound)')
        # Shapes estimated, not converted: numpy.shape of a nested list builds the array it would check.
        shape_a, shape_b = _shape_estimate(a), _shape_estimate(b)
        try:
            shape = numpy.broadcast_shapes(shape_a, shape_b)
        except ValueError:
            return  # numpy raises its own clear error
        check_elements(math.prod(shape), what)


# ---------------------------------------------------------------------------------------------------- operators
_INTEGERS = (int, numpy.integer)
# Operands of these types alone make a result of one element: only integer sizes need a check. The operators below
# decide that in their first line, with no further call: each line of this file costs a trace event.
_SCALARS = frozenset({int, float, bool, complex, numpy.float64, numpy.float32, numpy.int64, numpy.int32,
                      numpy.bool_})


# Integers: every way a program makes one (literals, int(), int.from_bytes, +, -, *, **, <<, pow) keeps it within
# LIMITS.max_int_bits, and the operations whose cost grows faster than their operands' size (*, //, %, divmod, pow,
# round) refuse operands beyond it, wherever they came from. NumPy integers are fixed-width; bool is an int.
def check_int_operands(a, b, extra_bits, what):
    """Both integers within the limit, and a result of at most the larger one plus `extra_bits` bits."""
    check_int_bits(max(a.bit_length(), b.bit_length()) + extra_bits, what)


def _repeat_check(a, b, what):
    """Sequence repetition (`'ab' * n`, `[0] * n`, also with a NumPy integer count)."""
    if isinstance(a, _SEQUENCES) and isinstance(b, _INTEGERS):
        check_length(len(a) * max(operator.index(b), 0), what)
    elif isinstance(b, _SEQUENCES) and isinstance(a, _INTEGERS):
        check_length(len(b) * max(operator.index(a), 0), what)


def _mult_check(a, b):
    if isinstance(a, int) and isinstance(b, int):
        check_int_bits(a.bit_length() + b.bit_length(), 'this multiplication')
    else:
        _repeat_check(a, b, 'this repetition')
        _check_broadcast(a, b, 'this array product')


def op_mult(a, b):
    if type(a) not in _SCALARS or type(b) not in _SCALARS or isinstance(a, int) and isinstance(b, int):
        _mult_check(a, b)
    return a * b


def op_imult(a, b):
    if type(a) not in _SCALARS or type(b) not in _SCALARS or isinstance(a, int) and isinstance(b, int):
        _mult_check(a, b)
    a *= b
    return a


def _pow_check(a, b):
    if isinstance(a, int) and isinstance(b, int):
        check_int_bits(a.bit_length(), 'this power')
        if b > 0 and abs(a) > 1:
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
    if isinstance(exp, int) and isinstance(mod, int):
        if max(abs(exp).bit_length(), abs(mod).bit_length()) > _MAX_MODULAR_BITS:
            refuse(f'pow() with a modulus or exponent over {_MAX_MODULAR_BITS} bits is not allowed in the sandbox')
        if isinstance(base, int):
            check_int_bits(base.bit_length(), 'pow()')
    return pow(base, exp, mod)


def _index_or_none(value):
    """The integer value Python would use for `value` as a count or index (NumPy integers too), or None."""
    try:
        return operator.index(value)
    except TypeError:
        return None


def guarded_round(number, ndigits=None):
    """round(); an integer rounded to -n digits computes 10 ** n first, so n is bounded (also as a NumPy integer,
    which round() reads through its index)."""
    if ndigits is None:
        return round(number)
    digits = _index_or_none(ndigits)
    if digits is not None and abs(digits) > LIMITS.max_format_width:
        refuse(f'round() to {digits} digits is not allowed in the sandbox')
    if isinstance(number, int):
        check_int_bits(number.bit_length(), 'round()')
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


def _sum_check(a, b, what):
    if isinstance(a, int) and isinstance(b, int):
        check_int_operands(a, b, 1, f'this integer {what}')
    elif isinstance(a, _SEQUENCES) and isinstance(b, _SEQUENCES):
        check_length(len(a) + len(b), 'this concatenation')
    else:
        _check_broadcast(a, b, f'this array {what}')


def _large_ints(a, b):
    """Both are integers, one of them near the limit (the rest of a check is skipped for the usual small ones)."""
    return isinstance(a, int) and isinstance(b, int) and \
        max(a.bit_length(), b.bit_length()) >= LIMITS.max_int_bits - 1


def op_add(a, b):
    if type(a) not in _SCALARS or type(b) not in _SCALARS or _large_ints(a, b):
        _sum_check(a, b, 'sum')
    return a + b


def op_iadd(a, b):
    if type(a) is list and not isinstance(b, _SEQUENCES):
        checked_extend(a, b, 'this in-place concatenation')
        return a
    if type(a) not in _SCALARS or type(b) not in _SCALARS or _large_ints(a, b):
        _sum_check(a, b, 'sum')
    a += b
    return a


def op_sub(a, b):
    if type(a) not in _SCALARS or type(b) not in _SCALARS or _large_ints(a, b):
        _sum_check(a, b, 'difference')
    return a - b


def op_isub(a, b):
    if type(a) not in _SCALARS or type(b) not in _SCALARS or _large_ints(a, b):
        _sum_check(a, b, 'difference')
    a -= b
    return a


def _quotient_check(a, b, what):
    if isinstance(a, int) and isinstance(b, int):
        check_int_operands(a, b, 0, f'this integer {what}')
    else:
        _check_broadcast(a, b, f'this array {what}')


def op_floordiv(a, b):
    if type(a) not in _SCALARS or type(b) not in _SCALARS or _large_ints(a, b):
        _quotient_check(a, b, 'quotient')
    return a // b


def op_ifloordiv(a, b):
    if type(a) not in _SCALARS or type(b) not in _SCALARS or _large_ints(a, b):
        _quotient_check(a, b, 'quotient')
    a //= b
    return a


def guarded_divmod(a, b):
    """divmod(): quadratic in its integers' size, like // and %."""
    if type(a) not in _SCALARS or type(b) not in _SCALARS or _large_ints(a, b):
        _quotient_check(a, b, 'divmod')
    return divmod(a, b)


_PERCENT_FIELD = re.compile(r'%(?:\([^)]*\))?[-#0 +]*(\*|\d+)?(?:\.(\*|\d+))?')


# The template checks below work on whole lists with C-level map/filter/join: a template may hold hundreds of
# thousands of fields, and a traced Python loop over them would spend the time limit on the check itself.
_FIRST = operator.itemgetter(0)
_SECOND = operator.itemgetter(1)
_THIRD = operator.itemgetter(2)


def _numbers_in(texts):
    """The integers written in `texts` (format specs, widths), as ints."""
    return list(map(int, re.findall(r'\d+', '\x00'.join(texts))))


def _text_length(value):
    return len(value) if isinstance(value, (str, bytes, bytearray)) else 0


_TEXT_TESTS = tuple(functools.partial(type.__instancecheck__, kind) for kind in (str, bytes, bytearray))
_IS_NOT_NONE = functools.partial(operator.is_not, None)


def _text_lengths(values):
    """Lengths of the text values among `values`, computed in C."""
    return list(itertools.chain.from_iterable(map(len, filter(test, values)) for test in _TEXT_TESTS))


def _percent_fields(template):
    text = template.decode('latin-1') if isinstance(template, (bytes, bytearray)) else template
    return _PERCENT_FIELD.findall(text)


def _check_percent_format(template):
    found = _percent_fields(template)
    numbers = list(filter(None, itertools.chain(map(_FIRST, found), map(_SECOND, found))))
    if '*' in numbers:
        forbid("'%' formatting with a '*' width is not allowed in the sandbox")
    widest = max(map(int, numbers), default=0)
    if widest > LIMITS.max_format_width:
        refuse(f"'%' formatting width {widest} exceeds the sandbox's {LIMITS.max_format_width}")


def _check_percent_output(template, values):
    """Output length of `template % values`: the template, every width, and the text arguments (each used once,
    or every field may use the longest when fields name keys of a mapping)."""
    found = _percent_fields(template)
    padding = sum(_numbers_in(itertools.chain(map(_FIRST, found), map(_SECOND, found))))
    if isinstance(values, tuple):
        extra = sum(_text_lengths(values[:len(found)]))
    elif isinstance(values, dict):
        extra = len(found) * max(_text_lengths(values.values()), default=0)
    else:
        extra = _text_length(values)
    check_length(len(template) + extra + padding, "this '%' formatting")


def _mod_check(a, b):
    if isinstance(a, (str, bytes, bytearray)):
        _check_percent_format(a)
        _check_percent_output(a, b)
    else:
        _quotient_check(a, b, 'remainder')


def op_mod(a, b):
    if type(a) not in _SCALARS or type(b) not in _SCALARS or _large_ints(a, b):
        _mod_check(a, b)
    return a % b


def op_imod(a, b):
    if type(a) not in _SCALARS or type(b) not in _SCALARS or _large_ints(a, b):
        _mod_check(a, b)
    a %= b
    return a


def _make_array_op(function, name):
    def checked(a, b):
        _check_broadcast(a, b, f'this array {name}')
        return function(a, b)
    return checked


op_truediv = _make_array_op(operator.truediv, 'quotient')
op_itruediv = _make_array_op(operator.itruediv, 'quotient')
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
    """Elements of a @ b (batch dimensions broadcast) or np.dot(a, b), whichever is larger; lists count with the
    shape they convert to (estimated, not converted)."""
    shape_a, shape_b = _shape_estimate(a), _shape_estimate(b)
    check_elements(math.prod(shape_a), 'this matrix product')
    check_elements(math.prod(shape_b), 'this matrix product')
    if shape_a and shape_b:
        dot = math.prod(shape_a[:-1]) * (math.prod(shape_b[:-2]) * shape_b[-1] if len(shape_b) > 1 else 1)
        matmul = 0
        if len(shape_a) > 1 and len(shape_b) > 1:
            try:
                batch = math.prod(numpy.broadcast_shapes(shape_a[:-2], shape_b[:-2]))
            except ValueError:
                batch = 0  # numpy raises its own error
            matmul = batch * shape_a[-2] * shape_b[-1]
        check_elements(max(dot, matmul), 'this matrix product')


def op_matmult(a, b):
    _matmul_check(a, b)
    return a @ b


def op_imatmult(a, b):
    _matmul_check(a, b)
    a @= b
    return a


def tick():
    """Called at the top of every loop body of generated code: the tracer checks limits on each call; when the
    trace function was removed (a stop swallowed by a generator finalizer) the explicit checkpoint raises."""
    if _gettrace() is None:
        checkpoint()


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


# int() and int.from_bytes: the size of the integer is known from the text or bytes before it is made (a string in a
# power-of-two base converts in linear time without CPython's digit limit: int('1' * 10 ** 6, 2) is a million bits).
def _text_bits(text, base):
    """An upper bound of the bits of int(text, base): at most log2(base) bits per character (base 0 reads a prefix:
    hexadecimal is the most per character)."""
    base = _index_or_none(base)
    if base is None or not 0 <= base <= 36 or base == 1:
        return 0  # int() raises its own error
    return math.ceil(len(text) * math.log2(base or 16))


class _IntegerType(type):
    """The metaclass of the program's `int`: isinstance and issubclass answer for the real int."""

    def __instancecheck__(cls, value):
        return isinstance(value, int)

    def __subclasscheck__(cls, kind):
        return issubclass(kind, int)


class checked_int(int, metaclass=_IntegerType):
    """`int` as a program sees it: a checked constructor whose values are real ints. It is a subclass so that
    `case int(x):`, `isinstance(x, int)`, `int | None` and `int.bit_length` keep their meaning, and NumPy reads
    `dtype=int` as it reads the real int."""

    dtype = numpy.dtype(int)

    def __new__(cls, *args, **kwargs):
        if args and isinstance(args[0], (str, bytes, bytearray)):
            base = args[1] if len(args) > 1 else kwargs.get('base', 10)
            check_int_bits(_text_bits(args[0], base), 'int() of this text')
        return int(*args, **kwargs)


checked_int.__name__ = checked_int.__qualname__ = 'int'
checked_int.__module__ = 'builtins'


def _checked_from_bytes(from_bytes):
    """int.from_bytes, called on the class or on a value: the integer has eight bits per byte."""
    def checked(bytes, byteorder='big', *, signed=False):
        size = _len_or_none(bytes)
        if size is None:
            bytes = list(bytes)
            size = len(bytes)
        check_int_bits(8 * size, 'int.from_bytes')
        return from_bytes(bytes, byteorder, signed=signed)
    return checked


# map, filter, zip, enumerate and reversed as Python generators: their frames are traced, so an endless chain
# (any(map(x.append, x))) meets the time limit and a deep nesting meets max_call_depth instead of the C stack.
def _map(function, iterators):
    if len(iterators) == 1:
        for item in iterators[0]:
            yield function(item)
    else:
        for items in _zip(iterators, False):
            yield function(*items)


def guarded_map(function, iterable, *iterables):
    return _map(function, [iter(iterable)] + [iter(more) for more in iterables])


def _filter(function, iterator):
    for item in iterator:
        if (item if function is None else function(item)):
            yield item


def guarded_filter(function, iterable):
    return _filter(function, iter(iterable))


def _zip(iterators, strict):
    if not iterators:
        return
    while True:
        items = []
        for index, iterator in enumerate(iterators):
            try:
                items.append(next(iterator))
            except StopIteration:
                if strict and (index or _any_left(iterators[1:])):
                    raise ValueError('zip() arguments have different lengths') from None
                return
        yield tuple(items)


def _any_left(iterators):
    for iterator in iterators:
        for _item in iterator:
            return True
    return False


def guarded_zip(*iterables, strict=False):
    return _zip([iter(iterable) for iterable in iterables], strict)


def _enumerate(iterator, start):
    index = start
    for item in iterator:
        yield index, item
        index += 1


def guarded_enumerate(iterable, start=0):
    return _enumerate(iter(iterable), operator.index(start))


def _each(iterator):
    for item in iterator:
        yield item


def guarded_reversed(sequence):
    return _each(reversed(sequence))


def checked_extend(target, iterable, what):
    """list.extend / += of an iterable without a length: a checked Python loop (the iterable may be the list's
    own iterator, which never ends in C)."""
    size = _len_or_none(iterable)
    if size is not None:
        check_length(len(target) + size, what)
        target.extend(iterable)
        return
    append = target.append
    for item in iterable:
        append(item)
        if len(target) > LIMITS.max_sequence_length:
            check_length(len(target), what)


_COMPARED = frozenset((list, tuple))
_IS_COMPARED = tuple(functools.partial(type.__instancecheck__, kind) for kind in _COMPARED)


def _check_comparisons(items, comparisons, what):
    """Comparing two lists or tuples visits their elements, also when both are one object (`[row] * 20000`):
    comparisons times the largest item is the C work a sort, min or max would do."""
    if _COMPARED.isdisjoint(set(map(type, items))):
        return  # numbers, texts: the usual case, decided in C
    containers = list(itertools.chain.from_iterable(filter(test, items) for test in _IS_COMPARED))
    distinct = dict(zip(map(id, containers), containers)).values()  # aliased items are estimated once, in C
    largest = max(map(_array_size_estimate, distinct), default=1)
    if comparisons * largest > 100 * LIMITS.max_sequence_length:
        refuse(f'{what} would compare {comparisons:,} times items of up to {largest:,} elements; the sandbox allows '
               f'at most {100 * LIMITS.max_sequence_length:,} element comparisons')


def _sort_keys(items, key):
    return items if key is None else list(map(key, items))


def guarded_sorted(iterable, *, key=None, reverse=False):
    items = list(iterable)
    keys = _sort_keys(items, key)
    _check_comparisons(keys, len(keys) * max(len(keys).bit_length(), 1), 'sorted()')
    if key is None:
        return sorted(items, reverse=reverse)
    order = sorted(range(len(items)), key=keys.__getitem__, reverse=reverse)  # keys computed once, as sorted does
    return [items[index] for index in order]


def _extreme(builtin, what):
    def extreme(*args, key=None, **options):
        items = list(args[0]) if len(args) == 1 else list(args)
        keys = _sort_keys(items, key)
        _check_comparisons(keys, len(keys), what)
        if key is None:
            return builtin(items, **options)
        if not items:
            return builtin(items, **options)  # the default, or builtin's own error
        return items[builtin(range(len(items)), key=keys.__getitem__)]
    return extreme


guarded_min = _extreme(min, 'min()')
guarded_max = _extreme(max, 'max()')


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


def check_format_template(template, args=(), kwargs=None):
    """str.format templates may name fields by position or keyword only: no `.attr` or `[key]` lookups.
    The output length is bounded too: the template, every number in the specs, and for each field the longest
    text argument (an upper bound: fields may repeat an argument)."""
    parsed = list(_FORMATTER.parse(template))
    fields = list(filter(_IS_NOT_NONE, map(_SECOND, parsed)))
    names = '\x00'.join(fields)
    if '.' in names or '[' in names:
        forbid('format fields that look up an attribute or item (`{0.name}`, `{0[key]}`) are not allowed; the '
               'sandbox allows plain fields only')
    specs = list(filter(None, map(_THIRD, parsed)))
    if '{' in '\x00'.join(specs):
        forbid('str.format: nested format fields are not allowed in the sandbox')
    numbers = _numbers_in(specs)
    widest = max(numbers, default=0)
    if widest > LIMITS.max_format_width:
        refuse(f'str.format: width {widest} exceeds the sandbox limit of {LIMITS.max_format_width}')
    longest = max(_text_lengths(itertools.chain(args, (kwargs or {}).values())), default=0)
    check_length(len(template) + sum(numbers) + len(fields) * longest, 'str.format')


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
            parts = iterable if isinstance(iterable, (list, tuple)) else list(iterable)
            # the parts' lengths summed in C (a traced loop over a million parts would spend the time limit);
            # what is not text makes join raise its own TypeError
            total = len(obj) * max(len(parts) - 1, 0) + sum(_text_lengths(parts))
            check_length(total, 'str.join')
            return method(parts)
        return join
    if name == 'format':
        def format_(*args, **kwargs):
            check_format_template(obj, args, kwargs)
            return method(*args, **kwargs)
        return format_
    if name in ('format_map', 'translate', 'maketrans'):
        forbid(f'str.{name} is not available in the sandbox')
    return method


def _list_method(obj, name):
    method = getattr(obj, name)
    if name == 'extend':
        def extend(iterable):
            checked_extend(obj, iterable, 'list.extend')
        return extend
    if name == 'sort':
        def sort(*, key=None, reverse=False):
            obj[:] = guarded_sorted(obj, key=key, reverse=reverse)
        return sort
    return method


def _array_method(obj, name):
    method = getattr(obj, name)
    if name == 'repeat':
        def repeat(repeats, *rest, **kwargs):
            axis = rest[0] if rest else kwargs.get('axis')
            check_elements(repeat_elements(obj, repeats, axis), 'ndarray.repeat')
            return method(repeats, *rest, **kwargs)
        return repeat
    if name == 'resize':
        def resize(*shape, **kwargs):
            if kwargs:  # refcheck=False frees memory that views still use
                forbid('ndarray.resize takes no keyword arguments in the sandbox')
            dims = shape[0] if len(shape) == 1 and isinstance(shape[0], (tuple, list)) else shape
            check_elements(math.prod(operator.index(d) for d in dims), 'ndarray.resize')
            return method(*shape)
        return resize
    if name in ('astype', 'view'):
        def converted(*args, **kwargs):
            for value in args[:1] + tuple(kwargs.get(key) for key in ('dtype', 'type')):
                check_dtype(value, f'ndarray.{name}')
            if name == 'view' and (len(args) > 1 or kwargs.get('type') is not None):  # view(dtype, type)
                forbid('ndarray.view(type=...) is not available in the sandbox')
            return method(*args, **kwargs)
        return converted
    if name == 'dot':
        def dot(b, out=None):
            _matmul_check(obj, b)
            return method(b, out)
        return dot
    return method


_MAX_QUAD_SEGS = 64


def _segment_count(value):
    if isinstance(value, (float, numpy.floating)):
        return int(value)
    if isinstance(value, bool):
        return 0
    return operator.index(value)


def _geometry_method(obj, name):
    method = getattr(obj, name)
    if name in ('buffer', 'offset_curve', 'parallel_offset'):
        bind = binder(method, f'{type(obj).__name__}.{name}')

        def buffered(*args, **kwargs):
            p = bind(args, kwargs)
            # quad_segs, or resolution (parallel_offset's name, and a keyword buffer still reads)
            candidates = [p.get('quad_segs'), p.get('resolution')]
            segments = max([_segment_count(c) for c in candidates if c is not None], default=0)
            if segments > _MAX_QUAD_SEGS:
                refuse(f'{name} with {segments} segments per quarter circle; the sandbox allows {_MAX_QUAD_SEGS}')
            # an array of distances makes one geometry per distance
            # every vertex of the geometry gets a quarter circle (GEOS works without the interpreter: a buffer of
            # a 100,000-point line runs for a minute, out of the tracer's reach)
            vertices = max(int(shapely.get_num_coordinates(obj)), 1)
            distances = _array_size_estimate(p.get('distance'))
            check_elements(distances * (4 * max(segments, 16) + 1) * vertices, name)
            return method(*args, **kwargs)
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
                               'buffer', 'segmentize', 'to_bytes', 'from_bytes', 'sort'))


def guarded_getattr(obj, name):
    """Attribute reads of generated code. Names were screened by the AST check; this adds checks on values."""
    if isinstance(obj, type):
        if name in _REFUSED_ON_TYPES:
            if name == 'from_bytes' and issubclass(obj, int):
                return _checked_from_bytes(getattr(obj, name))  # the check a value's from_bytes has
            forbid(f'{obj.__name__}.{name} cannot be used unbound in the sandbox; call it on a value')
        return getattr(obj, name)
    if isinstance(obj, (str, bytes, bytearray)):
        return _string_method(obj, name)
    if isinstance(obj, list):
        return _list_method(obj, name)
    if isinstance(obj, _ARRAYS):
        return _array_method(obj, name)
    if isinstance(obj, BaseGeometry):
        return _geometry_method(obj, name)
    if isinstance(obj, int) and name in ('to_bytes', 'from_bytes'):
        if name == 'from_bytes':
            return _checked_from_bytes(obj.from_bytes)  # the check the class's from_bytes has

        def to_bytes(length=1, *args, **kwargs):
            check_length(length, 'int.to_bytes')
            return obj.to_bytes(length, *args, **kwargs)
        return to_bytes
    return getattr(obj, name)


# ---------------------------------------------------------------------------------------------------- wrappers
def wrap_callable(function):
    """A plain function that calls `function`: generated code sees no attributes of what it wraps."""
    def call(*args, **kwargs):
        if _gettrace() is None:
            checkpoint()
        return function(*args, **kwargs)
    return call


def _shape_count(shape):
    if shape is None:
        return 1
    if isinstance(shape, (int, numpy.integer)):
        return operator.index(shape)
    return math.prod(operator.index(d) for d in shape)


def _size(value):
    return _array_size_estimate(value)


def _broadcast_count(*values):
    """Elements of the broadcast of `values` (shapes estimated without converting lists), 0 if they do not."""
    try:
        return math.prod(numpy.broadcast_shapes(*(_shape_estimate(v) for v in values if v is not None)))
    except Exception:
        return 0  # numpy raises its own error


_ARRAY_LIKE = (numpy.ndarray, numpy.generic, list, tuple)
_DTYPE_LIKE = (str, type, numpy.dtype)


def _check_arguments(values, what):
    """Every argument of a NumPy function: no object arrays (their elements grow without bound: a sum of huge
    integers), no dtype of objects or strings wherever it is passed, no list that converts to too many elements,
    and no broadcast of them all to too many elements."""
    arrays = []
    for value in values:
        if isinstance(value, _DTYPE_LIKE):
            check_dtype(value, what)
        elif isinstance(value, _ARRAY_LIKE):
            if isinstance(value, numpy.ndarray) and value.dtype.kind == 'O':
                forbid(f'{what} on an array of Python objects is not available in the sandbox')
            check_elements(_array_size_estimate(value), what)
            arrays.append(value)
    if len(arrays) >= 2:
        check_elements(_broadcast_count(*arrays), what)


def _check_result(value, what):
    if isinstance(value, numpy.ndarray) and value.dtype.kind == 'O':
        forbid(f'{what} made an array of Python objects (e.g. integers too large for int64), which is not '
               'available in the sandbox')
    return value


# ---------------------------------------------------------------------------------------------------- binding
# Rules read a call's arguments by parameter name, bound the way the function binds them (binding.py): positional
# and keyword alike, defaults filled in.
_NO_VALUE = numpy._NoValue  # NumPy's default for "not given"


# NumPy functions whose own signature says less than they accept (np.arange reads start and stop by name too).
def _arange_signature(start=None, stop=None, step=None, dtype=None, *, device=None, like=None):
    """np.arange as it binds its arguments: np.arange(stop=3), np.arange(1, 5, step=2)."""


SIGNATURES = {'arange': _arange_signature}


# ---------------------------------------------------------------------------------------------------- NumPy rules
# Each rule gets the bound parameters and returns the elements of the result (inputs are checked apart).
def _rule_shape(p):
    if isinstance(p.get('fill_value'), (str, bytes)):
        forbid('np.full with a string fill value is not available in the sandbox')
    return _shape_count(p['shape'])


def _rule_like(p):
    shape = p['shape']
    return _size(p['a']) if shape is None else _shape_count(shape)


def _rule_arange(p):
    start, stop, step = p['start'], p['stop'], p['step']
    if stop is None:  # np.arange(n): n is the stop
        start, stop = 0, start
    elif start is None:  # np.arange(stop=n)
        start = 0
    step = 1 if step is None else step
    if stop is None or step == 0:
        return 0  # numpy raises its own error
    return max(int(math.ceil((float(stop) - float(start)) / float(step))), 0)


def _rule_linspace(p):
    num = operator.index(p['num'])
    return num * max(_broadcast_count(p['start'], p['stop']), 1)


def _rule_eye(p):
    rows = operator.index(p['N'] if 'N' in p else p['n'])
    cols = p.get('M')
    return rows * (rows if cols is None else operator.index(cols))


def _rule_input(p):
    return _size(p['object'] if 'object' in p else p['a'])


def _rule_join(p):
    return sum(_size(item) for item in (p['arrays'] if 'arrays' in p else p['tup']))


def _rule_outer(p):
    return _size(p['a']) * _size(p['b'])


def _rule_tile(p):
    return _size(p['A']) * _shape_count(p['reps'])


def repeat_elements(a, repeats, axis):
    """Elements, or for zero-width chunks the copies, np.repeat makes: numpy loops once per repeated chunk, so
    repeating an empty row 10 ** 12 times along an axis is 10 ** 12 steps although the result is empty."""
    shape = _shape_estimate(a) or (1,)
    check_elements(_array_size_estimate(repeats), 'np.repeat counts')  # before they are converted
    counts = numpy.asarray(repeats)
    if counts.dtype.kind not in 'biu' or not counts.size:
        return 0  # numpy raises its own error (or repeats nothing)
    try:
        along = math.prod(shape) if axis is None else shape[operator.index(axis)]
    except (IndexError, TypeError):
        return 0  # numpy raises its own error
    copies = int(counts.max()) * along if counts.size == 1 else int(counts.sum())
    rest = 1 if axis is None else math.prod(max(d, 1) for i, d in enumerate(shape) if i != axis % len(shape))
    return max(copies, 0) * rest


def _rule_repeat(p):
    return repeat_elements(p['a'], p['repeats'], p['axis'])


def _rule_quantile(p):
    """np.percentile / np.median: one result per quantile and per element of the axes not reduced."""
    shape = _shape_estimate(p['a'])
    size = math.prod(shape)
    axis = p['axis']
    if axis is None:
        kept = 1
    else:
        try:
            axes = {operator.index(ax) % max(len(shape), 1) for ax in (axis if isinstance(axis, (tuple, list))
                                                                      else (axis,))}
        except TypeError:
            return size  # numpy raises its own error
        kept = math.prod(d for i, d in enumerate(shape) if i not in axes)
    return max(size, _array_size_estimate(p.get('q', 0)) * kept)


def _rule_meshgrid(p):
    arrays = p['xi']
    return math.prod(_size(a) for a in arrays) * max(len(arrays), 1)


def _rule_matmul(p):
    a, b = (p['a'], p['b']) if 'a' in p else (p['x1'], p['x2'])
    _matmul_check(a, b)
    return 0


def _rule_diff(p):
    n = operator.index(p['n'])
    if n > _size(p['a']):  # numpy loops n times in Python, out of the tracer's sight
        forbid(f'np.diff with n={n} larger than the array is not available in the sandbox')
    return 0


_MAX_ROLL_PAIRS = 64  # NumPy's most dimensions


def _rule_roll(p):
    """np.roll loops in Python over every (shift, axis) pair it is given, out of the tracer's sight."""
    if max(_array_size_estimate(p['shift']), _array_size_estimate(p['axis'])) > _MAX_ROLL_PAIRS:
        forbid(f'np.roll with more than {_MAX_ROLL_PAIRS} shifts or axes is not available in the sandbox')
    return 0


def _rule_dimensions(p):
    """np.random.rand(2, 3) style: every positional argument is a dimension."""
    return _shape_count(p['args'])


def _rule_size(p):
    return _shape_count(p['size'])


def _rule_distribution(p):
    if p['size'] is not None:
        return _shape_count(p['size'])
    first, second = ('loc', 'scale') if 'loc' in p else ('low', 'high')
    return _broadcast_count(p[first], p[second])


def _rule_choice(p):
    population = p['a']
    if not p['replace']:  # numpy permutes the whole population first (any false value, as numpy tests it)
        check_elements(operator.index(population) if isinstance(population, (int, numpy.integer))
                       else _size(population), 'np.random.choice without replacement')
    return _shape_count(p['size'])


# Cubic-time linear algebra: inputs are kept small so a single call stays well under a second; svd also makes
# its factors, which with full_matrices are square in each dimension (a 1 x 15000 input has a 15000 x 15000 V).
MAX_MATRIX_ELEMENTS = 250_000


def _check_matrix(value, what):
    size = _array_size_estimate(value)
    if size > MAX_MATRIX_ELEMENTS:
        refuse(f'{what} on more than {MAX_MATRIX_ELEMENTS:,} elements is not allowed in the sandbox '
               f'(this matrix has {size:,})')


def _matrix_rule(what):
    def rule(p):
        _check_matrix(p['a'], what)
        return _size(p['a'])
    return rule


def _rule_svd(p):
    shape = _shape_estimate(p['a'])
    _check_matrix(p['a'], 'np.linalg.svd')
    if not p['compute_uv'] or len(shape) < 2:
        return math.prod(shape)
    rows, cols = shape[-2], shape[-1]
    both = min(rows, cols)
    factors = rows * rows + cols * cols if p['full_matrices'] else (rows + cols) * both
    return math.prod(shape[:-2]) * (factors + both)


def _rule_norm(p):
    """np.linalg.norm: the 2-norm and nuclear norm of a matrix are a singular value decomposition."""
    shape = _shape_estimate(p['x'])
    axis = p['axis']
    matrix = len(shape) == 2 if axis is None else isinstance(axis, (tuple, list)) and len(axis) == 2
    try:
        spectral = p['ord'] in (2, -2, 'nuc')
    except Exception:
        spectral = True  # numpy raises its own error
    if matrix and spectral:
        _check_matrix(p['x'], 'np.linalg.norm with this ord')
    return 0


SIZE_RULES = {
    'zeros': _rule_shape, 'ones': _rule_shape, 'empty': _rule_shape, 'full': _rule_shape,
    'zeros_like': _rule_like, 'ones_like': _rule_like, 'arange': _rule_arange,
    'linspace': _rule_linspace, 'eye': _rule_eye, 'identity': _rule_eye,
    'array': _rule_input, 'asarray': _rule_input,
    'concatenate': _rule_join, 'stack': _rule_join, 'vstack': _rule_join, 'hstack': _rule_join,
    'column_stack': _rule_join, 'meshgrid': _rule_meshgrid,
    'outer': _rule_outer, 'kron': _rule_outer, 'tile': _rule_tile, 'repeat': _rule_repeat,
    'dot': _rule_matmul, 'matmul': _rule_matmul, 'diff': _rule_diff, 'roll': _rule_roll,
    'rand': _rule_dimensions, 'randn': _rule_dimensions,
    'random': _rule_size, 'normal': _rule_distribution, 'uniform': _rule_distribution,
    'randint': _rule_distribution, 'choice': _rule_choice,
    'percentile': _rule_quantile, 'median': _rule_quantile,
    **{name: _matrix_rule(f'np.linalg.{name}') for name in ('inv', 'det', 'solve', 'pinv', 'eig')},
    'svd': _rule_svd, 'norm': _rule_norm,
}
# Keywords that change what a ufunc computes with: a loop over Python objects (signature='O->O').
_REFUSED_KEYWORDS = frozenset({'signature', 'sig'})


def wrap_numpy_function(name, function):
    """NumPy function for generated code (`name` as the program writes it after `np.`: 'zeros', 'linalg.svd'):
    the arguments bound by the function's signature, checked (sizes, dtypes, broadcast), the result's size bounded
    before the call, the result checked after it."""
    short = name.rpartition('.')[2]
    what = f'np.{name}'
    rule = SIZE_RULES.get(short)
    bind = binder(SIGNATURES.get(short, function), what, _NO_VALUE)
    if bind is None and rule is not None:
        raise RuntimeError(f'{what} has a size rule but no signature to bind its arguments with')
    is_type = isinstance(function, type)  # np.float64(...) and friends

    def call(*args, **kwargs):
        p = bind(args, kwargs) if bind is not None else kwargs
        if not _REFUSED_KEYWORDS.isdisjoint(kwargs):
            forbid(f'{what}: the keyword argument signature is not available in the sandbox')
        # inputs first: no rule below may convert a list the limits have not seen
        _check_arguments(itertools.chain(args, kwargs.values()), what)
        check_dtype(p.get('dtype'), what)
        if is_type and args and isinstance(args[0], (str, bytes)):
            forbid(f'{what} of a string is not available in the sandbox')
        if rule is not None:
            check_elements(rule(p), what)
        return _check_result(function(*args, **kwargs), what)
    return call


def _coordinate_count(value):
    """Coordinates a constructor copies: geometries inside a list count with all their coordinates."""
    if isinstance(value, BaseGeometry):
        return int(shapely.get_num_coordinates(value))
    if isinstance(value, (list, tuple)):
        return sum(_coordinate_count(item) if isinstance(item, (BaseGeometry, list, tuple)) else 1
                   for item in value)
    return _array_size_estimate(value)


def wrap_geometry_function(name, function):
    """Shapely constructors and functions: coordinate lists are bounded like sequences."""
    def call(*args, **kwargs):
        for arg in itertools.chain(args, kwargs.values()):
            size = _len_or_none(arg) if not isinstance(arg, (str, bytes)) else None
            if size is not None:
                check_length(size, name)
                check_elements(_coordinate_count(arg), name)
        return function(*args, **kwargs)
    return call
