"""Imports of what a program's scope already holds are dropped; every other import is still refused.

Models trained on ordinary Python open their code with `import numpy as np` or `from shapely.geometry import
Point`, although the sandbox provides exactly those names. Such a statement binds nothing new, so it is replaced by
`pass` with the statement as a comment (line numbers stay, the shown code says what happened); the sandbox's check
then refuses any import that is left (`import os`, `import numpy` as `numpy`, `from math import sqrt`).
"""
from __future__ import annotations

import ast
from typing import AbstractSet, Mapping

from cap_lmp.sandbox.names import SHAPELY_AFFINITY, SHAPELY_GEOMETRY, SHAPELY_OPS

# Module -> the names the sandbox provides from it, under the same name (numpy: the whole module as `np`).
PROVIDED_FROM: Mapping[str, frozenset[str]] = {
    'shapely': frozenset(SHAPELY_GEOMETRY),
    'shapely.geometry': frozenset(SHAPELY_GEOMETRY),
    'shapely.affinity': frozenset(SHAPELY_AFFINITY),
    'shapely.ops': frozenset(SHAPELY_OPS),
}
PROVIDED_MODULES: Mapping[str, str] = {'numpy': 'np'}  # `import numpy as np`


def _provided(node: ast.Import | ast.ImportFrom, scope: AbstractSet[str]) -> bool:
    if isinstance(node, ast.Import):
        return all(PROVIDED_MODULES.get(alias.name) == alias.asname and alias.asname in scope for alias in node.names)
    names = PROVIDED_FROM.get(node.module or '') if node.level == 0 else None
    return bool(names) and all(alias.name in names and alias.asname in (None, alias.name) and alias.name in scope
                               for alias in node.names)


def drop_provided_imports(source: str, scope: AbstractSet[str]) -> str:
    """`source` with every import of names `scope` already holds replaced by `pass  # <import> (provided)`.

    A statement that shares its line with another one, or code that does not parse, is left as it is (the sandbox's
    check reports it)."""
    if 'import' not in source:
        return source
    try:
        tree = ast.parse(source)
    except (SyntaxError, ValueError, RecursionError, MemoryError):
        return source
    lines = source.split('\n')
    changed = False
    for node in ast.walk(tree):
        if not isinstance(node, (ast.Import, ast.ImportFrom)) or not _provided(node, scope):
            continue
        first, last = node.lineno - 1, (node.end_lineno or node.lineno) - 1
        prefix, rest = lines[first][:node.col_offset], lines[last][node.end_col_offset or 0:]
        if prefix.strip() or rest.strip():
            continue  # `x = 1; import numpy as np`: not a line of its own
        statement = ' '.join(part.strip() for part in lines[first:last + 1])
        lines[first] = f'{prefix}pass  # {statement} (already provided)'
        for index in range(first + 1, last + 1):
            lines[index] = ''
        changed = True
    return '\n'.join(lines) if changed else source
