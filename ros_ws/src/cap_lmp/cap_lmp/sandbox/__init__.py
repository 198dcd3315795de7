"""In-process sandbox for model-written policy code: AST checks, rewritten operators, restricted names, a watchdog.

What a program goes through
1. **AST check** (`check_code`): refuses imports; `global`; class definitions; async code; `with`; `try ... finally`
   and bare `except:` (either could keep running after a stop); any name starting with `__`; any attribute starting
   with `_`; frame, generator, coroutine, traceback and code attributes (`gi_`, `f_`, `cr_`, `ag_`, `tb_`, `co_`
   prefixes, `mro`); NumPy's file and raw-memory attributes (`tofile`, `dump`, `ctypes`, ...); attribute assignment
   and deletion; the names exec, eval, compile, open, getattr, setattr, delattr, hasattr, globals, locals, vars, dir,
   type, object, super, input, breakpoint, help, memoryview; the string methods translate and maketrans; class
   patterns in `match` except a builtin type's own `case int(x):` (a class pattern reads attributes with a plain
   getattr, past every guard); f-string format specs that are nested or wider than the limit. `nonlocal` is
   allowed: it reaches only the enclosing function's own variables.
2. **Rewrite**: every binary and augmented operator, every single comparison and every attribute read becomes a call
   to a checked helper (`guards.py`), every loop body starts with a call to a checkpoint, and every
   comprehension step, function body and lambda checks that the tracer is still installed (one C call; if it is
   gone, the checkpoint raises the stop). The
   helpers estimate the size of a result first (integer bits of `**`, `*`, `<<`; length of sequence repetition and
   concatenation, also with NumPy integer counts; elements of broadcast NumPy operations and matrix products) and
   raise ResourceLimitError instead of doing work that exceeds SandboxLimits; string methods that pad, replace,
   join or format, and `%` formatting, are checked the same way (output length from the template and its text
   arguments); `str.format` fields may not look up attributes or items (OperationRefused). `list.extend` and `+=`
   of an iterable without a length run as a checked Python loop (an iterator over the list itself never ends in
   C). NumPy methods (`ndarray` and scalars): `resize` takes no `refcheck`, `astype`/`view` and every `dtype=`
   refuse object, string, void and subarray dtypes; arithmetic on object arrays is refused; `np.diff`'s `n` is
   bounded by the array size. Every argument of an allow-listed NumPy function is checked: a dtype of objects or
   strings is refused wherever it is passed (also positionally), object arrays are refused as arguments and as
   results (an array of integers too large for int64 would make a sum or product unbounded), lists count with the
   size they convert to, and all array-like arguments together must broadcast within the element limit.
   `np.repeat` counts the copies it makes (repeating a zero-width row 10 ** 12 times is 10 ** 12 steps), and
   `np.percentile` / `np.median` the results per quantile. `sorted`, `list.sort`, `min` and `max` bound the
   element comparisons of list and tuple items (aliased long lists compare element by element).
3. **Names**: the program sees restricted builtins (no `type`/`object`, one-argument `iter`, bounded `range`, `sum`
   as a checked Python loop, `map`/`filter`/`zip`/`enumerate`/`reversed` as Python generators whose frames the
   watchdog sees, so an endless or deeply nested chain meets the time or depth limit, and an `__import__` for
   NumPy's C code, which imports its own submodules through the caller's builtins; the program cannot name it),
   a NumPy namespace `np` of allow-listed functions with size rules (they read arguments by name whether passed
   by position or keyword), the Shapely constructors and affinity functions (coordinates of geometries inside
   lists count), and the injected robot API and LMPs. Every injected callable is wrapped in a plain function, so
   attribute traversal from it finds nothing of the host. A program may rebind these names within its own run;
   the engine puts the robot API, LMP, `np` and Shapely names back before every command.
4. **Watchdog**: while a program runs, a trace function on the calling thread (sys.settrace) checks, at every line
   and every call of sandboxed code (the helpers included): the wall-clock limit (time spent waiting for the model
   is excluded), the cancel event, the nesting depth of sandboxed calls, and every 5 ms the growth of the process'
   resident memory. A violation raises ExecutionStopped (reason 'timeout', 'cancelled', 'recursion', 'memory')
   through an internal BaseException the program cannot catch (it sees no BaseException, and bare `except` and
   `finally` are refused). A stop is sticky: CPython swallows an exception raised while a generator is finalized
   and removes the trace function with it, so the watchdog never raises on the 'call' event of a generator frame
   (it checks at the frame's first line instead), every later check raises the stop again, loop checkpoints and
   wrapped calls, comprehensions, function bodies and lambdas verify that the tracer is still installed (and
   raise the stop when it is not), and a run that ends after a swallowed stop still raises ExecutionStopped.
   Memory growth is measured from the start of the run, or, once `reset_memory_baseline()` was called (the engine
   does at every session start), from then on: what a session keeps between commands counts against the limit
   (after a memory stop the engine drops what the command bound and, if the session still holds more than half the
   limit, resets it). The engine's own work for a nested LMP call (prompting, checking) runs untraced; the model's
   time is excluded with `Watchdog.exclude`, and the engine stops a command whose model deadline passed through
   `Watchdog.stop` (reason 'model_timeout').

What it guarantees
- Generated code cannot import, reach dunder attributes, frames, globals or real builtins, or write attributes.
- A Python-level loop, comprehension, recursion or generator chain is stopped within one trace event of the limit,
  also after a stop was swallowed by a generator finalizer; a call into the robot API is a checkpoint too.
- Single operations the helpers know (big powers, repetition, padding, NumPy creation and broadcasting, Shapely
  buffers) are refused before they allocate.
- The host survives: refusals and stops raise SandboxError subclasses; the program's own exceptions (an unknown
  object from the robot API, a TypeError...) propagate unchanged, and the engine reports type, message and line.
  The engine's report of a program's exception and the sandbox's print() are built with bounded work
  (`bounded_text`, `bounded_exception_text`: reprlib, at most 10,000 characters).

What it does not guarantee (in process; IsolatedEngine, which lmp_node uses, runs the sandbox in a process of
its own and bounds the first three from outside: a dead process costs the session, and a program that has not
ended by `time_limit_s` + 0.5 s, whatever it does, is killed, see isolated_engine.py)
- It is not an OS boundary: a bug in CPython, NumPy or Shapely reachable with allowed values is not contained.
  Known instances: C recursion over a deeply nested value built by a loop (`t = (t,)` 300,000 times, then
  `hash(t)`, `str(t)` or `t == t`) overflows the C stack and kills the process.
- Quadratic C work on aliased data is not bounded: `str([row] * 1000)` with a million-element `row`, hashing or
  comparing tuples that repeat one long tuple, `list.count` over aliased long lists, a set of integers with one
  hash. Every input stays within the size limits, the single C call runs for minutes or hours and is not
  interrupted.
- C-level work inside a single allowed call is not interrupted (e.g. sorting a million long strings, a NumPy
  reduction over a large array, a GEOS operation on a pathological geometry: a buffer of a 30,000-point random
  line runs for minutes and releases the interpreter); the size limits keep most such calls to seconds, but a
  robot API call that blocks is only checked when it returns.
- Memory is bounded by the size rules for the operations above, and otherwise by sampling resident memory every
  5 ms: a NumPy function without a size rule could allocate up to its inputs' product before the sampler sees it.
  Size rules are estimates: NumPy arrays built from nested lists are estimated from their first element, and
  string arrays inferred from data (`np.array(['a' * 10 ** 6] * 2)`) are not refused.
  The sampler measures the whole process, so other threads' allocations count against the limit.
- Chained comparisons (`a < b < c`) are not rewritten.
- The tracer replaces any other trace function (a debugger, coverage) on the thread while a program runs.
"""
from __future__ import annotations

