"""Rehearsal on a twin: a program runs on a simulated copy of the world before the robot moves (plain Python).

With rehearsal on (lmp_node's `rehearse`), a command's program is first run whole, nested LMPs and generated
functions included, with every robot call answered by the twin: a simulator reset to the scene as the graph
perceives it, driven by the same robot API and control nodes as the robot. The engine's plan phase (approval.py)
carries it: `Engine.rehearse` makes the plan run call the acting functions instead of only recording them, and the
node routes those calls to the twin (Rehearsal.routed), on its own side of the calls, where no program reaches.

After each acting call on the twin, the node asks the twin what it saw (the arm on the table, an object knocked
over, ...: cap_sim_bridge.twin_watch); harm ends the call with TwinHarm, so the program stops on the twin at that
line, and the command is refused with what the twin saw and where. A program that fails there for any other reason
(an error, a target the controller refuses) is refused the same way. Only a rehearsal that ends clean lets the
program run on the robot, and then only the acting calls the twin received, in their order, with numbers within
REHEARSAL_TOLERANCE (approval.ApprovalGuard holds the real run to them; words are not held, UNHELD_WHEN_REHEARSED).

After the real run, `prediction_misses` compares the world with the twin's prediction: objects more than
PREDICTION_TOLERANCE from where the twin left them, and objects that moved though the twin did not move them.
"""
from __future__ import annotations

import functools
import math
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Mapping, Sequence

from cap_lmp.approval import MAX_PLANNED_CALLS, PlanBudget, PlannedCall, plain
from cap_lmp.errors import RobotApiError

REHEARSE_MODES = ('always', 'off', 'on_approval')
# A real call's numbers may differ from the rehearsed ones by this much [m, rad]: the twin's objects end up to about
# a centimetre from where the robot leaves them, and a later step that reads a position reads the real one.
REHEARSAL_TOLERANCE = 0.03
# Rehearsal holds the robot's motions to what the twin did; what the program says is not motion, and the real run
# says what it finds in the real world (its count of blocks in bowls, not the twin's). With approval on as well, the
# person approved the words too, and they are held again.
UNHELD_WHEN_REHEARSED = ('say',)
PREDICTION_TOLERANCE = 0.03  # [m] an object farther than this from where the twin left it is a miss
STILL_M = 0.01  # [m] an object the twin moved less than this, it did not move


# The node's function (in the robot API the engine is given, kept out of the program's scope) that rebuilds the twin
# for a new rehearsal of the same command: a program that failed on the twin is followed by a new one (feedback).
RESTART_REHEARSAL = 'restart_rehearsal'


class TwinHarm(RobotApiError):
    """The twin saw harm during a robot call of the rehearsal: the program stops there (and the robot never
    moves)."""


def rehearses(mode: str, approval_required: bool) -> bool:
    """Whether a command is rehearsed under `mode` (one of REHEARSE_MODES)."""
    return mode == 'always' or (mode == 'on_approval' and approval_required)


Position = tuple[float, float, float]


@dataclass
class TwinVerdict:
    """What a rehearsal came to: the acting calls the twin received, what it saw, where it left the objects."""

    calls: list[PlannedCall] = field(default_factory=list)
    findings: list[str] = field(default_factory=list)
    start: dict[str, Position] = field(default_factory=dict)  # the objects as the twin was built from them
    predicted: dict[str, Position] = field(default_factory=dict)  # where the twin left them
    build_s: float = 0.0  # wall time to build the twin [s]
    rehearse_s: float = 0.0  # wall time of the rehearsal, the program's run on the twin included [s]
    rehearse_from: float = 0.0  # time.monotonic() when the rehearsal began
    simulated_s: float = 0.0  # simulated time of the rehearsal [s]
    image_png: bytes = b''  # the twin's scene at the end

    def end_rehearsal(self) -> None:
        """The rehearsal is over (passed its gate, or failed on the twin): its time is kept, once."""
        if not self.rehearse_s:
            self.rehearse_s = time.monotonic() - self.rehearse_from

    def summary(self) -> str:
        """One line for a person: what the rehearsal found, or that it found nothing."""
        moved = sorted(name for name, where in self.predicted.items()
                       if name in self.start and _distance(where, self.start[name]) >= STILL_M)
        seen = '; '.join(self.findings) if self.findings else 'nothing went wrong'
        what = f'{len(self.calls)} action(s), {self.simulated_s:.1f} s simulated in {self.rehearse_s:.1f} s'
        return (f'rehearsed on the twin ({what}): {seen}'
                + (f'; it moves the {", the ".join(moved)}' if moved and not self.findings else ''))


def harm_text(findings: Sequence[str], function: str) -> str:
    """The message of a TwinHarm raised after `function`."""
    return f'on the twin, {function}() did harm: {"; ".join(findings)} (the robot did not move)'


