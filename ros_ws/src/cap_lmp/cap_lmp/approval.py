"""Approval before a program runs: a plan-only run of it, a gate a person answers, and a guard that holds the run
to what was approved.

With an approval gate set (`Engine.approval`), a command's checked code is first run in plan-only mode, in the same
sandbox with the same limits, over a copy of the session (session_copy: every value copied, so a rejected plan
leaves the session as it was) in which each of the engine's `plan_functions` (the robot API functions that act:
move the robot, speak) records its call instead of making it. Everything else runs as usual: the program reads the
world as it is now (perception), and nested LMPs are asked as usual, their answers kept for the command, so that
the run after approval executes the code that was planned. The gate is then called with the code (nested LMPs'
code included) and the recorded calls; it returns once a person approved, and raises NotApproved (rejected, not
approved in time) or ExecutionStopped (cancelled) otherwise. Only then does the program run for real.

What the program does cannot be trusted to match its plan (a program can tell the plan-only run from the real one:
a recorded move changes nothing), so the node that owns the robot holds it to the plan with an ApprovalGuard, on
its side of every robot call and model request: before approval no acting call goes through; after approval each
acting call must be the next call of the approved plan (same function, same arguments; numbers within
MATCH_TOLERANCE), and no model request goes through (the approved code is all the code there is). A call that
breaks this is refused, the program is stopped and the command is refused; nothing moves that was not approved.

A plan is no simulation: a recorded motion moves nothing, so a program whose later steps read where an earlier step
put something plans them from the world as it was; if the real run then computes another motion, it is stopped
there.
"""
from __future__ import annotations

import copy
import functools
import math
import threading
import types
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from cap_lmp.errors import NotApproved, RobotApiError, UnapprovedAction
from cap_lmp.wire import CallableHandle

MAX_PLANNED_CALLS = 200  # a program that would make more motions than this is not planned (nor run)
# What one plan may hold, arguments of all its calls together: it travels to the node in one message and is
# compared call by call, so it is recorded in full (a stroke of the whiteboard's 5,000 points included).
MAX_PLAN_VALUES = 100_000  # numbers, texts, flags
MAX_PLAN_CHARS = 500_000  # characters of its texts
_MAX_DEPTH = 8  # of nested lists and dicts in one argument
# Numbers of an approved call and of the real one may differ by this much (metres, radians): a program that reads
# the world again after approval gets the same objects where perception saw them, within its noise.
MATCH_TOLERANCE = 0.005
FUNCTION = '<function>'  # a function of the program passed to a robot call (a controller), as a plan shows it


class PlanError(RobotApiError):
    """A call's arguments cannot be recorded for approval in full (too large, nested too deep, not plain data)."""


@dataclass(frozen=True)
class PlannedCall:
    """One call a program would make of a function that acts (moves the robot, speaks), with plain arguments."""

    function: str
    args: tuple[Any, ...] = ()
    kwargs: dict[str, Any] = field(default_factory=dict)

    def to_wire(self) -> dict[str, Any]:
        return {'function': self.function, 'args': list(self.args), 'kwargs': dict(self.kwargs)}

    def text(self, limit: int = 200) -> str:
        """The call as code, cut to `limit` characters: `put_first_on_second('red block', [0.1, -0.5])`."""
        words = [repr(arg) for arg in self.args] + [f'{key}={value!r}' for key, value in self.kwargs.items()]
        text = f"{self.function}({', '.join(words)})"
        return text if len(text) <= limit else text[:limit - 3] + '...'


# gate(code, plan): returns when the code may run; raises NotApproved or ExecutionStopped when it must not.
ApprovalGate = Callable[[str, list[PlannedCall]], None]


class PlanBudget:
    """What is left of one plan's MAX_PLAN_VALUES and MAX_PLAN_CHARS."""

    def __init__(self, values: int = MAX_PLAN_VALUES, chars: int = MAX_PLAN_CHARS) -> None:
        self.values, self.chars = values, chars

    def spend(self, values: int, chars: int = 0) -> None:
        self.values -= values
        self.chars -= chars
        if self.values < 0 or self.chars < 0:
            raise PlanError(f'the robot actions\' arguments are larger than a plan can show (more than '
                            f'{MAX_PLAN_VALUES:,} values or {MAX_PLAN_CHARS:,} characters); the program was not run')


