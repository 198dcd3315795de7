"""A call's arguments by parameter name, bound the way the called function binds them.

The sandbox's size rules read what a call will do from its arguments: a rule that read `args[0]` let
`np.linalg.eig(a=M)` past the cubic limit. Binding by the function's signature gives every rule the same dict
whatever mix of positional and keyword arguments the program used. This module is imported normally (not compiled
as sandboxed code): binding is bounded work, and the tracer would charge a trace event for each of its lines.
"""
from __future__ import annotations

import inspect
from typing import Any, Callable, Mapping

Binder = Callable[[tuple, Mapping[str, Any]], dict[str, Any]]


def binder(function: Callable[..., Any], what: str, no_value: Any = None) -> Binder | None:
    """A function `bind(args, kwargs)` that gives the parameters of a call of `function` by name: defaults filled in
    (a default that is `no_value`, NumPy's "not given", reads as None), **kwargs spread among them, *args as a tuple
    under its name. A call the signature does not accept raises TypeError naming `what`, as the function would.
    None when `function` has no signature."""
    try:
        signature = inspect.signature(function)
    except (TypeError, ValueError):
        return None
    kinds = inspect.Parameter
    parameters = list(signature.parameters.values())
    defaults = {parameter.name: None if parameter.default is no_value else parameter.default
                for parameter in parameters if parameter.default is not parameter.empty}
    defaults.update((parameter.name, ()) for parameter in parameters if parameter.kind is kinds.VAR_POSITIONAL)
    positional = tuple(parameter.name for parameter in parameters
                       if parameter.kind in (kinds.POSITIONAL_ONLY, kinds.POSITIONAL_OR_KEYWORD))
    keywords = frozenset(parameter.name for parameter in parameters
                         if parameter.kind in (kinds.POSITIONAL_OR_KEYWORD, kinds.KEYWORD_ONLY))
    required = frozenset(parameter.name for parameter in parameters if parameter.default is parameter.empty
                         and parameter.kind not in (kinds.VAR_POSITIONAL, kinds.VAR_KEYWORD))
    spread = next((parameter.name for parameter in parameters if parameter.kind is kinds.VAR_KEYWORD), None)

    def bind_slowly(args: tuple, kwargs: Mapping[str, Any]) -> dict[str, Any]:
        try:
            arguments = signature.bind(*args, **kwargs).arguments
        except TypeError as error:
            raise TypeError(f'{what}(): {error}') from None
        bound = {**defaults, **arguments}
        if spread is not None:
            bound.update(bound.pop(spread, None) or {})
        return bound

    def bind(args: tuple, kwargs: Mapping[str, Any]) -> dict[str, Any]:
        # The usual call (no more positional arguments than parameters, known keywords, none given twice, nothing
        # required missing) binds in a few dict operations; anything else takes inspect's way, errors included.
        given = dict(zip(positional, args))
        if len(args) > len(positional) or not keywords.issuperset(kwargs) or not given.keys().isdisjoint(kwargs):
            return bind_slowly(args, kwargs)
        given.update(kwargs)
        if not required.issubset(given):
            return bind_slowly(args, kwargs)
        return {**defaults, **given}
    return bind