class Rehearsal:
    """The node's switch between the twin and the robot for one command at a time (thread-safe).

    `acting`: the robot functions that act (a domain's plan_functions); the twin's answers to them are recorded as
    the plan the real run is held to."""

    def __init__(self, acting: Iterable[str]) -> None:
        self.acting = frozenset(acting)
        self._lock = threading.Lock()
        self.active = False
        self.calls: list[PlannedCall] = []
        self._budget = PlanBudget()

    def begin(self) -> None:
        """Route the program's calls to the twin from now on, with an empty plan."""
        with self._lock:
            self.active, self.calls, self._budget = True, [], PlanBudget()

    def end(self) -> list[PlannedCall]:
        """Route to the robot again; the acting calls the twin received."""
        with self._lock:
            self.active = False
            return list(self.calls)

    def _record(self, name: str, args: Sequence[Any], kwargs: Mapping[str, Any]) -> None:
        with self._lock:
            if len(self.calls) >= MAX_PLANNED_CALLS:
                raise RobotApiError(f'the program would make more than {MAX_PLANNED_CALLS} robot actions; it was not '
                                    'run')
            self.calls.append(PlannedCall(name, tuple(plain(arg, self._budget) for arg in args),
                                          {str(key): plain(item, self._budget) for key, item in kwargs.items()}))

    def routed(self, robot: Mapping[str, Callable[..., Any]], twin: Mapping[str, Callable[..., Any]],
               check_harm: Callable[[str], None]) -> dict[str, Callable[..., Any]]:
        """The robot API as the program gets it: while a rehearsal is active each call goes to `twin` (acting calls
        recorded first, then `check_harm(name)` after them, which raises TwinHarm), otherwise to `robot`."""

        def route(name: str) -> Callable[..., Any]:
            to_robot, to_twin = robot[name], twin[name]

            @functools.wraps(to_robot)
            def call(*args: Any, **kwargs: Any) -> Any:
                if not self.active:
                    return to_robot(*args, **kwargs)
                if name not in self.acting:
                    return to_twin(*args, **kwargs)
                self._record(name, args, kwargs)
                value = to_twin(*args, **kwargs)
                check_harm(name)
                return value
            return call

        return {name: route(name) for name in robot}


@dataclass(frozen=True)
class PredictionMiss:
    name: str
    predicted: Position
    observed: Position
    distance: float
    unexpected: bool  # the twin did not move it, yet it moved


def _distance(a: Sequence[float], b: Sequence[float]) -> float:
    return math.dist(tuple(a)[:3], tuple(b)[:3])


def prediction_misses(start: Mapping[str, Position], predicted: Mapping[str, Position],
                      observed: Mapping[str, Position], before: Mapping[str, Position] | None = None,
                      tolerance: float = PREDICTION_TOLERANCE) -> list[PredictionMiss]:
    """The objects seen after the real run (`observed`) that are more than `tolerance` from where the twin left
    them; an object the twin did not move (from `start`) that moved from where it was before the real run (`before`,
    default `start`) is `unexpected`. Objects the twin does not know, or perception does not see, are not
    compared."""
    before = before if before is not None else start
    misses = []
    for name in sorted(set(predicted) & set(observed)):
        distance = _distance(predicted[name], observed[name])
        still_on_twin = name in start and _distance(start[name], predicted[name]) < STILL_M
        moved_for_real = name in before and _distance(before[name], observed[name]) > tolerance
        unexpected = still_on_twin and moved_for_real
        if distance > tolerance or unexpected:
            misses.append(PredictionMiss(name, tuple(predicted[name]), tuple(observed[name]), distance, unexpected))
    return misses


def prediction_text(misses: Sequence[PredictionMiss], compared: int, tolerance: float = PREDICTION_TOLERANCE) -> str:
    """The prediction-versus-outcome line of a rehearsed command's result."""
    if compared == 0:
        return 'the twin\'s prediction could not be compared: perception saw none of its objects'
    if not misses:
        return f'as the twin predicted: all {compared} object(s) within {100 * tolerance:.0f} cm of where it left them'
    parts = [f'the {miss.name} is {100 * miss.distance:.1f} cm from where the twin left it'
             + (' (the twin did not move it)' if miss.unexpected else '') for miss in misses]
    return f'{len(misses)} of {compared} object(s) not where the twin predicted: ' + '; '.join(parts)


__all__ = ['PREDICTION_TOLERANCE', 'REHEARSAL_TOLERANCE', 'REHEARSE_MODES', 'RESTART_REHEARSAL',
           'UNHELD_WHEN_REHEARSED', 'PredictionMiss', 'Rehearsal', 'TwinHarm', 'TwinVerdict', 'harm_text',
           'prediction_misses', 'prediction_text', 'rehearses']
