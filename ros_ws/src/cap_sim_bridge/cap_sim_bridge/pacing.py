"""Keeping simulated time in step with the wall clock (or not): the physics loop's pacing, without ROS."""
from __future__ import annotations

import time
from typing import Callable


class Pacer:
    """Tells the physics loop how long to wait so that simulated time runs at real_time_factor x wall time.

    real_time_factor <= 0 means as fast as possible (never wait). When the simulation falls behind by more than
    max_lag seconds (a slow step, a reset, a debugger) the pacer starts afresh instead of racing to catch up.
    """

    def __init__(self, real_time_factor: float, max_lag: float = 0.2,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.real_time_factor = real_time_factor
        self.max_lag = max_lag
        self._clock = clock
        self._anchor: tuple[float, float] | None = None  # (wall, sim) at the start of the current run

    def restart(self) -> None:
        """Pace afresh from the next call (after simulated time jumped, e.g. objects settling on a reset)."""
        self._anchor = None

    def delay(self, sim_time: float) -> float:
        """Seconds of wall time to wait before simulating beyond sim_time."""
        if self.real_time_factor <= 0:
            return 0.0
        now = self._clock()
        if self._anchor is None or sim_time < self._anchor[1]:
            self._anchor = (now, sim_time)
            return 0.0
        due = self._anchor[0] + (sim_time - self._anchor[1]) / self.real_time_factor
        if now - due > self.max_lag:
            self._anchor = (now, sim_time)
            return 0.0
        return max(0.0, due - now)


class LoopPacing:
    """The physics loop's wait: real time at real_time_factor, or as fast as possible, slowed to idle_speed while
    the world is idle (a graph spinning its physics at full speed while it waits for a program or a model takes
    the CPU from them; the waits on simulated time meanwhile stay short).

    real_time_factor > 0: paced at that factor, idle or not. Otherwise as fast as possible while busy, and at
    idle_speed x wall time while idle (idle_speed <= 0: as fast as possible then too).
    """

    def __init__(self, real_time_factor: float, idle_speed: float = 0.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self._pacer = Pacer(real_time_factor, clock=clock)
        self._idle_pacer = Pacer(idle_speed, clock=clock) if real_time_factor <= 0 and idle_speed > 0 else None
        self._was_idle = False

    @property
    def slows_when_idle(self) -> bool:
        """True when idleness changes the pace (as fast as possible with an idle speed)."""
        return self._idle_pacer is not None

    def restart(self) -> None:
        """Pace afresh from the next call (after simulated time jumped, e.g. a reset)."""
        self._pacer.restart()
        if self._idle_pacer is not None:
            self._idle_pacer.restart()

    def delay(self, sim_time: float, idle: bool) -> float:
        """Seconds of wall time to wait before simulating beyond sim_time."""
        if self._idle_pacer is None:
            return self._pacer.delay(sim_time)
        if not idle:
            self._was_idle = False
            return 0.0
        if not self._was_idle:  # idle from here: paced from now, not from an earlier idle spell
            self._idle_pacer.restart()
            self._was_idle = True
        return self._idle_pacer.delay(sim_time)
