"""The toy domain's world in memory: named objects at xy positions on a board, a voice and a bell.

No simulator: `put_first_on_second` moves the object to the target at once. It lets the engine's tests run real
generated programs against a world whose state they can check. The functions raise errors with messages a person
understands, as a robot's binding does.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

import numpy as np

MAX_RINGS = 10  # ring_bell(times) takes 1 to MAX_RINGS


class UnknownObjectError(ValueError):
    """The program named an object that is not on the board."""


def bell_rings(times: Any) -> int:
    """`times` if ring_bell may ring that often (a whole number from 1 to MAX_RINGS), else a ValueError."""
    if not isinstance(times, int) or isinstance(times, bool) or not 1 <= times <= MAX_RINGS:
        raise ValueError(f'ring_bell(times) takes a whole number from 1 to {MAX_RINGS}')
    return times


@dataclass
class ToyWorld:
    """Object positions by name; `said` collects what the program said, `moves` every put_first_on_second and
    `rings` every ring_bell."""

    positions: dict[str, np.ndarray] = field(default_factory=dict)
    said: list[str] = field(default_factory=list)
    moves: list[tuple[str, Any]] = field(default_factory=list)
    rings: list[int] = field(default_factory=list)

    @classmethod
    def with_objects(cls, positions: Mapping[str, Sequence[float]]) -> 'ToyWorld':
        return cls({name: np.array(xy, dtype=float) for name, xy in positions.items()})

    def _position(self, name: Any) -> np.ndarray:
        if not isinstance(name, str) or name not in self.positions:
            known = ', '.join(self.positions)
            raise UnknownObjectError(f'there is no object called {name!r} on the board (objects: {known})')
        return self.positions[name]

    # -- what reads the world --------------------------------------------------------------------------------
    def get_obj_names(self) -> list[str]:
        return list(self.positions)

    def get_obj_pos(self, name: str) -> np.ndarray:
        return self._position(name).copy()

    # -- what acts on it -------------------------------------------------------------------------------------
    def put_first_on_second(self, obj_name: str, target: Any) -> None:
        """Move the object onto the target object, or to the target point [x, y]."""
        self._position(obj_name)
        if isinstance(target, str):
            xy = self._position(target).copy()
        else:
            xy = np.asarray(target, dtype=float).reshape(-1)[:2]
            if xy.shape != (2,) or not np.all(np.isfinite(xy)):
                raise ValueError(f'cannot place the {obj_name} at {target!r}: expected a position [x, y]')
        self.positions[obj_name] = xy
        self.moves.append((obj_name, target))

    def say(self, text: Any) -> None:
        self.said.append(str(text))

    def ring_bell(self, times: int) -> None:
        """Ring the bell `times` times (1 to MAX_RINGS)."""
        self.rings.append(bell_rings(times))

    def api(self) -> dict[str, Callable[..., Any]]:
        """The toy domain's robot functions bound to this world."""
        return {'get_obj_names': self.get_obj_names, 'get_obj_pos': self.get_obj_pos,
                'put_first_on_second': self.put_first_on_second, 'say': self.say, 'ring_bell': self.ring_bell}


__all__ = ['MAX_RINGS', 'ToyWorld', 'UnknownObjectError', 'bell_rings']