import ast
import builtins
import inspect
import itertools
import logging
import os
import re
import reprlib
import sys
import threading
import time
import warnings
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from types import CodeType, SimpleNamespace
from typing import Any, Callable, Iterator, Mapping

from cap_lmp.errors import CodeRejected, ExecutionStopped, OperationRefused, ResourceLimitError

# Code objects whose file name starts with this are sandboxed: the tracer watches only them.
SANDBOX_FILE_PREFIX = '<cap-sandbox'
_GUARDS_FILENAME = SANDBOX_FILE_PREFIX + ':guards>'
_GUARD_PREFIX = '__cap_'


@dataclass(frozen=True)
class SandboxLimits:
    """Limits for one program run. Defaults fit table-top policies with room to spare.

    The time limit counts time inside robot API calls (motions take seconds each) but not time waiting for the model.
    """

    time_limit_s: float = 300.0
    max_sequence_length: int = 1_000_000
    max_array_elements: int = 2_000_000
    max_int_bits: int = 100_000
    max_format_width: int = 10_000
    max_call_depth: int = 150
    max_memory_growth_bytes: int = 1 << 30
    memory_check_interval_s: float = 0.005


# ---------------------------------------------------------------------------------------------------- AST check
FORBIDDEN_NAMES = frozenset({
    'exec', 'eval', 'compile', 'open', 'getattr', 'setattr', 'delattr', 'hasattr', 'globals', 'locals', 'vars',
    'dir', 'type', 'object', 'super', 'input', 'breakpoint', 'help', 'memoryview', 'classmethod', 'staticmethod',
    'property', 'exit', 'quit', 'BaseException', 'SystemExit', 'KeyboardInterrupt', 'GeneratorExit',
})
FORBIDDEN_ATTRIBUTES = frozenset({
    'mro', 'ctypes', 'tofile', 'dump', 'dumps', 'load', 'loads', 'save', 'savetxt', 'setfield', 'getfield',
    'func_globals', 'func_code', 'im_func', 'im_self', 'format_map', 'translate', 'maketrans',
})
FORBIDDEN_ATTRIBUTE_PREFIXES = ('_', 'gi_', 'f_', 'cr_', 'ag_', 'tb_', 'co_')
_FORBIDDEN_NODES = {
    ast.Import: 'imports are not allowed; np, shapely and the robot API are already available',
    ast.ImportFrom: 'imports are not allowed; np, shapely and the robot API are already available',
    ast.Global: '`global` is not allowed; variables of the session are shared already',
    ast.ClassDef: 'class definitions are not allowed',
    ast.AsyncFunctionDef: 'async code is not allowed',
    ast.AsyncFor: 'async code is not allowed',
    ast.AsyncWith: 'async code is not allowed',
    ast.Await: 'async code is not allowed',
    ast.With: '`with` statements are not allowed',
    ast.TryStar: '`except*` is not allowed',
}
_WIDTH = re.compile(r'\d+')
_SELF_MATCHING_TYPES = frozenset({'bool', 'bytes', 'dict', 'float', 'frozenset', 'int', 'list', 'set', 'str',
                                  'tuple', 'complex'})