def plain(value: Any, budget: PlanBudget | None = None, depth: int = 0) -> Any:
    """`value` in full as JSON-like data for a plan: numbers, texts, lists, dicts; a function as FUNCTION.

    A plan is what a person approves and what the real run is held to, so nothing is cut short or summarised:
    PlanError for what cannot be shown as it is (another kind of object, a huge integer, too much in `budget`).
    """
    budget = budget if budget is not None else PlanBudget()
    if depth > _MAX_DEPTH:
        raise PlanError(f'a robot action\'s argument is nested more than {_MAX_DEPTH} levels deep')
    if value is None or isinstance(value, (bool, np.bool_)):
        budget.spend(1)
        return None if value is None else bool(value)
    if isinstance(value, (int, np.integer)):
        if abs(int(value)) >= 2 ** 53:
            raise PlanError('a robot action\'s argument holds an integer too large to show exactly')
        budget.spend(1)
        return int(value)
    if isinstance(value, (float, np.floating)):
        budget.spend(1)
        number = float(value)
        return number if math.isfinite(number) else str(number)
    if isinstance(value, str):
        budget.spend(1, len(value))
        return value
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in 'biuf':
            raise PlanError(f'a robot action\'s argument is an array of {value.dtype} values, not numbers')
        if value.size > budget.values:  # before tolist() builds it
            budget.spend(int(value.size))
        return plain(value.tolist(), budget, depth)
    if isinstance(value, (list, tuple)):
        budget.spend(1)
        return [plain(item, budget, depth + 1) for item in value]
    if isinstance(value, dict):
        return {str(key): plain(item, budget, depth + 1) for key, item in value.items()}
    if isinstance(value, CallableHandle) or (callable(value) and not isinstance(value, type)):
        return FUNCTION
    raise PlanError(f'a robot action\'s argument of type {type(value).__name__} cannot be shown for approval')


def recorders(names: Iterable[str], plan: list[PlannedCall],
              calling: Mapping[str, Callable[..., Any]] | None = None) -> dict[str, Callable[..., Any]]:
    """Stand-ins for the functions `names` that append each call to `plan` (its arguments in full) and return
    None; with `calling` (a rehearsal, cap_lmp.rehearsal), that then make the call and return what it returns."""
    budget = PlanBudget()

    def recorder(name: str) -> Callable[..., Any]:
        def record(*args: Any, **kwargs: Any) -> Any:
            if len(plan) >= MAX_PLANNED_CALLS:
                raise RobotApiError(f'the program would make more than {MAX_PLANNED_CALLS} robot actions; it was '
                                    'not run')
            plan.append(PlannedCall(name, tuple(plain(arg, budget) for arg in args),
                                    {str(key): plain(item, budget) for key, item in kwargs.items()}))
            return calling[name](*args, **kwargs) if calling is not None else None
        record.__name__ = name
        return record

    return {name: recorder(name) for name in names}


def planned_call(values: Any, budget: PlanBudget | None = None) -> PlannedCall:
    """A PlannedCall from its wire form (a dict from the sandbox process), every field checked (ValueError)."""
    if not isinstance(values, dict):
        raise ValueError('a planned call is not an object')
    function, args, kwargs = values.get('function'), values.get('args', []), values.get('kwargs', {})
    if not isinstance(function, str) or not function.isidentifier() or len(function) > 100:
        raise ValueError('a planned call names no function')
    if not isinstance(args, list) or not isinstance(kwargs, dict) or len(args) > 20 or len(kwargs) > 20:
        raise ValueError('malformed arguments of a planned call')
    budget = budget if budget is not None else PlanBudget()
    try:
        return PlannedCall(function, tuple(plain(arg, budget) for arg in args),
                           {str(key)[:100]: plain(item, budget) for key, item in kwargs.items()})
    except PlanError as error:
        raise ValueError(str(error)) from None


