"""A table top in memory: objects at xy positions and the table-top robot API of generated code over it.

Not a simulator: `put_first_on_second` moves the object to the target instantly. It lets the engine's tests and
benchmark run real generated programs against a world whose state they can check, without ROS or MuJoCo. The API
functions raise errors with messages a person understands, like the ROS binding does.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from cap_lmp_ros.domains.tabletop.lmps import denormalize_xy, get_corner_name, get_side_name
from cap_tabletop.objects import BLOCK_SIZE, BOWL_RIM_RADIUS
from cap_tabletop.workspace import on_table

BOWL_SIZE = 2 * BOWL_RIM_RADIUS  # across the rim


class UnknownObjectError(ValueError):
    """The program named an object that is not on the table."""


@dataclass
class TableObject:
    name: str
    xy: np.ndarray
    height: float = 0.0  # z of the object's base, for stacking

    @property
    def kind(self) -> str:
        return self.name.split()[-1]

    @property
    def color(self) -> str:
        return self.name.split()[0]


@dataclass
class Table:
    """Objects by name; `said` collects what the program said; `moves` every put_first_on_second."""

    objects: dict[str, TableObject] = field(default_factory=dict)
    said: list[str] = field(default_factory=list)
    moves: list[tuple[str, Any]] = field(default_factory=list)
    moved_from: dict[str, np.ndarray] = field(default_factory=dict)  # this command's, as RosTabletopApi keeps them
    last_moved_from: dict[str, np.ndarray] = field(default_factory=dict)

    @classmethod
    def with_objects(cls, positions: Mapping[str, Sequence[float]]) -> 'Table':
        return cls({name: TableObject(name, np.array(xy, dtype=float)) for name, xy in positions.items()})

    def _get(self, name: str) -> TableObject:
        if not isinstance(name, str) or name not in self.objects:
            known = ', '.join(self.objects)
            raise UnknownObjectError(f'there is no object called {name!r} on the table (objects: {known})')
        return self.objects[name]

    def get_obj_names(self) -> list[str]:
        return list(self.objects)

    def get_obj_pos(self, name: str) -> np.ndarray:
        return self._get(name).xy.copy()

    def get_bbox(self, name: str) -> np.ndarray:
        obj = self._get(name)
        half = (BLOCK_SIZE if obj.kind == 'block' else BOWL_SIZE) / 2
        return np.array([obj.xy[0] - half, obj.xy[1] - half, obj.xy[0] + half, obj.xy[1] + half])

    def get_color(self, name: str) -> str:
        return self._get(name).color

    def is_obj_visible(self, name: str) -> bool:
        return name in self.objects

    def begin_command(self) -> None:
        if self.moved_from:
            self.last_moved_from, self.moved_from = self.moved_from, {}

    def get_pos_before_last_command(self, name: str) -> np.ndarray:
        return self.last_moved_from.get(name, self._get(name).xy).copy()

    def put_first_on_second(self, obj_name: str, target: Any) -> None:
        obj = self._get(obj_name)
        self.moved_from.setdefault(obj_name, obj.xy.copy())
        if obj.kind != 'block':
            raise ValueError(f'the robot can only pick up blocks, not the {obj_name}')
        if isinstance(target, str):
            base = self._get(target)
            xy, height = base.xy.copy(), base.height + (BLOCK_SIZE if base.kind == 'block' else 0.0)
        else:
            xy = np.asarray(target, dtype=float).reshape(-1)[:2]
            if xy.shape != (2,) or not np.all(np.isfinite(xy)):
                raise ValueError(f'cannot place the {obj_name} at {target!r}: expected a position [x, y]')
            if not on_table(xy[0], xy[1]):
                raise ValueError(f'cannot place the {obj_name} at ({xy[0]:.2f}, {xy[1]:.2f}): outside the table')
            height = 0.0
        obj.xy, obj.height = xy, height
        self.moves.append((obj_name, target))

    def say(self, text: Any) -> None:
        self.said.append(str(text))

    def api(self) -> dict[str, Callable[..., Any]]:
        """The table-top robot API bound to this table."""
        return {'get_obj_names': self.get_obj_names, 'get_obj_pos': self.get_obj_pos, 'get_bbox': self.get_bbox,
                'get_color': self.get_color, 'is_obj_visible': self.is_obj_visible,
                'put_first_on_second': self.put_first_on_second, 'say': self.say,
                'get_pos_before_last_command': self.get_pos_before_last_command,
                'denormalize_xy': denormalize_xy, 'get_corner_name': get_corner_name,
                'get_side_name': get_side_name}