class _Checker(ast.NodeVisitor):
    def __init__(self, limits: SandboxLimits) -> None:
        self.limits = limits

    def refuse(self, node: ast.AST, reason: str) -> None:
        raise CodeRejected(reason, getattr(node, 'lineno', None))

    def generic_visit(self, node: ast.AST) -> None:
        reason = _FORBIDDEN_NODES.get(type(node))
        if reason:
            self.refuse(node, reason)
        super().generic_visit(node)

    def visit_Constant(self, node: ast.Constant) -> None:
        pass  # (the base class' visit_Constant is a slow compatibility shim)

    def visit_Name(self, node: ast.Name) -> None:
        if node.id.startswith('__'):
            self.refuse(node, f'the name {node.id!r} is not allowed (names starting with "__" are reserved)')
        if node.id in FORBIDDEN_NAMES:
            self.refuse(node, f'{node.id!r} is not available in generated code')

    def _check_binding(self, node: ast.AST, name: str | None) -> None:
        if name and (name.startswith('__') or name in FORBIDDEN_NAMES):
            self.refuse(node, f'the name {name!r} may not be defined in generated code')

    def visit_FunctionDef(self, node: ast.FunctionDef) -> None:
        self._check_binding(node, node.name)
        for arg in itertools.chain(node.args.posonlyargs, node.args.args, node.args.kwonlyargs,
                                   [node.args.vararg, node.args.kwarg]):
            if arg is not None:
                self._check_binding(arg, arg.arg)
        self.generic_visit(node)

    def visit_Lambda(self, node: ast.Lambda) -> None:
        for arg in itertools.chain(node.args.posonlyargs, node.args.args, node.args.kwonlyargs,
                                   [node.args.vararg, node.args.kwarg]):
            if arg is not None:
                self._check_binding(arg, arg.arg)
        self.generic_visit(node)

    def visit_Attribute(self, node: ast.Attribute) -> None:
        name = node.attr
        if name.startswith(FORBIDDEN_ATTRIBUTE_PREFIXES) or name in FORBIDDEN_ATTRIBUTES:
            self.refuse(node, f'the attribute {name!r} is not allowed in generated code')
        if not isinstance(node.ctx, ast.Load):
            self.refuse(node, f'assigning or deleting attributes ({name!r}) is not allowed in generated code')
        self.generic_visit(node)

    def visit_Try(self, node: ast.Try) -> None:
        if node.finalbody:
            self.refuse(node, '`finally` is not allowed in generated code')
        for handler in node.handlers:
            if handler.type is None:
                self.refuse(handler, 'a bare `except:` is not allowed; name the exception, e.g. `except Exception:`')
            self._check_binding(handler, handler.name)
        self.generic_visit(node)

    def visit_Nonlocal(self, node: ast.Nonlocal) -> None:
        for name in node.names:
            self._check_binding(node, name)

    def visit_MatchAs(self, node: ast.MatchAs) -> None:
        self._check_binding(node, node.name)
        self.generic_visit(node)

    def visit_MatchStar(self, node: ast.MatchStar) -> None:
        self._check_binding(node, node.name)

    def visit_MatchMapping(self, node: ast.MatchMapping) -> None:
        self._check_binding(node, node.rest)
        self.generic_visit(node)

    def visit_MatchClass(self, node: ast.MatchClass) -> None:
        # A class pattern reads attributes with a plain getattr (keyword patterns, and positional ones through
        # __match_args__), past every guard: only the builtin types' own self-match `case int(x):` is allowed.
        if node.kwd_attrs:
            self.refuse(node, 'class patterns with keywords (`case str(name=...)`) are not allowed in generated code')
        if not (isinstance(node.cls, ast.Name) and node.cls.id in _SELF_MATCHING_TYPES) or len(node.patterns) > 1:
            self.refuse(node, 'class patterns are allowed for builtin types only, e.g. `case int(x):`')
        self.generic_visit(node)

    def visit_FormattedValue(self, node: ast.FormattedValue) -> None:
        spec = node.format_spec
        if spec is not None:
            for part in spec.values:
                if not isinstance(part, ast.Constant):
                    self.refuse(node, 'f-string format specs must be constant in generated code')
                for width in _WIDTH.findall(str(part.value)):
                    if int(width) > self.limits.max_format_width:
                        self.refuse(node, f'f-string width {width} exceeds the limit of '
                                          f'{self.limits.max_format_width}')
        self.visit(node.value)


