"""The names generated code sees (step 3 of the sandbox): the allow-listed builtins, NumPy and Shapely members,
print() to the log, and text of program values built with bounded work."""
from __future__ import annotations

import builtins
import logging
import reprlib
from types import SimpleNamespace
from typing import Any

SAFE_BUILTIN_NAMES = (
    'abs', 'all', 'any', 'ascii', 'bin', 'bool', 'callable', 'chr', 'complex', 'dict', 'divmod', 'enumerate',
    'filter', 'float', 'frozenset', 'hash', 'hex', 'int', 'isinstance', 'len', 'list', 'map', 'max', 'min', 'next',
    'oct', 'ord', 'repr', 'reversed', 'set', 'slice', 'sorted', 'str', 'tuple', 'zip',
    'ArithmeticError', 'AssertionError', 'AttributeError', 'Exception', 'IndexError', 'KeyError', 'LookupError',
    'NameError', 'NotImplementedError', 'OverflowError', 'RuntimeError', 'StopIteration', 'TypeError',
    'ValueError', 'ZeroDivisionError', 'True', 'False', 'None',
)
NUMPY_FUNCTIONS = (
    'abs', 'absolute', 'all', 'allclose', 'any', 'arange', 'arccos', 'arcsin', 'arctan', 'arctan2', 'argmax',
    'argmin', 'argsort', 'around', 'array', 'array_equal', 'asarray', 'atleast_2d', 'ceil', 'clip', 'column_stack',
    'concatenate', 'cos', 'count_nonzero', 'cross', 'cumsum', 'deg2rad', 'degrees', 'diff', 'dot', 'empty', 'exp',
    'expand_dims', 'eye', 'flip', 'floor', 'full', 'hstack', 'hypot', 'identity', 'interp', 'isclose', 'kron',
    'linspace', 'log', 'matmul', 'max', 'maximum', 'mean', 'median', 'meshgrid', 'min', 'minimum', 'mod', 'nonzero',
    'ones', 'outer', 'percentile', 'prod', 'rad2deg', 'radians', 'repeat', 'reshape', 'roll', 'round', 'sign', 'sin',
    'sort', 'sqrt', 'square', 'squeeze', 'stack', 'std', 'sum', 'tan', 'tile', 'transpose', 'unique', 'var',
    'vstack', 'where', 'zeros', 'zeros_like', 'ones_like', 'argwhere', 'float32', 'float64', 'int32', 'int64',
)
NUMPY_CONSTANTS = ('pi', 'e', 'inf', 'nan', 'newaxis')
NUMPY_LINALG = ('norm', 'inv', 'det', 'solve', 'pinv', 'eig', 'svd')
NUMPY_RANDOM = ('rand', 'randn', 'random', 'uniform', 'normal', 'randint', 'choice')
SHAPELY_GEOMETRY = ('Point', 'MultiPoint', 'LineString', 'MultiLineString', 'Polygon', 'MultiPolygon', 'box')
SHAPELY_AFFINITY = ('rotate', 'scale', 'translate', 'affine_transform')
SHAPELY_OPS = ('unary_union', 'nearest_points')


_program_log = logging.getLogger('cap_lmp.program')


_BOUNDED_REPR = reprlib.Repr()
_BOUNDED_REPR.maxlevel = 3
_BOUNDED_REPR.maxlist = _BOUNDED_REPR.maxtuple = _BOUNDED_REPR.maxset = _BOUNDED_REPR.maxfrozenset = 10
_BOUNDED_REPR.maxdict = _BOUNDED_REPR.maxdeque = _BOUNDED_REPR.maxarray = 10
_BOUNDED_REPR.maxstring = _BOUNDED_REPR.maxother = 500
_BOUNDED_REPR.maxlong = 500
MAX_TEXT = 10_000
_PLAIN = (str, int, float, bool, type(None))


def bounded_text(value: Any, limit: int = MAX_TEXT) -> str:
    """str() of a program's value with bounded work: containers are abbreviated (str() of an aliased nested list
    could take hours), long text is cut."""
    if isinstance(value, str):
        text = value
    elif isinstance(value, (float, bool, type(None))) or (isinstance(value, int) and value.bit_length() < 4000):
        text = str(value)
    elif isinstance(value, int):  # str() would be quadratic, and Python refuses it past 4,300 digits
        text = f'<an integer of {value.bit_length():,} bits>'
    else:
        try:
            text = _BOUNDED_REPR.repr(value)
        except Exception:  # reprlib falls back on repr(), which may refuse (an int nested in a container)
            text = f'<{type(value).__name__}>'

    return text if len(text) <= limit else text[:limit] + '...'


def bounded_exception_text(error: BaseException, limit: int = MAX_TEXT) -> str:
    """The message of a program's exception, built with bounded work whatever its arguments are."""
    args = error.args
    if len(args) <= 1 and all(isinstance(arg, _PLAIN) and not (isinstance(arg, int) and arg.bit_length() >= 4000)
                              for arg in args):
        text = str(error)  # one plain argument: the exception's own wording, cost bounded by its size
    elif len(args) == 1:
        text = bounded_text(args[0], limit)
    else:  # str() of many arguments is the repr of their tuple: unbounded for aliased long texts
        text = bounded_text(args[:10], limit)
    return text if len(text) <= limit else text[:limit] + '...'


def program_print(*values: Any, sep: Any = ' ', **_ignored: Any) -> None:
    """print() of generated code goes to the log (models print now and then; stdout is not theirs)."""
    separator = bounded_text(sep, 100)
    parts: list[str] = []
    total = 0
    for value in values:
        if total > MAX_TEXT:
            break
        parts.append(bounded_text(value))
        total += len(parts[-1]) + len(separator)
    _program_log.info('%s', separator.join(parts)[:MAX_TEXT])


_INTERNAL_IMPORT_ROOTS = frozenset({'numpy', 'shapely'})


def internal_import(name: str, globals: Any = None, locals: Any = None, fromlist: Any = (), level: int = 0) -> Any:
    """`__import__` of the sandbox builtins, for C code only: NumPy methods import their helpers through the calling
    frame's builtins. Generated code cannot name it (names starting with "__" are refused); it imports NumPy and
    Shapely submodules and nothing else."""
    if level == 0 and name.split('.')[0] in _INTERNAL_IMPORT_ROOTS:
        return builtins.__import__(name, globals, locals, fromlist, level)
    raise ImportError(f'importing {name!r} is not allowed in the sandbox')


class SafeNamespace(SimpleNamespace):
    """A module stand-in holding only allow-listed members (e.g. the `np` generated code sees)."""

    def __repr__(self) -> str:
        return f'<sandboxed namespace with {len(vars(self))} members>'
