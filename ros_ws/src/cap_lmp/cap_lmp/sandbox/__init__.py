"""In-process sandbox for model-written policy code: AST checks, rewritten operators, restricted names, a watchdog.

What a program goes through
1. **AST check** (`check_code`): refuses imports (the engine first drops imports of names the scope already holds,
   `import numpy as np`, see cap_lmp/provided_imports.py); `global`; class definitions; async code; `with`; `try ...
   finally` and bare `except:` (either could keep running after a stop); any name starting with `__`; any attribute
   starting with `_`; frame, generator, coroutine, traceback and code attributes (`gi_`, `f_`, `cr_`, `ag_`, `tb_`,
   `co_` prefixes, `mro`); NumPy's file and raw-memory attributes (`tofile`, `dump`, `ctypes`, ...); attribute
   assignment and deletion; the names exec, eval, compile, open, getattr, setattr, delattr, hasattr, globals, locals,
   vars, dir, type, object, super, input, breakpoint, help, memoryview; the string methods translate and maketrans;
   class patterns in `match` except a builtin type's own `case int(x):` (a class pattern reads attributes with a plain
   getattr, past every guard); f-string format specs that are nested or wider than the limit. `nonlocal` is allowed: it
   reaches only the enclosing function's own variables.
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
   size they convert to (estimated from their nesting, never by converting them), and all array-like arguments
   together must broadcast within the element limit. Size rules read a call's arguments by meaning: bound to
   parameter names the way the function binds them (its signature, binding.py; positional and keyword alike,
   defaults filled in), flags by their truth value as NumPy tests them (`replace=0` is no replacement), and they
   bound the result as well as the inputs: creation, `linspace`/`arange` lengths, `outer`/`kron`/`meshgrid`/
   `tile`/`repeat`, `np.random.*` sizes and `choice` without replacement (which permutes its population), and
   `np.linalg.svd`'s factors (with `full_matrices` a 1 x n input has an n x n V). Cubic linear algebra (`inv`,
   `det`, `solve`, `pinv`, `eig`, `svd`, and `norm` of order 2, -2 or 'nuc' of a matrix) takes at most 250,000
   elements. `np.repeat` counts the copies it makes (repeating a zero-width row 10 ** 12 times is 10 ** 12 steps),
   `np.percentile` / `np.median` the results per quantile, and `np.roll` takes at most 64 shifts (it loops over
   them in Python, out of the tracer's sight); a ufunc's `signature=` is refused. `sorted`, `list.sort`, `min`
   and `max` bound the element comparisons of list and tuple items (aliased long lists compare element by element).
   Integers stay within `max_int_bits` however a program makes them: integer literals (checked in step 1),
   `int()` of text (at most log2(base) bits per character; a power-of-two base has no CPython digit limit),
   `int.from_bytes` on the class or a value, `+`, `-`, `*`, `**`, `<<` and `pow`; and the operations whose cost
   grows faster than their operands (`*`, `//`, `%`, `divmod`, `pow`, `round`) refuse operands beyond the limit
   wherever they came from (the robot API). At that size each is a matter of milliseconds, decimal text included.
3. **Names**: the program sees restricted builtins (no `type`/`object`, one-argument `iter`, bounded `range`, `sum` as
   a checked Python loop, `int` as a checked constructor that is still the type for `isinstance`, `case int(x):` and
   `dtype=int`, checked `divmod`, `pow` and `round`, `map`/`filter`/`zip`/`enumerate`/`reversed` as Python generators
   whose frames the watchdog sees, so an endless or deeply nested chain meets the time or depth limit, and an
   `__import__` for NumPy's C code, which imports its own submodules through the caller's builtins; the program cannot
   name it), a NumPy namespace `np` of allow-listed functions with size rules (step 2), the Shapely constructors and
   affinity functions (coordinates of geometries inside lists count), and the injected robot API and LMPs. Every
   injected callable is wrapped in a plain function, so attribute traversal from it finds nothing of the host. A
   program may rebind these names within its own run; the engine puts the robot API, LMP, `np` and Shapely names back
   before every command.
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
ended by `time_limit_s` + 0.5 s, whatever it does, is killed, see isolated_engine.py; lmp_node runs programs in
its own process only with `sandbox_process: false`, for debugging, and then says at start-up, as a warning in the
log and on /cap/status, that single C calls are not bounded: IN_PROCESS_WARNING)
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
import itertools
import sys
import threading
import warnings
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from types import CodeType
from typing import Any, Callable, Iterator, Mapping

from cap_lmp.errors import CodeRejected, ExecutionStopped, OperationRefused, ResourceLimitError
from cap_lmp.sandbox.check import (FORBIDDEN_ATTRIBUTE_PREFIXES, FORBIDDEN_ATTRIBUTES, FORBIDDEN_NAMES,
                                   check_code)
from cap_lmp.sandbox.limits import SANDBOX_FILE_PREFIX, SandboxLimits
from cap_lmp.sandbox.names import (MAX_TEXT, NUMPY_CONSTANTS, NUMPY_FUNCTIONS, NUMPY_LINALG, NUMPY_RANDOM,
                                   SAFE_BUILTIN_NAMES, SHAPELY_AFFINITY, SHAPELY_GEOMETRY, SHAPELY_OPS,
                                   SafeNamespace, bounded_exception_text, bounded_text, internal_import,
                                   program_print)
from cap_lmp.sandbox.rewrite import GUARD_PREFIX, rewrite
from cap_lmp.sandbox.watchdog import StopSignal, Watchdog, resident_bytes

# What an engine running programs in its host's own process says at start-up, loudly (lmp_node with
# sandbox_process: false): only a sandbox process is bounded from outside (isolated_engine.py).
IN_PROCESS_WARNING = ('warning: generated programs run in this process (sandbox_process: false), where a single long '
                      'C call (NumPy, Shapely, a big integer) cannot be interrupted and memory is only sampled: the '
                      'time limit, /cap/stop and the memory limit are not guaranteed. Use it for debugging only.')

# The guard helpers run as sandboxed code: the tracer watches them too.
_GUARDS_FILENAME = SANDBOX_FILE_PREFIX + ':guards>'
_GUARDS_CODE: CodeType | None = None
_GUARDS_LOCK = threading.Lock()


def _guards_code() -> CodeType:
    global _GUARDS_CODE
    with _GUARDS_LOCK:
        if _GUARDS_CODE is None:
            source = (Path(__file__).with_name('guards.py')).read_text(encoding='utf-8')
            _GUARDS_CODE = compile(source, _GUARDS_FILENAME, 'exec')
    return _GUARDS_CODE


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
        return 0 if self.memory_baseline is None else resident_bytes() - self.memory_baseline

    def reset_memory_baseline(self) -> None:
        """Measure memory growth from now on (a new session): variables kept between runs count against the
        limit, so a session cannot grow by the full limit once per command."""
        self.memory_baseline = resident_bytes()

    def _checkpoint(self) -> None:
        watchdog = getattr(self._local, 'watchdog', None)
        if watchdog is not None:
            watchdog.checkpoint()

    # -- names ------------------------------------------------------------------------------------------
    def _make_builtins(self) -> dict[str, Any]:
        names = {name: getattr(builtins, name) for name in SAFE_BUILTIN_NAMES}
        names.update({name: self._guards['guarded_' + name]
                      for name in ('map', 'filter', 'zip', 'enumerate', 'reversed')})
        names.update(range=self._guards['guarded_range'], iter=self._guards['guarded_iter'],
                     sum=self._guards['guarded_sum'], pow=self._guards['guarded_pow'],
                     round=self._guards['guarded_round'], sorted=self._guards['guarded_sorted'],
                     min=self._guards['guarded_min'], max=self._guards['guarded_max'],
                     divmod=self._guards['guarded_divmod'], int=self._guards['checked_int'],
                     print=self.wrap_callable(program_print))
        names['__import__'] = internal_import
        return names

    def _make_numpy(self) -> SafeNamespace:
        import numpy

        wrap = self._guards['wrap_numpy_function']
        members: dict[str, Any] = {name: wrap(name, getattr(numpy, name)) for name in NUMPY_FUNCTIONS}
        members.update({name: getattr(numpy, name) for name in NUMPY_CONSTANTS})
        members['linalg'] = SafeNamespace(**{name: wrap(f'linalg.{name}', getattr(numpy.linalg, name))
                                             for name in NUMPY_LINALG})
        members['random'] = SafeNamespace(**{name: wrap(f'random.{name}', getattr(numpy.random, name))
                                             for name in NUMPY_RANDOM})
        return SafeNamespace(**members)

    def _make_shapely(self) -> dict[str, Any]:
        import shapely
        import shapely.affinity
        import shapely.geometry
        import shapely.ops

        wrap = self._guards['wrap_geometry_function']
        names = {name: wrap(name, getattr(shapely.geometry, name)) for name in SHAPELY_GEOMETRY}
        names.update({name: wrap(name, getattr(shapely.affinity, name)) for name in SHAPELY_AFFINITY})
        names.update({name: wrap(name, getattr(shapely.ops, name)) for name in SHAPELY_OPS})
        return names

    def wrap_callable(self, function: Callable[..., Any]) -> Callable[..., Any]:
        """A plain sandboxed function calling `function`: a checkpoint, and nothing of `function` is reachable."""
        return self._guards['wrap_callable'](function)

    def new_scope(self, names: Mapping[str, Any] | None = None) -> dict[str, Any]:
        """Globals for generated code: restricted builtins, guard helpers, np, shapely, then `names` (wrapped)."""
        scope: dict[str, Any] = {'__builtins__': dict(self.builtins), '__name__': 'generated'}
        for key, value in self._guards.items():
            if key.startswith(('op_', 'cmp_')) or key in ('augmented_item', 'tick'):
                scope[GUARD_PREFIX + key] = value
        scope[GUARD_PREFIX + 'getattr'] = self._guards['guarded_getattr']
        scope[GUARD_PREFIX + 'gettrace'] = sys.gettrace
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
                raise StopSignal(str(watchdog.stopped), watchdog.stopped.reason)
        except StopSignal as signal:
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


__all__ = ['FORBIDDEN_ATTRIBUTES', 'FORBIDDEN_ATTRIBUTE_PREFIXES', 'FORBIDDEN_NAMES', 'IN_PROCESS_WARNING', 'MAX_TEXT',
           'SANDBOX_FILE_PREFIX',
           'CompiledProgram', 'SafeNamespace', 'Sandbox', 'SandboxLimits', 'Watchdog', 'bounded_exception_text',
           'bounded_text', 'check_code', 'rewrite']