def check_code(source: str, limits: SandboxLimits | None = None) -> ast.Module:
    """Parse and check generated code; raise CodeRejected with line and reason when it is not allowed."""
    try:
        with warnings.catch_warnings():  # model code is not ours to warn about on stderr
            warnings.simplefilter('ignore')
            tree = ast.parse(source, mode='exec')
    except SyntaxError as error:
        line_text = (error.text or '').strip()
        raise CodeRejected(f'the code has a syntax error at line {error.lineno}: {error.msg}'
                           + (f': `{line_text}`' if line_text else ''), error.lineno, line_text) from None
    except (ValueError, MemoryError, RecursionError) as error:
        raise CodeRejected(f'the code could not be parsed: {error}') from None
    try:
        _Checker(limits or SandboxLimits()).visit(tree)
    except CodeRejected as error:
        if error.line:
            lines = source.splitlines()
            if 0 < error.line <= len(lines):
                error.source_line = lines[error.line - 1].strip()
                error.args = (f'{error.args[0]} (line {error.line}: `{error.source_line}`)',)
        raise
    except RecursionError:
        raise CodeRejected('the code is nested too deeply to check') from None
    return tree


# ---------------------------------------------------------------------------------------------------- rewrite
_BINOP_HELPERS = {
    ast.Add: 'add', ast.Sub: 'sub', ast.Mult: 'mult', ast.MatMult: 'matmult', ast.Div: 'truediv',
    ast.FloorDiv: 'floordiv', ast.Mod: 'mod', ast.Pow: 'pow', ast.LShift: 'lshift', ast.RShift: 'rshift',
    ast.BitAnd: 'and', ast.BitOr: 'or', ast.BitXor: 'xor',
}
_COMPARE_HELPERS = {ast.Eq: 'eq', ast.NotEq: 'ne', ast.Lt: 'lt', ast.LtE: 'le', ast.Gt: 'gt', ast.GtE: 'ge'}


def _helper(name: str, node: ast.AST) -> ast.Name:
    return ast.copy_location(ast.Name(id=_GUARD_PREFIX + name, ctx=ast.Load()), node)


def _located(new: ast.AST, old: ast.AST) -> ast.AST:
    """Give a new node and its new children the source position of `old` (cheaper than fix_missing_locations)."""
    for node in ast.walk(new):
        if 'lineno' in node._attributes and not hasattr(node, 'lineno'):
            ast.copy_location(node, old)
    return new


