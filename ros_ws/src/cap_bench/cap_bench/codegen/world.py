"""The table-top world of the robot-API problems: named objects with positions, sizes and visibility, and the log of
the robot actions a function asked for.

A scene is a JSON-like mapping, {'objects': [{'name': 'red block', 'pos': [x, y], 'size': [w, d], 'visible': True},
...]}, in world metres on the project's table (cap_tabletop.workspace). Object names are "<colour> <kind>".
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Mapping

import numpy as np

from cap_tabletop.workspace import SPAWN_X_RANGE, SPAWN_Y_RANGE, on_table

COLOURS: tuple[str, ...] = ('red', 'orange', 'yellow', 'green', 'cyan', 'blue', 'purple', 'pink', 'brown', 'gray')
# Footprint edge [m] per kind (square footprints: largest by area, by edge or by perimeter is the same object),
# drawn per object so that sizes differ.
SIZE_RANGES: dict[str, tuple[float, float]] = {'block': (0.03, 0.06), 'bowl': (0.08, 0.14)}
# Positions in the action log are rounded: the same place reached by other float arithmetic logs the same entry.
ACTION_DECIMALS = 6

API_DESCRIPTION = """\
# Robot API (positions are np.array([x, y]) in metres on the table; +x is to the right, +y to the top):
#   names = get_obj_names()                  names of the objects on the table, e.g. ['red block', 'blue bowl']
#   pos = get_obj_pos(obj_name)              position of the object's centre
#   bbox = get_bbox(obj_name)                its footprint, np.array([x_min, y_min, x_max, y_max])
#   visible = is_obj_visible(obj_name)       whether the camera sees an object of that name now
#   put_first_on_second(obj_name, target)    pick up the object and put it on the object named target, or at the
#                                            position target
#   say(text)                                say text to the user"""


@dataclass(frozen=True)
class SceneObject:
    """One object of a scene."""

    name: str
    pos: tuple[float, float]
    size: tuple[float, float]  # footprint along x and y
    visible: bool = True


MAX_ACTIONS = 1_000  # per case; the problems ask for a handful
MAX_SAY_CHARS = 10_000


def _position(value: Any, what: str) -> tuple[float, float]:
    """A position argument of the API as two finite floats (a third coordinate, a height, is ignored)."""
    if isinstance(value, (str, bytes)):
        raise ValueError(f'{what} must be a position [x, y], got {value!r}')
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f'{what} must be a position [x, y], got {value!r}') from None
    if array.shape not in ((2,), (3,)) or not np.all(np.isfinite(array)):
        raise ValueError(f'{what} must be a position [x, y] of finite numbers, got {value!r}')
    return float(array[0]), float(array[1])


def _logged(position: tuple[float, float]) -> list[float]:
    return [round(coordinate, ACTION_DECIMALS) + 0.0 for coordinate in position]  # + 0.0: no -0.0 in the log


class CodegenWorld:
    """A deterministic table-top stand-in for the robot API problems (no simulator: these problems are judged on
    return values and on the sequence of robot actions the function asked for)."""

    def __init__(self) -> None:
        self.actions: list[dict[str, Any]] = []
        self._objects: dict[str, SceneObject] = {}

    # -- cases ------------------------------------------------------------------------------------------
    def begin_case(self, scene: Mapping | None) -> None:
        """Load the objects of a case's scene (none for None) and start a new action log."""
        self.actions = []
        self._objects = {}
        for entry in (scene or {}).get('objects', ()):
            item = SceneObject(name=str(entry['name']), pos=_position(entry['pos'], 'pos'),
                               size=_position(entry['size'], 'size'), visible=bool(entry.get('visible', True)))
            if item.name in self._objects:
                raise ValueError(f'the scene names {item.name!r} twice')
            self._objects[item.name] = item

    def api(self) -> dict[str, Callable[..., Any]]:
        """The robot API functions generated code calls, by name."""
        return {'get_obj_names': self.get_obj_names, 'get_obj_pos': self.get_obj_pos, 'get_bbox': self.get_bbox,
                'is_obj_visible': self.is_obj_visible, 'put_first_on_second': self.put_first_on_second,
                'say': self.say}

    # -- perception -------------------------------------------------------------------------------------
    def _object(self, name: Any) -> SceneObject:
        if not isinstance(name, str):
            raise ValueError(f'an object name must be a string, got {name!r}')
        if name not in self._objects:
            raise ValueError(f'there is no object named {name!r}; objects: {list(self._objects)}')
        return self._objects[name]

    def get_obj_names(self) -> list[str]:
        return list(self._objects)

    def get_obj_pos(self, name: str) -> np.ndarray:
        return np.array(self._object(name).pos, dtype=float)

    def get_bbox(self, name: str) -> np.ndarray:
        item = self._object(name)
        half = np.array(item.size) / 2
        return np.concatenate([np.array(item.pos) - half, np.array(item.pos) + half])

    def is_obj_visible(self, name: str) -> bool:
        if not isinstance(name, str):
            raise ValueError(f'an object name must be a string, got {name!r}')
        item = self._objects.get(name)
        return item is not None and item.visible

    # -- actions ----------------------------------------------------------------------------------------
    def put_first_on_second(self, obj_name: str, target: Any) -> None:
        """Move the object onto the named object, or to a position on the table; log the action."""
        item = self._object(obj_name)
        if isinstance(target, str):
            if target == obj_name:
                raise ValueError(f'cannot put the {obj_name} on itself')
            position = self._object(target).pos
            logged: Any = target
        else:
            position = _position(target, 'target')
            if not on_table(*position):
                raise ValueError(f'the target {list(position)} is not on the table')
            logged = _logged(position)
        self._log({'action': 'put_first_on_second', 'obj': obj_name, 'target': logged})
        self._objects[obj_name] = SceneObject(item.name, position, item.size, item.visible)

    def say(self, text: str) -> None:
        if not isinstance(text, str):
            raise ValueError(f'say() takes a string, got {text!r}')
        if len(text) > MAX_SAY_CHARS:
            raise ValueError(f'say() takes at most {MAX_SAY_CHARS:,} characters')
        self._log({'action': 'say', 'text': text})

    def _log(self, action: dict[str, Any]) -> None:
        if len(self.actions) >= MAX_ACTIONS:  # the host keeps the log: a program may not grow it without bound
            raise ValueError(f'more than {MAX_ACTIONS:,} robot actions in one case')
        self.actions.append(action)


def random_scene(rng: np.random.Generator, counts: Mapping[str, int], hidden: int = 0) -> dict[str, Any]:
    """A scene with `counts[kind]` objects of each kind in distinct colours, in random order at random places of the
    spawn area (millimetre coordinates), `hidden` of them not visible."""
    names = [f'{colour} {kind}' for kind, count in counts.items()
             for colour in rng.choice(COLOURS, size=count, replace=False)]
    order = rng.permutation(len(names))
    hidden_names = {names[i] for i in rng.choice(len(names), size=hidden, replace=False)} if hidden else set()
    objects = []
    for i in order:
        name = names[i]
        low, high = SIZE_RANGES[name.split(' ')[-1]]
        edge = round(float(rng.uniform(low, high)), 3)
        objects.append({'name': name,
                        'pos': [round(float(rng.uniform(*SPAWN_X_RANGE)), 3),
                                round(float(rng.uniform(*SPAWN_Y_RANGE)), 3)],
                        'size': [edge, edge], 'visible': name not in hidden_names})
    return {'objects': objects}


def footprint_area(entry: Mapping[str, Any]) -> float:
    """Area of a scene object's footprint."""
    return math.prod(entry['size'])
