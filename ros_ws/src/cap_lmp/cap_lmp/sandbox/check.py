"""The AST check of generated code (step 1 of the sandbox): what a program may not contain, refused with
the line and the reason before anything runs."""
from __future__ import annotations

import ast
import itertools
import re
import warnings

from cap_lmp.errors import CodeRejected
from cap_lmp.sandbox.limits import SandboxLimits

FORBIDDEN_NAMES = frozenset({
    'exec', 'eval', 'compile', 'open', 'getattr', 'setattr', 'delattr', 'hasattr', 'globals', 'locals', 'vars',
    'dir', 'type', 'object', 'super', 'input', 'breakpoint', 'help', 'memoryview', 'classmethod', 'staticmethod',
    'property', 'exit', 'quit', 'BaseException', 'SystemExit', 'KeyboardInterrupt', 'GeneratorExit',
})
FORBIDDEN_ATTRIBUTES = frozenset({
    'mro', 'ctypes', 'tofile', 'dump', 'dumps', 'load', 'loads', 'save', 'savetxt', 'setfield', 'getfield',
    'func_globals', 'func_code', 'im_func', 'im_self', 'format_map', 'translate', 'maketrans',
})
FORBIDDEN_ATTRIBUTE_PREFIXES = ('_', 'gi_', 'f_', 'cr_', 'ag_', 'tb_', 'co_')
_FORBIDDEN_NODES = {
    ast.Import: 'imports are not allowed; np, shapely and the robot API are already available',
    ast.ImportFrom: 'imports are not allowed; np, shapely and the robot API are already available',
    ast.Global: '`global` is not allowed; variables of the session are shared already',
    ast.ClassDef: 'class definitions are not allowed',
    ast.AsyncFunctionDef: 'async code is not allowed',
    ast.AsyncFor: 'async code is not allowed',
    ast.AsyncWith: 'async code is not allowed',
    ast.Await: 'async code is not allowed',
    ast.With: '`with` statements are not allowed',
    ast.TryStar: '`except*` is not allowed',
}
_WIDTH = re.compile(r'\d+')
_SELF_MATCHING_TYPES = frozenset({'bool', 'bytes', 'dict', 'float', 'frozenset', 'int', 'list', 'set', 'str',
                                  'tuple', 'complex'})