class _Rewriter(ast.NodeTransformer):
    """Routes operators and attribute reads through the checked helpers (names the checker refuses in user code)."""

    def visit_Constant(self, node: ast.Constant) -> ast.AST:
        return node

    def visit_Name(self, node: ast.Name) -> ast.AST:
        return node

    def visit_BinOp(self, node: ast.BinOp) -> ast.AST:
        self.generic_visit(node)
        helper = _helper('op_' + _BINOP_HELPERS[type(node.op)], node)
        return ast.copy_location(ast.Call(func=helper, args=[node.left, node.right], keywords=[]), node)

    def visit_Compare(self, node: ast.Compare) -> ast.AST:
        self.generic_visit(node)
        if len(node.ops) != 1 or type(node.ops[0]) not in _COMPARE_HELPERS:
            return node
        helper = _helper('cmp_' + _COMPARE_HELPERS[type(node.ops[0])], node)
        return ast.copy_location(ast.Call(func=helper, args=[node.left, node.comparators[0]], keywords=[]), node)

    def visit_Attribute(self, node: ast.Attribute) -> ast.AST:
        self.generic_visit(node)
        return ast.copy_location(ast.Call(func=_helper('getattr', node),
                                          args=[node.value, ast.copy_location(ast.Constant(node.attr), node)],
                                          keywords=[]), node)

    def visit_AugAssign(self, node: ast.AugAssign) -> ast.AST:
        self.generic_visit(node)
        helper = _helper('op_i' + _BINOP_HELPERS[type(node.op)], node)
        target = node.target
        if isinstance(target, ast.Name):
            value = ast.Call(func=helper, args=[ast.Name(id=target.id, ctx=ast.Load()), node.value], keywords=[])
            return _located(ast.Assign(targets=[target], value=value), node)
        if isinstance(target, ast.Subscript):
            call = ast.Call(func=_helper('augmented_item', node),
                            args=[target.value, target.slice, helper, node.value], keywords=[])
            return _located(ast.Expr(value=call), node)
        raise CodeRejected('this augmented assignment target is not allowed', node.lineno)

    def _tick_loop(self, node: ast.While | ast.For) -> ast.AST:
        # A call at the top of every loop body: a checkpoint even for loops that emit no line events
        # (`while True: pass` compiles to a jump onto itself).
        self.generic_visit(node)
        tick = _located(ast.Expr(value=ast.Call(func=_helper('tick', node), args=[], keywords=[])), node)
        node.body.insert(0, tick)
        return node

    visit_While = _tick_loop
    visit_For = _tick_loop

    # Comprehensions, function bodies and lambdas check too once the tracer is gone (a stop swallowed by a
    # generator finalizer): `gettrace() is None and tick()`, one C call while the tracer runs, which checks anyway.
    @staticmethod
    def _untraced_check(node: ast.AST) -> ast.expr:
        traced = ast.Compare(left=ast.Call(func=_helper('gettrace', node), args=[], keywords=[]), ops=[ast.Is()],
                             comparators=[ast.Constant(None)])
        check = ast.BoolOp(op=ast.And(), values=[traced, ast.Call(func=_helper('tick', node), args=[], keywords=[])])
        return _located(check, node)

    def _tick_comprehension(self, node: ast.AST) -> ast.AST:
        self.generic_visit(node)
        for generator in node.generators:
            generator.ifs.insert(0, _located(ast.UnaryOp(op=ast.Not(), operand=self._untraced_check(node)), node))
        return node

    visit_ListComp = _tick_comprehension
    visit_SetComp = _tick_comprehension
    visit_DictComp = _tick_comprehension
    visit_GeneratorExp = _tick_comprehension

    def visit_FunctionDef(self, node: ast.FunctionDef) -> ast.AST:
        self.generic_visit(node)
        node.body.insert(0, _located(ast.Expr(value=self._untraced_check(node)), node))
        return node

    def visit_Lambda(self, node: ast.Lambda) -> ast.AST:
        self.generic_visit(node)
        node.body = _located(ast.BoolOp(op=ast.Or(), values=[self._untraced_check(node), node.body]), node)
        return node


def rewrite(tree: ast.Module) -> ast.Module:
    """Return the checked tree with guarded operators (line numbers preserved for error reports)."""
    return _Rewriter().visit(tree)


# ---------------------------------------------------------------------------------------------------- names
_SAFE_BUILTIN_NAMES = (
    'abs', 'all', 'any', 'ascii', 'bin', 'bool', 'callable', 'chr', 'complex', 'dict', 'divmod', 'enumerate',
    'filter', 'float', 'frozenset', 'hash', 'hex', 'int', 'isinstance', 'len', 'list', 'map', 'max', 'min', 'next',
    'oct', 'ord', 'repr', 'reversed', 'set', 'slice', 'sorted', 'str', 'tuple', 'zip',
    'ArithmeticError', 'AssertionError', 'AttributeError', 'Exception', 'IndexError', 'KeyError', 'LookupError',
    'NameError', 'NotImplementedError', 'OverflowError', 'RuntimeError', 'StopIteration', 'TypeError',
    'ValueError', 'ZeroDivisionError', 'True', 'False', 'None',
)
_NUMPY_FUNCTIONS = (
    'abs', 'absolute', 'all', 'allclose', 'any', 'arange', 'arccos', 'arcsin', 'arctan', 'arctan2', 'argmax',
    'argmin', 'argsort', 'around', 'array', 'array_equal', 'asarray', 'atleast_2d', 'ceil', 'clip', 'column_stack',
    'concatenate', 'cos', 'count_nonzero', 'cross', 'cumsum', 'deg2rad', 'degrees', 'diff', 'dot', 'empty', 'exp',
    'expand_dims', 'eye', 'flip', 'floor', 'full', 'hstack', 'hypot', 'identity', 'interp', 'isclose', 'kron',
    'linspace', 'log', 'matmul', 'max', 'maximum', 'mean', 'median', 'meshgrid', 'min', 'minimum', 'mod', 'nonzero',
    'ones', 'outer', 'percentile', 'prod', 'rad2deg', 'radians', 'repeat', 'reshape', 'roll', 'round', 'sign', 'sin',
    'sort', 'sqrt', 'square', 'squeeze', 'stack', 'std', 'sum', 'tan', 'tile', 'transpose', 'unique', 'var',
    'vstack', 'where', 'zeros', 'zeros_like', 'ones_like', 'argwhere', 'float32', 'float64', 'int32', 'int64',
)
_NUMPY_CONSTANTS = ('pi', 'e', 'inf', 'nan', 'newaxis')
_NUMPY_LINALG = ('norm', 'inv', 'det', 'solve', 'pinv', 'eig', 'svd')
_NUMPY_RANDOM = ('rand', 'randn', 'random', 'uniform', 'normal', 'randint', 'choice')
_SHAPELY_GEOMETRY = ('Point', 'MultiPoint', 'LineString', 'MultiLineString', 'Polygon', 'MultiPolygon', 'box')
_SHAPELY_AFFINITY = ('rotate', 'scale', 'translate', 'affine_transform')
_SHAPELY_OPS = ('unary_union', 'nearest_points')


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


