"""When the simulated world is idle: no motion commanded and everything still. Plain Python, no ROS.

An idle bridge in real time publishes less (the idle rates of SimBridgeConfig): with nothing moving, a /clock and
/joint_states at 100 Hz and fresh camera renders at 10 Hz cost a third of a core and tell subscribers nothing new.
"""
from __future__ import annotations

import math

REST_SPEED = 1e-3  # [m/s or rad/s] every joint of the model (arm, fingers, objects) slower than this is still


class RestWatch:
    """Says, one physics tick after another, whether the world has been idle for `after` seconds of simulated time.

    Idle ends at once when a goal runs or anything moves; it begins again only after a whole `after` of stillness.
    `after` <= 0 switches idling off (never idle).
    """

    def __init__(self, after: float, rest_speed: float = REST_SPEED) -> None:
        self.after = after
        self.rest_speed = rest_speed
        self._still_since: float | None = None

    def wake(self) -> None:
        """Something happened outside the physics (a goal, a reset): not idle until still again for `after`."""
        self._still_since = None

    def update(self, sim_time: float, busy: bool, max_speed: float) -> bool:
        """True while idle: no goal running (`busy` false) and `max_speed` below the rest speed for `after` s."""
        if self.after <= 0 or busy or not math.isfinite(max_speed) or max_speed >= self.rest_speed:
            self._still_since = None
            return False
        if self._still_since is None or sim_time < self._still_since:
            self._still_since = sim_time
        return sim_time - self._still_since >= self.after
