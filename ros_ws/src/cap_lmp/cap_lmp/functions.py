"""Function discovery for hierarchical code generation: which called bare names does a program leave undefined?"""
from __future__ import annotations

import ast
import keyword as keyword_module
from dataclasses import dataclass
from typing import AbstractSet

from cap_lmp.unbound import bound_names


@dataclass(frozen=True)
class UndefinedCall:
    """A call of a name nothing defines, with the signature the function-generation LMP is asked for."""

    name: str
    signature: str  # the call as written, e.g. 'pts = get_square_corners(get_obj_pos("red bowl"), size=0.1)'
    parameters: str = ''  # the call with parameter names, e.g. 'pts = get_square_corners(obj_pos, size)'

    def query_signature(self, style: str) -> str:
        """'call': the call as the program wrote it (the paper's queries); 'parameters': with parameter names, so
        that a small model does not copy the call's values into its `def` line."""
        return self.parameters if style == 'parameters' and self.parameters else self.signature


_GETTER_PREFIXES = ('get_', 'parse_', 'compute_', 'find_')


def parameter_name(argument: ast.expr) -> str:
    """A parameter name for a positional argument: the variable's name, the attribute, what a getter returns
    (`get_obj_pos(...)` -> obj_pos), `len(x)` -> n; '' when the argument suggests none."""
    if isinstance(argument, ast.Name):
        return argument.id
    if isinstance(argument, ast.Attribute):
        return argument.attr
    if isinstance(argument, ast.Subscript):
        return parameter_name(argument.value)
    if isinstance(argument, ast.Call) and isinstance(argument.func, ast.Name):
        name = argument.func.id
        if name == 'len':
            return 'n'
        for prefix in _GETTER_PREFIXES:
            if name.startswith(prefix) and len(name) > len(prefix):
                return name[len(prefix):]
    if isinstance(argument, ast.Constant) and isinstance(argument.value, str):
        return 'name'
    return ''


def parameter_signature(call: ast.Call) -> str:
    """The call with a parameter name in place of each argument: `f(get_obj_pos('a'), 2, r=0.1)` -> `f(obj_pos,
    x2, r)`. Names repeat-free; keyword arguments keep their keyword; `*xs` and `**kw` stay starred."""
    keywords = [keyword.arg if keyword.arg else '**kwargs' for keyword in call.keywords]
    taken = set(keywords)  # a keyword's name is fixed by the call: positional names give way to it
    positional: list[str] = []
    for index, argument in enumerate(call.args, start=1):
        if isinstance(argument, ast.Starred):
            name = '*' + (parameter_name(argument.value) or 'args')
        else:
            name = parameter_name(argument) or f'x{index}'
            if keyword_module.iskeyword(name):
                name = f'x{index}'
        base, count = name, 1
        while name in taken:
            count += 1
            name = f'{base}{count}'
        taken.add(name)
        positional.append(name)
    unique = positional + keywords
    return f'{ast.unparse(call.func)}({", ".join(unique)})'


def top_level_functions(tree: ast.Module) -> list[str]:
    return [node.name for node in tree.body if isinstance(node, ast.FunctionDef)]


def undefined_calls(tree: ast.AST, known: AbstractSet[str]) -> list[UndefinedCall]:
    """Called bare names that neither `known` (the scope) nor the code itself defines, in source order.

    The code defines a name by any binding anywhere in it (unbound.bound_names: a def, a parameter, an assignment,
    loop or comprehension target, `except ... as`, a match capture, ...).
    """
    local = bound_names(tree)
    calls: list[ast.Call] = []
    assigned_calls: dict[int, ast.expr] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            if isinstance(node.func, ast.Name):
                calls.append(node)
        elif isinstance(node, ast.Assign):
            if len(node.targets) == 1 and isinstance(node.value, ast.Call):
                assigned_calls[id(node.value)] = node.targets[0]
    calls.sort(key=lambda call: (call.lineno, call.col_offset))
    missing: dict[str, UndefinedCall] = {}
    for call in calls:
        name = call.func.id  # type: ignore[attr-defined]
        if name in known or name in local or name in missing:
            continue
        target = assigned_calls.get(id(call))
        assigned = f'{ast.unparse(target)} = ' if target is not None else ''
        missing[name] = UndefinedCall(name, assigned + ast.unparse(call), assigned + parameter_signature(call))
    return list(missing.values())