def _program_print(*values: Any, sep: Any = ' ', **_ignored: Any) -> None:
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


def _internal_import(name: str, globals: Any = None, locals: Any = None, fromlist: Any = (), level: int = 0) -> Any:
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


_GUARDS_CODE: CodeType | None = None
_GUARDS_LOCK = threading.Lock()


def _guards_code() -> CodeType:
    global _GUARDS_CODE
    with _GUARDS_LOCK:
        if _GUARDS_CODE is None:
            source = (Path(__file__).with_name('guards.py')).read_text(encoding='utf-8')
            _GUARDS_CODE = compile(source, _GUARDS_FILENAME, 'exec')
    return _GUARDS_CODE


# ---------------------------------------------------------------------------------------------------- watchdog
class _StopSignal(BaseException):
    """Raised by the tracer inside generated code; BaseException so `except Exception` cannot swallow it."""

    def __init__(self, message: str, reason: str) -> None:
        super().__init__(message)
        self.reason = reason


_RESUMABLE = inspect.CO_GENERATOR | inspect.CO_COROUTINE | inspect.CO_ASYNC_GENERATOR
_PAGE_SIZE = os.sysconf('SC_PAGE_SIZE') if hasattr(os, 'sysconf') else 4096


def _resident_bytes() -> int:
    """Resident memory of this process (Linux); 0 where /proc is missing, which disables the memory check."""
    try:
        with open('/proc/self/statm', 'rb') as statm:
            return int(statm.read().split()[1]) * _PAGE_SIZE
    except (OSError, ValueError, IndexError):
        return 0


class Watchdog:
    """Deadline, cancel, depth and memory checks for the sandboxed frames of one run on the calling thread."""

    def __init__(self, limits: SandboxLimits, cancel_event: threading.Event | None,
                 memory_baseline: int | None = None) -> None:
        self.limits = limits
        self.cancel_event = cancel_event or threading.Event()
        self.deadline = time.monotonic() + limits.time_limit_s
        self.depth = 0
        self.memory_baseline = _resident_bytes() if memory_baseline is None else memory_baseline
        self.next_memory_check = 0.0
        self.stopped: _StopSignal | None = None
        self.tracer = self.trace  # one bound method, so `sys.gettrace() is self.tracer` is a cheap identity test

    @contextmanager
    def paused(self) -> Iterator[None]:
        """Time inside this block (waiting for the model) does not count against the wall-clock limit."""
        started = time.monotonic()
        try:
            yield
        finally:
            self.exclude(time.monotonic() - started)

    def exclude(self, seconds: float) -> None:
        """`seconds` (spent waiting for the model) do not count against the wall-clock limit."""
        self.deadline += max(seconds, 0.0)

    def stop(self, message: str, reason: str) -> None:
        """End the run now with `reason` (e.g. the command's model deadline passed): raised, and sticky."""
        self._stop(message, reason)

    @contextmanager
    def suspended(self) -> Iterator[None]:
        """Host work on behalf of the program (generating a nested LMP's code) runs untraced, then tracing resumes.

        Frames already running keep their local tracer, so the program's own frames stay watched.
        """
        sys.settrace(None)
        try:
            yield
        finally:
            sys.settrace(self.tracer)

    def check(self) -> None:
        """Raise the stop signal if the run must end (used by the tracer and between model calls).

        A stop is sticky: CPython swallows an exception raised while a generator is finalized (and removes the
        trace function with it), so every later check raises it again.
        """
        if self.stopped is not None:
            raise _StopSignal(str(self.stopped), self.stopped.reason)
        if self.cancel_event.is_set():
            self._stop('the program was cancelled', 'cancelled')
        now = time.monotonic()
        if now > self.deadline:
            self._stop(f'the program ran longer than the time limit of {self.limits.time_limit_s:g} s and was '
                       'stopped', 'timeout')
        if now > self.next_memory_check:
            self.next_memory_check = now + self.limits.memory_check_interval_s
            growth = _resident_bytes() - self.memory_baseline
            if growth > self.limits.max_memory_growth_bytes:
                self._stop(f'the program used more than {self.limits.max_memory_growth_bytes // (1 << 20)} MiB of '
                           'memory and was stopped', 'memory')

    def checkpoint(self) -> None:
        """Explicit check from loop bodies and wrapped calls. While the tracer is installed it has just checked
        deadline and cancel at this call's 'call' event; once it was removed (a stop swallowed in a finalizer), no
        trace event comes again and this check raises the stop."""
        if sys.gettrace() is self.tracer and self.stopped is None:
            return
        if self.stopped is None:
            self._stop('the program disabled the time limit and was stopped', 'timeout')
        self.check()

    def _stop(self, message: str, reason: str) -> None:
        self.stopped = _StopSignal(message, reason)
        raise _StopSignal(message, reason)

    def _check_depth(self) -> None:
        if self.depth > self.limits.max_call_depth:
            self._stop(f'the program nested calls deeper than {self.limits.max_call_depth} levels (runaway '
                       'recursion?) and was stopped', 'recursion')

    def _trace_local(self, frame: Any, event: str, arg: Any) -> Any:
        if event == 'return':
            self.depth -= 1
        elif event == 'line':
            if self.depth > self.limits.max_call_depth:
                self._check_depth()
            self.check()
        return self._trace_local

    def trace(self, frame: Any, event: str, arg: Any) -> Any:
        if event != 'call' or not frame.f_code.co_filename.startswith(SANDBOX_FILE_PREFIX):
            return None
        self.depth += 1
        if not frame.f_code.co_flags & _RESUMABLE:
            # Generator frames are resumed by finalizers too, where a raised stop would be swallowed: their
            # checks happen at their first line event instead.
            if self.depth > self.limits.max_call_depth:
                self._check_depth()
            self.check()
        return self._trace_local


