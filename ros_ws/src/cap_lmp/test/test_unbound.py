"""unbound_names: the NameErrors a program would raise, found before it runs."""
import ast

from cap_lmp.unbound import unbound_names


def names(code: str, known=frozenset({'print', 'len', 'range'})) -> list[tuple[str, int]]:
    return [(unbound.name, unbound.line) for unbound in unbound_names(ast.parse(code), known)]


def test_a_read_of_a_name_nothing_binds_is_found_with_its_first_line():
    assert names("a = 1\nprint(a, blue_pos)\nprint(blue_pos, green_pos)") == [('blue_pos', 2), ('green_pos', 3)]


def test_every_way_of_binding_counts():
    code = '\n'.join([
        'x = 1', 'for i in range(3):\n    pass', 'ys = [j for j in range(i)]', 'f = lambda k: k + x',
        'def g(p, *rest, q=1, **more):\n    return p, rest, q, more, g', 'class C:\n    pass',
        'try:\n    pass\nexcept ValueError as caught:\n    print(caught)', 'with open("f") as handle:\n    pass',
        '(w := 3)', 'match x:\n    case [first, *others]:\n        pass\n    case {"a": 1, **tail}:\n        pass',
        'print(i, ys, f, C, handle, w, first, others, tail)'])
    assert names(code, known=frozenset({'print', 'range', 'ValueError', 'open'})) == []


def test_called_names_are_left_to_function_generation():
    assert names('pts = get_points_on_circle(center, radius=0.1)') == [('center', 1)]


def test_names_the_scope_holds_and_names_bound_later_are_not_reported():
    assert names('print(objects)', known=frozenset({'print', 'objects'})) == []
    assert names('def f():\n    return later\nlater = 2') == []  # conservative: bound anywhere is bound