def same_value(planned: Any, actual: Any, tolerance: float = MATCH_TOLERANCE) -> bool:
    """Whether a real call's argument (plain) is the planned one: texts, flags and shapes exactly, numbers within
    `tolerance`."""
    if planned is None or actual is None:
        return planned is actual
    if isinstance(planned, bool) or isinstance(actual, bool):
        return type(planned) is type(actual) and planned == actual
    if isinstance(planned, (int, float)) and isinstance(actual, (int, float)):
        return abs(planned - actual) <= tolerance
    if isinstance(planned, str) or isinstance(actual, str):
        return planned == actual
    if isinstance(planned, list) and isinstance(actual, list):
        return len(planned) == len(actual) and all(same_value(p, a, tolerance) for p, a in zip(planned, actual))
    if isinstance(planned, dict) and isinstance(actual, dict):
        return planned.keys() == actual.keys() and all(same_value(planned[k], actual[k], tolerance)
                                                       for k in planned)
    return False


def session_copy(scope: Mapping[str, Any], shared: Iterable[Any] = ()) -> dict[str, Any]:
    """A copy of a session's scope for a plan-only run: whatever the run changes, the session keeps what it had.

    Values are deep-copied; `shared` values (the robot API, the LMPs, np), modules, dunder names and the sandbox's
    own helpers stay as they are. Functions the session's programs defined are rebound to the copy, so that calling
    one during the plan reads and writes the copy (and calls the recorders). A value that cannot be copied (a
    generator) makes the plan impossible: PlanError naming it.
    """
    copied: dict[str, Any] = {}
    memo: dict[int, Any] = {id(value): value for value in shared}
    memo[id(scope)] = copied
    for value in scope.values():
        if isinstance(value, types.FunctionType) and value.__globals__ is scope and id(value) not in memo:
            memo[id(value)] = types.FunctionType(value.__code__, copied, value.__name__, None, value.__closure__)
    for name, value in scope.items():
        if name.startswith('_') or isinstance(value, types.ModuleType) or id(value) in memo and \
                not isinstance(value, types.FunctionType):
            copied[name] = value
            continue
        try:
            copied[name] = copy.deepcopy(value, memo)
        except Exception as error:  # whatever the object's own __deepcopy__ or __reduce__ raised
            raise PlanError(f'the session\'s variable {name} ({type(value).__name__}) cannot be copied for the '
                            f'plan-only run ({type(error).__name__}); reset the session to plan') from None
    for original in scope.values():  # defaults and attributes of the rebound functions, from the copy too
        rebound = memo.get(id(original))
        if isinstance(original, types.FunctionType) and rebound is not original and \
                isinstance(rebound, types.FunctionType):
            rebound.__defaults__ = copy.deepcopy(original.__defaults__, memo)
            rebound.__kwdefaults__ = copy.deepcopy(original.__kwdefaults__, memo)
            rebound.__dict__.update(copy.deepcopy(original.__dict__, memo))
    return copied


OFF, PLANNING, APPROVED = 'off', 'planning', 'approved'


