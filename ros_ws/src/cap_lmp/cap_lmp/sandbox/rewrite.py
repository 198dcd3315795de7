"""The rewrite of checked code (step 2 of the sandbox): operators, comparisons and attribute reads become
calls of the checked helpers in guards.py, and loops, comprehensions, functions and lambdas get checkpoints."""
from __future__ import annotations

import ast

from cap_lmp.errors import CodeRejected

# Names of the helpers in a program's scope; the checker refuses names starting with '__' in user code.
GUARD_PREFIX = '__cap_'

_BINOP_HELPERS = {
    ast.Add: 'add', ast.Sub: 'sub', ast.Mult: 'mult', ast.MatMult: 'matmult', ast.Div: 'truediv',
    ast.FloorDiv: 'floordiv', ast.Mod: 'mod', ast.Pow: 'pow', ast.LShift: 'lshift', ast.RShift: 'rshift',
    ast.BitAnd: 'and', ast.BitOr: 'or', ast.BitXor: 'xor',
}
_COMPARE_HELPERS = {ast.Eq: 'eq', ast.NotEq: 'ne', ast.Lt: 'lt', ast.LtE: 'le', ast.Gt: 'gt', ast.GtE: 'ge'}


def _helper(name: str, node: ast.AST) -> ast.Name:
    return ast.copy_location(ast.Name(id=GUARD_PREFIX + name, ctx=ast.Load()), node)


def _located(new: ast.AST, old: ast.AST) -> ast.AST:
    """Give a new node and its new children the source position of `old` (cheaper than fix_missing_locations)."""
    for node in ast.walk(new):
        if 'lineno' in node._attributes and not hasattr(node, 'lineno'):
            ast.copy_location(node, old)
    return new


class _Rewriter(ast.NodeTransformer):
    """Routes operators and attribute reads through the checked helpers (names the checker refuses in user code)."""

    def visit_Constant(self, node: ast.Constant) -> ast.AST:
        return node

    def visit_Name(self, node: ast.Name) -> ast.AST:
        return node

    def visit_BinOp(self, node: ast.BinOp) -> ast.AST:
        self.generic_visit(node)
        helper = _helper('op_' + _BINOP_HELPERS[type(node.op)], node)
        return ast.copy_location(ast.Call(func=helper, args=[node.left, node.right], keywords=[]), node)

    def visit_Compare(self, node: ast.Compare) -> ast.AST:
        self.generic_visit(node)
        if len(node.ops) != 1 or type(node.ops[0]) not in _COMPARE_HELPERS:
            return node
        helper = _helper('cmp_' + _COMPARE_HELPERS[type(node.ops[0])], node)
        return ast.copy_location(ast.Call(func=helper, args=[node.left, node.comparators[0]], keywords=[]), node)

    def visit_Attribute(self, node: ast.Attribute) -> ast.AST:
        self.generic_visit(node)
        return ast.copy_location(ast.Call(func=_helper('getattr', node),
                                          args=[node.value, ast.copy_location(ast.Constant(node.attr), node)],
                                          keywords=[]), node)

    def visit_AugAssign(self, node: ast.AugAssign) -> ast.AST:
        self.generic_visit(node)
        helper = _helper('op_i' + _BINOP_HELPERS[type(node.op)], node)
        target = node.target
        if isinstance(target, ast.Name):
            value = ast.Call(func=helper, args=[ast.Name(id=target.id, ctx=ast.Load()), node.value], keywords=[])
            return _located(ast.Assign(targets=[target], value=value), node)
        if isinstance(target, ast.Subscript):
            call = ast.Call(func=_helper('augmented_item', node),
                            args=[target.value, target.slice, helper, node.value], keywords=[])
            return _located(ast.Expr(value=call), node)
        raise CodeRejected('this augmented assignment target is not allowed', node.lineno)

    def _tick_loop(self, node: ast.While | ast.For) -> ast.AST:
        # A call at the top of every loop body: a checkpoint even for loops that emit no line events
        # (`while True: pass` compiles to a jump onto itself).
        self.generic_visit(node)
        tick = _located(ast.Expr(value=ast.Call(func=_helper('tick', node), args=[], keywords=[])), node)
        node.body.insert(0, tick)
        return node

    visit_While = _tick_loop
    visit_For = _tick_loop

    # Comprehensions, function bodies and lambdas check too once the tracer is gone (a stop swallowed by a
    # generator finalizer): `gettrace() is None and tick()`, one C call while the tracer runs, which checks anyway.
    @staticmethod
    def _untraced_check(node: ast.AST) -> ast.expr:
        traced = ast.Compare(left=ast.Call(func=_helper('gettrace', node), args=[], keywords=[]), ops=[ast.Is()],
                             comparators=[ast.Constant(None)])
        check = ast.BoolOp(op=ast.And(), values=[traced, ast.Call(func=_helper('tick', node), args=[], keywords=[])])
        return _located(check, node)

    def _tick_comprehension(self, node: ast.AST) -> ast.AST:
        self.generic_visit(node)
        for generator in node.generators:
            generator.ifs.insert(0, _located(ast.UnaryOp(op=ast.Not(), operand=self._untraced_check(node)), node))
        return node

    visit_ListComp = _tick_comprehension
    visit_SetComp = _tick_comprehension
    visit_DictComp = _tick_comprehension
    visit_GeneratorExp = _tick_comprehension

    def visit_FunctionDef(self, node: ast.FunctionDef) -> ast.AST:
        self.generic_visit(node)
        node.body.insert(0, _located(ast.Expr(value=self._untraced_check(node)), node))
        return node

    def visit_Lambda(self, node: ast.Lambda) -> ast.AST:
        self.generic_visit(node)
        node.body = _located(ast.BoolOp(op=ast.Or(), values=[self._untraced_check(node), node.body]), node)
        return node


def rewrite(tree: ast.Module) -> ast.Module:
    """Return the checked tree with guarded operators (line numbers preserved for error reports)."""
    return _Rewriter().visit(tree)
