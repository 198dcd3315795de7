"""Function discovery: which calls a program leaves undefined, and how the function-generation LMP is asked."""
import ast

import pytest

from cap_lmp.functions import parameter_signature, undefined_calls

KNOWN = {'get_obj_pos', 'get_obj_names', 'parse_position', 'len', 'say'}


def asked(source: str, style: str) -> list[str]:
    return [call.query_signature(style) for call in undefined_calls(ast.parse(source), KNOWN)]


@pytest.mark.parametrize('source, call_style, parameter_style', [
    ("pts = get_points_on_circle(get_obj_pos('orange bowl'), radius=0.12, n=len(names))",
     "pts = get_points_on_circle(get_obj_pos('orange bowl'), radius=0.12, n=len(names))",
     'pts = get_points_on_circle(obj_pos, radius, n)'),
    ("slots = spaced(parse_position('top side'), parse_position('left side'), len(names))",
     "slots = spaced(parse_position('top side'), parse_position('left side'), len(names))",
     'slots = spaced(position, position2, n)'),
    ("ordered = sort_by(names, key_pt)", 'ordered = sort_by(names, key_pt)', 'ordered = sort_by(names, key_pt)'),
    ("shift(0.1, 'red block', *rest, **options)", "shift(0.1, 'red block', *rest, **options)",
     'shift(x1, name, *rest, **kwargs)'),
    ('greet()', 'greet()', 'greet()'),
    ('pts = spread(len(names), n=3)', 'pts = spread(len(names), n=3)', 'pts = spread(n2, n)'),
])
def test_a_missing_function_is_asked_for_as_called_or_with_parameter_names(source, call_style, parameter_style):
    assert asked(source, 'call') == [call_style]
    assert asked(source, 'parameters') == [parameter_style]
    # the parameter form is a valid `def` line once `def ` is put before the call
    call = parameter_style.split(' = ', 1)[-1]
    ast.parse(f'def {call}:\n    pass')


def test_a_parameter_name_is_never_a_python_keyword():
    call = ast.parse("f(get_lambda('x'), get_class('y'))").body[0].value
    assert parameter_signature(call) == 'f(x1, x2)'