class _Checker(ast.NodeVisitor):
    def __init__(self, limits: SandboxLimits) -> None:
        self.limits = limits

    def refuse(self, node: ast.AST, reason: str) -> None:
        raise CodeRejected(reason, getattr(node, 'lineno', None))

    def generic_visit(self, node: ast.AST) -> None:
        reason = _FORBIDDEN_NODES.get(type(node))
        if reason:
            self.refuse(node, reason)
        super().generic_visit(node)

    def visit_Constant(self, node: ast.Constant) -> None:
        # (the base class' visit_Constant is a slow compatibility shim)
        value = node.value
        if type(value) is int and value.bit_length() > self.limits.max_int_bits:  # a hexadecimal literal
            self.refuse(node, f'an integer literal of {value.bit_length():,} bits exceeds the limit of '
                              f'{self.limits.max_int_bits:,} bits')

    def visit_Name(self, node: ast.Name) -> None:
        if node.id.startswith('__'):
            self.refuse(node, f'the name {node.id!r} is not allowed (names starting with "__" are reserved)')
        if node.id in FORBIDDEN_NAMES:
            self.refuse(node, f'{node.id!r} is not available in generated code')

    def _check_binding(self, node: ast.AST, name: str | None) -> None:
        if name and (name.startswith('__') or name in FORBIDDEN_NAMES):
            self.refuse(node, f'the name {name!r} may not be defined in generated code')

    def visit_FunctionDef(self, node: ast.FunctionDef) -> None:
        self._check_binding(node, node.name)
        for arg in itertools.chain(node.args.posonlyargs, node.args.args, node.args.kwonlyargs,
                                   [node.args.vararg, node.args.kwarg]):
            if arg is not None:
                self._check_binding(arg, arg.arg)
        self.generic_visit(node)

    def visit_Lambda(self, node: ast.Lambda) -> None:
        for arg in itertools.chain(node.args.posonlyargs, node.args.args, node.args.kwonlyargs,
                                   [node.args.vararg, node.args.kwarg]):
            if arg is not None:
                self._check_binding(arg, arg.arg)
        self.generic_visit(node)

    def visit_Attribute(self, node: ast.Attribute) -> None:
        name = node.attr
        if name.startswith(FORBIDDEN_ATTRIBUTE_PREFIXES) or name in FORBIDDEN_ATTRIBUTES:
            self.refuse(node, f'the attribute {name!r} is not allowed in generated code')
        if not isinstance(node.ctx, ast.Load):
            self.refuse(node, f'assigning or deleting attributes ({name!r}) is not allowed in generated code')
        self.generic_visit(node)

    def visit_Try(self, node: ast.Try) -> None:
        if node.finalbody:
            self.refuse(node, '`finally` is not allowed in generated code')
        for handler in node.handlers:
            if handler.type is None:
                self.refuse(handler, 'a bare `except:` is not allowed; name the exception, e.g. `except Exception:`')
            self._check_binding(handler, handler.name)
        self.generic_visit(node)

    def visit_Nonlocal(self, node: ast.Nonlocal) -> None:
        for name in node.names:
            self._check_binding(node, name)

    def visit_MatchAs(self, node: ast.MatchAs) -> None:
        self._check_binding(node, node.name)
        self.generic_visit(node)

    def visit_MatchStar(self, node: ast.MatchStar) -> None:
        self._check_binding(node, node.name)

    def visit_MatchMapping(self, node: ast.MatchMapping) -> None:
        self._check_binding(node, node.rest)
        self.generic_visit(node)

    def visit_MatchClass(self, node: ast.MatchClass) -> None:
        # A class pattern reads attributes with a plain getattr (keyword patterns, and positional ones through
        # __match_args__), past every guard: only the builtin types' own self-match `case int(x):` is allowed.
        if node.kwd_attrs:
            self.refuse(node, 'class patterns with keywords (`case str(name=...)`) are not allowed in generated code')
        if not (isinstance(node.cls, ast.Name) and node.cls.id in _SELF_MATCHING_TYPES) or len(node.patterns) > 1:
            self.refuse(node, 'class patterns are allowed for builtin types only, e.g. `case int(x):`')
        self.generic_visit(node)

    def visit_FormattedValue(self, node: ast.FormattedValue) -> None:
        spec = node.format_spec
        if spec is not None:
            for part in spec.values:
                if not isinstance(part, ast.Constant):
                    self.refuse(node, 'f-string format specs must be constant in generated code')
                for width in _WIDTH.findall(str(part.value)):
                    if int(width) > self.limits.max_format_width:
                        self.refuse(node, f'f-string width {width} exceeds the limit of '
                                          f'{self.limits.max_format_width}')
        self.visit(node.value)


def check_code(source: str, limits: SandboxLimits | None = None) -> ast.Module:
    """Parse and check generated code; raise CodeRejected with line and reason when it is not allowed."""
    try:
        with warnings.catch_warnings():  # model code is not ours to warn about on stderr
            warnings.simplefilter('ignore')
            tree = ast.parse(source, mode='exec')
    except SyntaxError as error:
        line_text = (error.text or '').strip()
        raise CodeRejected(f'the code has a syntax error at line {error.lineno}: {error.msg}'
                           + (f': `{line_text}`' if line_text else ''), error.lineno, line_text) from None
    except (ValueError, MemoryError, RecursionError) as error:
        raise CodeRejected(f'the code could not be parsed: {error}') from None
    try:
        _Checker(limits or SandboxLimits()).visit(tree)
    except CodeRejected as error:
        if error.line:
            lines = source.splitlines()
            if 0 < error.line <= len(lines):
                error.source_line = lines[error.line - 1].strip()
                error.args = (f'{error.args[0]} (line {error.line}: `{error.source_line}`)',)
        raise
    except RecursionError:
        raise CodeRejected('the code is nested too deeply to check') from None
    return tree
