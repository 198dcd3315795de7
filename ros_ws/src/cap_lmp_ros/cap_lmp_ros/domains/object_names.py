"""What a generated program most likely meant as one object's name (pure; shared by the domains' robot APIs)."""
from __future__ import annotations

from typing import Any


def object_name_candidate(name: Any) -> str | None:
    """What a program most likely meant as one object's name: the text itself, the one name of a one-item list
    (`parse_obj_name` answers lists), without a leading "the", case and spaces folded; None if it is not a name."""
    if isinstance(name, (list, tuple)) and len(name) == 1:
        name = name[0]
    if not isinstance(name, str):
        return None
    words = name.strip().lower().split()
    if words[:1] == ['the']:
        words = words[1:]
    return ' '.join(words)


__all__ = ['object_name_candidate']
