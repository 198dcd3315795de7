"""The program an answer makes when it continues its query (LMPConfig.answer_continues_query, e.g. HumanEval).

A completions model writes what follows the query: the program is the query and the answer. A chat model, asked the
same, mostly writes the whole function again (signature, docstring, body), or the body without its indentation (all
of it, or the first line only). Each is unambiguous, so each is taken as the model meant it rather than failed as a
redefinition or a syntax error: HumanEval with a chat model (the protocol the instruct models' own reports use) is
then measurable.
"""
from __future__ import annotations

import ast
import textwrap


def continued_program(query: str, answer: str) -> str:
    """The program of `query` continued by `answer`; see the module's text. Anything else stays query + answer."""
    plain = query + answer
    try:
        query_body = ast.parse(query).body
    except (SyntaxError, ValueError):
        return plain
    functions = [node for node in query_body if isinstance(node, ast.FunctionDef)]
    if not functions:
        return plain
    restated = _restated_program(query, query_body, answer, functions[-1])  # the last one is being completed
    if restated is not None:
        return restated
    if answer[:1].strip() and not _compiles(plain):
        # The body written at column 0, or only its first line there: indent it as the body, like the query's last
        # line (the docstring's end).
        last = query.rstrip('\n').rsplit('\n', 1)[-1]
        indent = last[:len(last) - len(last.lstrip())]
        whole = '\n'.join(indent + line if line.strip() else line for line in answer.split('\n'))
        for indented in (query + whole, query + indent + answer):
            if _compiles(indented):
                return indented
    return plain


def _compiles(source: str) -> bool:
    """Whether the source compiles (compiled only, never run: `return` outside a function is caught here, not by
    ast.parse)."""
    try:
        compile(source, '<answer>', 'exec', dont_inherit=True)
    except (SyntaxError, ValueError):
        return False
    return True


def _restated_program(query: str, query_body: list[ast.stmt], answer: str, target: ast.FunctionDef) -> str | None:
    """When the answer defines the target function at top level: the query without its unfinished definition, then
    the answer without the query's other functions restated unchanged (so the one definition of each stays)."""
    answer = textwrap.dedent(answer)
    try:
        answer_body = ast.parse(answer).body
    except (SyntaxError, ValueError):
        return None
    if not any(isinstance(node, ast.FunctionDef) and node.name == target.name for node in answer_body):
        return None
    unchanged = {ast.dump(node) for node in query_body
                 if isinstance(node, ast.FunctionDef) and node.name != target.name}
    lines = answer.split('\n')
    for node in reversed(answer_body):  # drop restated helpers, last first so line numbers stay right
        if isinstance(node, ast.FunctionDef) and ast.dump(node) in unchanged:
            start = min([node.lineno] + [decorator.lineno for decorator in node.decorator_list]) - 1
            del lines[start:node.end_lineno]
    first = min([target.lineno] + [decorator.lineno for decorator in target.decorator_list]) - 1
    head = '\n'.join(query.split('\n')[:first]).rstrip('\n')
    return f'{head}\n\n\n' + '\n'.join(lines).strip('\n') if head else '\n'.join(lines).strip('\n')
