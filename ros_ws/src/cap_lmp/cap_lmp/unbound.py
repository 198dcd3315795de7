"""Names a program reads that nothing binds: a NameError found before the program runs (so nothing is half done).

Conservative: a name counts as bound if anything anywhere in the program binds it (assignment, loop or
comprehension target, def, class, parameter, import, `except ... as`, a match capture, global/nonlocal), whatever
the order or scope, or if the scope the program runs in holds it. Called names are left to function generation
(functions.undefined_calls), which defines them or says why not.
"""
from __future__ import annotations

import ast
from dataclasses import dataclass
from typing import AbstractSet


@dataclass(frozen=True)
class UnboundName:
    name: str
    line: int


def bound_names(tree: ast.AST) -> set[str]:
    """Every name the code binds, anywhere in it."""
    bound: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Name) and not isinstance(node.ctx, ast.Load):
            bound.add(node.id)
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            bound.add(node.name)
        elif isinstance(node, ast.arg):
            bound.add(node.arg)
        elif isinstance(node, ast.alias):
            bound.add((node.asname or node.name).split('.')[0])
        elif isinstance(node, ast.ExceptHandler) and node.name:
            bound.add(node.name)
        elif isinstance(node, (ast.MatchAs, ast.MatchStar)) and node.name:
            bound.add(node.name)
        elif isinstance(node, ast.MatchMapping) and node.rest:
            bound.add(node.rest)
        elif isinstance(node, (ast.Global, ast.Nonlocal)):
            bound.update(node.names)
    return bound


def unbound_names(tree: ast.AST, known: AbstractSet[str]) -> list[UnboundName]:
    """Names read, not called, that neither `known` nor the code binds: the first read of each, in source order."""
    called = {id(node.func) for node in ast.walk(tree) if isinstance(node, ast.Call)}
    bound = bound_names(tree)
    found: dict[str, UnboundName] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Name) and isinstance(node.ctx, ast.Load) and id(node) not in called \
                and node.id not in known and node.id not in bound:
            first = found.get(node.id)
            if first is None or node.lineno < first.line:
                found[node.id] = UnboundName(node.id, node.lineno)
    return sorted(found.values(), key=lambda unbound: unbound.line)


__all__ = ['UnboundName', 'bound_names', 'unbound_names']
