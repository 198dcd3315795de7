"""What perception knows about one object, independent of ROS messages and of where the knowledge came from."""
from __future__ import annotations

from dataclasses import dataclass, field

from cap_tabletop.objects import CATEGORIES
from cap_tabletop.palette import PALETTE, rgba

from cap_perception.names import canonical_name


@dataclass(frozen=True)
class PerceivedObject:
    """One object in the world frame (metres). `position` is the centre of the axis-aligned bounding box."""

    name: str
    category: str
    color_name: str
    position: tuple[float, float, float]
    bbox_min: tuple[float, float, float]
    bbox_max: tuple[float, float, float]
    orientation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)  # x, y, z, w
    visible: bool = True
    color_rgba: tuple[float, float, float, float] = field(default=(0.5, 0.5, 0.5, 1.0))

    @staticmethod
    def from_fields(color_name: str, category: str, position, size, visible: bool = True) -> 'PerceivedObject':
        """Build an object from its colour, category, centre and box size [m]; palette colour filled in."""
        if category not in CATEGORIES:
            raise ValueError(f'unknown object category {category!r}; expected one of {", ".join(CATEGORIES)}')
        if color_name not in PALETTE:
            raise ValueError(f'unknown colour {color_name!r}; expected one of {", ".join(PALETTE)}')
        centre = tuple(float(v) for v in position)
        half = tuple(float(s) / 2.0 for s in size)
        if len(centre) != 3 or len(half) != 3:
            raise ValueError('position and size need three values each (x, y, z)')
        return PerceivedObject(
            name=canonical_name(f'{color_name} {category}'),
            category=category,
            color_name=color_name,
            position=centre,
            bbox_min=tuple(c - h for c, h in zip(centre, half)),
            bbox_max=tuple(c + h for c, h in zip(centre, half)),
            visible=visible,
            color_rgba=rgba(color_name),
        )
