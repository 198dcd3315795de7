"""The table-top's check of a model answer before it runs: an object name the model made up.

A small model sometimes names an object that is neither on the table nor in the command ("put the red block and the
blue block in the green bowl" answered with a `'green block'`): the program would move other objects first and then
fail. An answer that names such an object is not run (and asked for again, see Engine's regenerations). An object
the command itself names ("the purple block") is the user's: that program runs and says the object is not there.
No rclpy here: the sandbox process imports this module.
"""
from __future__ import annotations

import ast

from cap_lmp.engine import literal_assignment
from cap_tabletop.objects import CATEGORY_BLOCK, CATEGORY_BOWL, object_name
from cap_tabletop.palette import COLOR_NAMES

# Every name an object of this domain can have: a palette colour and a category ('red block', 'cyan bowl').
OBJECT_NAMES = frozenset(object_name(color, category) for color in COLOR_NAMES
                         for category in (CATEGORY_BLOCK, CATEGORY_BOWL))


def invented_object(tree: ast.Module, query: str, context: str) -> str | None:
    """Why the answer cannot be meant (it names an object neither in the scene nor in the query), or None.

    The scene is the context line's `objects = [...]`; without one there is nothing to check against.
    """
    assigned = literal_assignment(context) if context else None
    if assigned is None or not isinstance(assigned[1], list):
        return None
    scene = [name for name in assigned[1] if isinstance(name, str)]
    asked = query.lower()
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value in OBJECT_NAMES \
                and node.value not in scene and node.value not in asked:
            return f"it names the {node.value}, which is neither on the table ({', '.join(scene)}) nor in the command"
    return None


__all__ = ['OBJECT_NAMES', 'invented_object']
