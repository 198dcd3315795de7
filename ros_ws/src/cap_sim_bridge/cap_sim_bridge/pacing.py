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
