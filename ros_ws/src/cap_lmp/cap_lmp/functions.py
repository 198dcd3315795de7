"""Function discovery for hierarchical code generation: which called bare names does a program leave undefined?"""
from __future__ import annotations

import ast
from dataclasses import dataclass
from typing import AbstractSet


@dataclass(frozen=True)
class UndefinedCall:
    """A call of a name nothing defines, with the signature the function-generation LMP is asked for."""

    name: str
    signature: str  # e.g. 'pts = get_square_corners(center, size)' or 'say_hello()'


def top_level_functions(tree: ast.Module) -> list[str]:
    return [node.name for node in tree.body if isinstance(node, ast.FunctionDef)]


def undefined_calls(tree: ast.AST, known: AbstractSet[str]) -> list[UndefinedCall]:
    """Called bare names that neither `known` (the scope) nor the code itself defines, in source order.

    The code defines a name by any binding anywhere in it: a def, a parameter, an assignment, loop or comprehension
    target, `except ... as`, a match capture. One walk over the tree collects bindings and calls.
    """
    local: set[str] = set()
    calls: list[ast.Call] = []
    assigned_calls: dict[int, ast.expr] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Name):
            if not isinstance(node.ctx, ast.Load):
                local.add(node.id)
        elif isinstance(node, ast.Call):
            if isinstance(node.func, ast.Name):
                calls.append(node)
        elif isinstance(node, ast.Assign):
            if len(node.targets) == 1 and isinstance(node.value, ast.Call):
                assigned_calls[id(node.value)] = node.targets[0]
        elif isinstance(node, ast.FunctionDef):
            local.add(node.name)
        elif isinstance(node, ast.arg):
            local.add(node.arg)
        elif isinstance(node, ast.ExceptHandler):
            if node.name:
                local.add(node.name)
        elif isinstance(node, (ast.MatchAs, ast.MatchStar)):
            if node.name:
                local.add(node.name)
        elif isinstance(node, ast.MatchMapping):
            if node.rest:
                local.add(node.rest)
        elif isinstance(node, ast.Nonlocal):
            local.update(node.names)
    calls.sort(key=lambda call: (call.lineno, call.col_offset))
    missing: dict[str, UndefinedCall] = {}
    for call in calls:
        name = call.func.id  # type: ignore[attr-defined]
        if name in known or name in local or name in missing:
            continue
        target = assigned_calls.get(id(call))
        call_text = ast.unparse(call)
        signature = f'{ast.unparse(target)} = {call_text}' if target is not None else call_text
        missing[name] = UndefinedCall(name, signature)
    return list(missing.values())