class ApprovalGuard:
    """The node's record of what a person approved, checked on the node's side of every robot call and model
    request of a program (see the module docstring). Thread-safe; one command at a time.

    `acting`: the robot functions that act (a domain's plan_functions); the others only read the world and are
    never held back. A violation is final for the command: every later acting call and model request is refused
    too, and `violation` says what happened.
    """

    def __init__(self, acting: Iterable[str]) -> None:
        self.acting = frozenset(acting)
        self._lock = threading.Lock()
        self.phase = OFF
        self._plan: list[PlannedCall] = []
        self._next = 0
        self.violation = ''
        self.tolerance = MATCH_TOLERANCE
        self.held_to = 'the approved plan'  # what the run is held to, in refusals
        self.unheld: frozenset[str] = frozenset()  # acting functions this command is not held to

    def begin(self, required: bool, tolerance: float = MATCH_TOLERANCE, held_to: str = 'the approved plan',
              unheld: Iterable[str] = ()) -> None:
        """A new command: held to approval (`required`) or not; numbers of a real call may differ from the plan's
        by `tolerance` (a rehearsed plan was computed on a twin, whose objects end a little off the real ones);
        the `unheld` functions go through as they come (left out of the plan too)."""
        with self._lock:
            self.phase = PLANNING if required else OFF
            self._plan, self._next, self.violation = [], 0, ''
            self.tolerance, self.held_to, self.unheld = tolerance, held_to, frozenset(unheld)

    def may_ask(self) -> None:
        """Before a person is asked: NotApproved if the program already broke the rules or was approved once (a
        command is approved once; a second request would show a plan the guard does not hold the run to)."""
        with self._lock:
            if self.phase == APPROVED and not self.violation:
                self.violation = 'the program asked for approval a second time; it was refused and the program stopped'
            if self.violation:
                raise NotApproved(f'{self.violation}; nothing more ran', 'rejected')

    def approve(self, plan: Sequence[PlannedCall]) -> None:
        """A person approved `plan`: from now on the program may make exactly these acting calls, in this order.
        NotApproved if the program already broke the rules (it is not run on)."""
        with self._lock:
            if self.violation:
                raise NotApproved(f'{self.violation}; nothing more ran', 'rejected')
            if self.phase == PLANNING:
                self.phase, self._next = APPROVED, 0
                self._plan = [call for call in plan if call.function not in self.unheld]

    def check_call(self, function: str, args: Sequence[Any], kwargs: Mapping[str, Any]) -> None:
        """Before a robot call goes through: UnapprovedAction if it must not."""
        if function not in self.acting:
            return
        with self._lock:
            if self.phase == OFF or function in self.unheld:
                return
            if self.violation:
                raise UnapprovedAction(self.violation)
            try:
                actual = PlannedCall(function, tuple(plain(arg) for arg in args),
                                     {str(key): plain(item) for key, item in kwargs.items()})
            except PlanError as error:
                self._refuse(f'the program called {function}() with arguments that cannot be compared with the '
                             f'approved plan ({error})')
            if self.phase == PLANNING:
                self._refuse(f'the program called {actual.text()} before it was approved')
            if self._next >= len(self._plan):
                self._refuse(f'the program called {actual.text()} after the {len(self._plan)} action(s) of '
                             f'{self.held_to}')
            expected = self._plan[self._next]
            if not (expected.function == actual.function
                    and same_value(list(expected.args), list(actual.args), self.tolerance)
                    and same_value(dict(expected.kwargs), dict(actual.kwargs), self.tolerance)):
                self._refuse(f'the program called {actual.text()} where {self.held_to}\'s action '
                             f'{self._next + 1} is {expected.text()}')
            self._next += 1

    def check_model_request(self, lmp: str, query: str) -> None:
        """Before a model request goes through: UnapprovedAction once the program runs approved."""
        with self._lock:
            if self.violation:
                raise UnapprovedAction(self.violation)
            if self.phase == APPROVED:
                self._refuse(f'after approval the program asked the model for new code ({lmp}: {query[:200]!r}), '
                             'code nobody reviewed')

    def _refuse(self, what: str) -> None:
        self.violation = f'{what}; it was refused and the program stopped'
        raise UnapprovedAction(self.violation)


def guarded_functions(functions: Mapping[str, Callable[..., Any]], guard: ApprovalGuard,
                      on_refusal: Callable[[], None]) -> dict[str, Callable[..., Any]]:
    """`functions` (the robot API) with `guard` checking every call before it goes through; `on_refusal` is called
    when it refuses one (the node stops the program), then UnapprovedAction is raised to the caller."""

    def guarded(name: str, function: Callable[..., Any]) -> Callable[..., Any]:
        @functools.wraps(function)
        def call(*args: Any, **kwargs: Any) -> Any:
            try:
                guard.check_call(name, args, kwargs)
            except UnapprovedAction:
                on_refusal()
                raise
            return function(*args, **kwargs)
        return call

    return {name: guarded(name, function) for name, function in functions.items()}


class GuardedClient:
    """A model client whose requests `guard` checks first (no new code once a program runs approved); anything
    else is the wrapped client's."""

    def __init__(self, client: Any, guard: ApprovalGuard, on_refusal: Callable[[], None]) -> None:
        self._client, self._guard, self._on_refusal = client, guard, on_refusal

    def complete(self, request: Any) -> Any:
        try:
            self._guard.check_model_request(str(request.lmp), str(request.query))
        except UnapprovedAction:
            self._on_refusal()
            raise
        return self._client.complete(request)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._client, name)


__all__ = ['APPROVED', 'FUNCTION', 'MATCH_TOLERANCE', 'MAX_PLANNED_CALLS', 'MAX_PLAN_CHARS', 'MAX_PLAN_VALUES', 'OFF',
           'PLANNING', 'ApprovalGate', 'ApprovalGuard', 'GuardedClient', 'PlanBudget', 'PlanError', 'PlannedCall',
           'guarded_functions', 'plain', 'planned_call', 'recorders', 'same_value', 'session_copy']
