"""continued_program: an answer that continues its query, as a completions model and as a chat model write it."""
import ast

from cap_lmp.continuation import continued_program

QUERY = '''from typing import List


def helper(x: int) -> int:
    return x + 1


def total(values: List[int]) -> int:
    """ Sum of the values plus one each.
    >>> total([1, 2])
    5
    """
'''


def _functions(program: str) -> list[str]:
    """The program's top-level functions, in order (it must parse)."""
    return [node.name for node in ast.parse(program).body if isinstance(node, ast.FunctionDef)]


def test_a_completion_continues_the_query():
    program = continued_program(QUERY, '    return sum(helper(v) for v in values)\n')
    assert program == QUERY + '    return sum(helper(v) for v in values)\n'
    assert _functions(program) == ['helper', 'total']


def test_a_chat_answer_that_writes_the_function_again_replaces_the_unfinished_one():
    answer = 'def total(values: List[int]) -> int:\n    """Sum."""\n    return sum(helper(v) for v in values)'
    program = continued_program(QUERY, answer)
    assert program.count('def total') == 1 and program.count('def helper') == 1
    assert program.startswith('from typing import List') and _functions(program) == ['helper', 'total']


def test_a_helper_restated_unchanged_is_kept_once_and_a_changed_one_stays_for_the_rules_to_judge():
    same = 'def helper(x: int) -> int:\n    return x + 1\n\n\ndef total(values):\n    return sum(map(helper, values))'
    assert continued_program(QUERY, same).count('def helper') == 1
    changed = 'def helper(x):\n    return 0\n\n\ndef total(values):\n    return sum(map(helper, values))'
    assert continued_program(QUERY, changed).count('def helper') == 2


def test_a_first_line_that_lost_its_indentation_gets_the_bodys():
    answer = 'result = 0\n    for v in values:\n        result += helper(v)\n    return result'
    program = continued_program(QUERY, answer)
    assert '    """\n    result = 0\n    for v in values:' in program and _functions(program) == ['helper', 'total']


def test_a_body_written_at_column_0_is_indented_as_the_body():
    answer = 'result = 0\nfor v in values:\n    result += helper(v)\nreturn result'
    program = continued_program(QUERY, answer)
    assert program.endswith('    result = 0\n    for v in values:\n        result += helper(v)\n    return result')
    assert _functions(program) == ['helper', 'total']


def test_anything_else_stays_query_and_answer():
    assert continued_program('x = (', 'oops') == 'x = (oops'
    assert continued_program(QUERY, 'not python at all (') == QUERY + 'not python at all ('