@dataclass(frozen=True)
class CompiledProgram:
    """Checked, rewritten and compiled code plus what error reports need."""

    source: str
    code: CodeType
    filename: str
    origin: str


# ---------------------------------------------------------------------------------------------------- sandbox
class Sandbox:
    """Checks, compiles and runs generated code with the limits; see the module docstring for guarantees."""

    _counter = itertools.count(1)

    def __init__(self, limits: SandboxLimits | None = None) -> None:
        self.limits = limits or SandboxLimits()
        guards: dict[str, Any] = {'__builtins__': builtins, '__name__': 'cap_lmp.sandbox.guards'}
        exec(_guards_code(), guards)  # our own helper module, compiled under the sandbox file name
        guards['LIMITS'] = self.limits
        guards['ResourceLimitError'] = ResourceLimitError
        guards['OperationRefused'] = OperationRefused
        guards['checkpoint'] = self._checkpoint
        self._guards = guards
        self._sources: dict[str, CompiledProgram] = {}
        self._local = threading.local()
        # None: memory growth is measured per run; a session (the engine) sets it so kept variables count.
        self.memory_baseline: int | None = None
        self.builtins = self._make_builtins()
        self.numpy = self._make_numpy()
        self.shapely_names = self._make_shapely()

    def memory_growth(self) -> int:
        """Resident memory above the session's baseline (0 when no baseline was set)."""
        return 0 if self.memory_baseline is None else _resident_bytes() - self.memory_baseline

    def reset_memory_baseline(self) -> None:
        """Measure memory growth from now on (a new session): variables kept between runs count against the
        limit, so a session cannot grow by the full limit once per command."""
        self.memory_baseline = _resident_bytes()

    def _checkpoint(self) -> None:
        watchdog = getattr(self._local, 'watchdog', None)
        if watchdog is not None:
            watchdog.checkpoint()

    # -- names ------------------------------------------------------------------------------------------
    def _make_builtins(self) -> dict[str, Any]:
        names = {name: getattr(builtins, name) for name in _SAFE_BUILTIN_NAMES}
        names.update({name: self._guards['guarded_' + name]
                      for name in ('map', 'filter', 'zip', 'enumerate', 'reversed')})
        names.update(range=self._guards['guarded_range'], iter=self._guards['guarded_iter'],
                     sum=self._guards['guarded_sum'], pow=self._guards['guarded_pow'],
                     round=self._guards['guarded_round'], sorted=self._guards['guarded_sorted'],
                     min=self._guards['guarded_min'], max=self._guards['guarded_max'],
                     print=self.wrap_callable(_program_print))
        names['__import__'] = _internal_import
        return names

    def _make_numpy(self) -> SafeNamespace:
        import numpy

        wrap = self._guards['wrap_numpy_function']
        members: dict[str, Any] = {name: wrap(name, getattr(numpy, name)) for name in _NUMPY_FUNCTIONS}
        members.update({name: getattr(numpy, name) for name in _NUMPY_CONSTANTS})
        members['linalg'] = SafeNamespace(**{name: wrap(name, getattr(numpy.linalg, name))
                                             for name in _NUMPY_LINALG})
        members['random'] = SafeNamespace(**{name: wrap(name, getattr(numpy.random, name))
                                             for name in _NUMPY_RANDOM})
        return SafeNamespace(**members)

    def _make_shapely(self) -> dict[str, Any]:
        import shapely
        import shapely.affinity
        import shapely.geometry
        import shapely.ops

        wrap = self._guards['wrap_geometry_function']
        names = {name: wrap(name, getattr(shapely.geometry, name)) for name in _SHAPELY_GEOMETRY}
        names.update({name: wrap(name, getattr(shapely.affinity, name)) for name in _SHAPELY_AFFINITY})
        names.update({name: wrap(name, getattr(shapely.ops, name)) for name in _SHAPELY_OPS})
        return names

    def wrap_callable(self, function: Callable[..., Any]) -> Callable[..., Any]:
        """A plain sandboxed function calling `function`: a checkpoint, and nothing of `function` is reachable."""
        return self._guards['wrap_callable'](function)

    def new_scope(self, names: Mapping[str, Any] | None = None) -> dict[str, Any]:
        """Globals for generated code: restricted builtins, guard helpers, np, shapely, then `names` (wrapped)."""
        scope: dict[str, Any] = {'__builtins__': dict(self.builtins), '__name__': 'generated'}
        for key, value in self._guards.items():
            if key.startswith(('op_', 'cmp_')) or key in ('augmented_item', 'tick'):
                scope[_GUARD_PREFIX + key] = value
        scope[_GUARD_PREFIX + 'getattr'] = self._guards['guarded_getattr']
        scope[_GUARD_PREFIX + 'gettrace'] = sys.gettrace
        scope['np'] = self.numpy
        scope.update(self.shapely_names)
        for name, value in (names or {}).items():
            scope[name] = self.wrap_callable(value) if callable(value) else value
        return scope

    # -- compile ----------------------------------------------------------------------------------------
    def check(self, source: str) -> ast.Module:
        """Parse and check only (the tree is used for function discovery before compile_checked rewrites it)."""
        return check_code(source, self.limits)

    def compile(self, source: str, origin: str = 'program') -> CompiledProgram:
        """Check, rewrite and compile; raise CodeRejected with a reason a person understands."""
        return self.compile_checked(self.check(source), source, origin)

    def compile_checked(self, tree: ast.Module, source: str, origin: str = 'program') -> CompiledProgram:
        """Rewrite (in place) and compile a tree that `check` accepted."""
        tree = rewrite(tree)
        filename = f'{SANDBOX_FILE_PREFIX}:{origin}#{next(self._counter)}>'
        try:
            with warnings.catch_warnings():
                warnings.simplefilter('ignore')
                code = compile(tree, filename, 'exec')
        except (SyntaxError, ValueError, RecursionError, MemoryError) as error:
            raise CodeRejected(f'the code could not be compiled: {error}') from None
        program = CompiledProgram(source=source, code=code, filename=filename, origin=origin)
        self._sources[filename] = program
        if len(self._sources) > 10_000:  # long sessions: keep the registry bounded
            self._sources.pop(next(iter(self._sources)))
        return program

    def program_for(self, filename: str) -> CompiledProgram | None:
        return self._sources.get(filename)

    # -- run --------------------------------------------------------------------------------------------
    @property
    def watchdog(self) -> Watchdog | None:
        """The watchdog of the run active on this thread, if any (nested LMP calls pause it for model time)."""
        return getattr(self._local, 'watchdog', None)

    @contextmanager
    def watching(self, cancel_event: threading.Event | None = None) -> Iterator[Watchdog]:
        """Install the watchdog on this thread for one run; nested use reuses the outer watchdog.

        Stops surface as ExecutionStopped here, at the outermost level.
        """
        outer = self.watchdog
        if outer is not None:
            yield outer
            return
        watchdog = Watchdog(self.limits, cancel_event, self.memory_baseline)
        previous = sys.gettrace()
        self._local.watchdog = watchdog
        sys.settrace(watchdog.tracer)
        try:
            yield watchdog
            if watchdog.stopped is not None:  # a stop that something swallowed still ends the run
                raise _StopSignal(str(watchdog.stopped), watchdog.stopped.reason)
        except _StopSignal as signal:
            raise ExecutionStopped(str(signal), signal.reason) from None
        except RecursionError:
            raise ExecutionStopped('the program recursed too deeply and was stopped', 'recursion') from None
        finally:
            sys.settrace(previous)
            self._local.watchdog = None

    def execute(self, program: CompiledProgram, scope: dict[str, Any],
                cancel_event: threading.Event | None = None) -> None:
        """Run a compiled program in `scope` (its globals) under the watchdog."""
        with self.watching(cancel_event) as watchdog:
            watchdog.check()
            exec(program.code, scope)
            watchdog.check()  # raises again a stop that was swallowed during the run
