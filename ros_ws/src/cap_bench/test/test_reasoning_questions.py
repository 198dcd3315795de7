"""The reasoning questions are well formed and unambiguous, their reference answers pass in all three styles, wrong
answers fail, and the prompts teach the formats the parser reads without giving away any benchmark question."""
import math
import re
from itertools import combinations

import numpy as np
import pytest
import shapely

from cap_bench.reasoning import answers
from cap_bench.reasoning.answers import (LANGUAGE_STOP, POSITION_TOLERANCE_M, code_query, context_line, judge,
                                         language_prompt, normalise_code_answer, parse_answer)
from cap_bench.reasoning.questions import COUNTS, KINDS, QUESTIONS, STYLES, format_answer, question
from cap_lmp.engine import literal_assignment
from cap_lmp.prompts import load_prompt
from cap_lmp.sandbox import Sandbox

PROMPTS = answers.__file__.replace('answers.py', 'prompts')
OBJECTS = [q for q in QUESTIONS if q.kind == 'object']
POSITIONS = [q for q in QUESTIONS if q.kind == 'position']
MARGIN_M = 0.02


@pytest.fixture(scope='module')
def sandbox():
    return Sandbox()


def _run(sandbox, context, code):
    """ret_val of `code` after the context line, both run in the sandbox as the harness does."""
    scope = sandbox.new_scope()
    sandbox.execute(sandbox.compile(context, 'context'), scope)
    sandbox.execute(sandbox.compile(code, 'answer'), scope)
    return scope['ret_val']


# -- the set ------------------------------------------------------------------------------------------------------
def test_there_are_28_object_then_23_position_questions_with_unique_ids():
    assert STYLES == ('code', 'vanilla', 'cot') and KINDS == ('object', 'position')
    assert COUNTS == {'object': 28, 'position': 23} and len(QUESTIONS) == 51
    assert [q.kind for q in QUESTIONS] == ['object'] * 28 + ['position'] * 23
    assert [q.id for q in QUESTIONS] == [f'object-{i:02d}' for i in range(1, 29)] + \
        [f'position-{i:02d}' for i in range(1, 24)]
    assert all(question(q.id) is q for q in QUESTIONS)
    with pytest.raises(KeyError, match='object-29'):
        question('object-29')
    assert len({q.question for q in QUESTIONS}) == 51 and len({code_query(q) for q in QUESTIONS}) == 51


@pytest.mark.parametrize('q', QUESTIONS, ids=lambda q: q.id)
def test_scenes_are_small_tables_on_a_centimetre_grid(q):
    assert 3 <= len(q.objects) <= 6
    for name, (x, y) in q.objects.items():
        assert re.fullmatch(r'[a-z]+ (block|bowl)', name)
        assert abs(x) <= 0.5 and abs(y) <= 0.5
        assert round(x, 2) == x and round(y, 2) == y
    for a, b in combinations(q.objects.values(), 2):
        assert math.dist(a, b) >= 0.05  # two objects never overlap
    if q.kind == 'object':
        assert q.answer in q.objects and q.answer not in q.question
        assert q.question.startswith('which ') and q.question.endswith('?')
    else:
        assert len(q.answer) == 2 and all(isinstance(v, float) for v in q.answer)


def test_code_queries_are_the_noun_phrase_of_the_question():
    assert code_query(question('object-04')) == 'the block farthest from the yellow bowl'
    assert code_query(question('object-16')) == 'the second block from the left'
    assert code_query(question('position-01')) == 'a point 10 cm to the right of the red block'
    assert all(code_query(q).startswith('the ') for q in OBJECTS)


# -- the answers, recomputed from the question text with formulas of the test's own -----------------------------
def _candidates(q, noun, named):
    return [n for n in q.objects if (noun == 'object' or n.endswith(noun)) and n not in named]


def _best(scores, smallest=True):
    """(answer, margin to the runner-up) of {name: score}."""
    ranked = sorted(scores.items(), key=lambda item: item[1], reverse=not smallest)
    return ranked[0][0], abs(ranked[1][1] - ranked[0][1])


def _only_inside(q, names, region):
    inside = [n for n in names if region.contains(shapely.Point(q.objects[n]))]
    assert len(inside) == 1, inside
    return inside[0], min(region.exterior.distance(shapely.Point(q.objects[n])) for n in names)


def _object_oracle(q):
    """(answer, margin in metres) from the words of the question."""
    p = {n: np.array(xy) for n, xy in q.objects.items()}
    text = q.question
    if m := re.fullmatch(r'which (\w+) is closest to the point halfway between the (.+) and the (.+)\?', text):
        noun, a, b = m.groups()
        middle = (p[a] + p[b]) / 2
        return _best({n: np.hypot(*(p[n] - middle)) for n in _candidates(q, noun, (a, b))})
    if m := re.fullmatch(r'which (\w+) is closest to the average position of the (\w+)s\?', text):
        noun, group = m.groups()
        mean = np.mean([p[n] for n in _candidates(q, group, ())], axis=0)
        return _best({n: np.hypot(*(p[n] - mean)) for n in _candidates(q, noun, ())})
    if m := re.fullmatch(r'which (\w+) is (closest to|farthest from) the (.+)\?', text):
        noun, relation, target = m.groups()
        scores = {n: shapely.Point(p[n]).distance(shapely.Point(p[target])) for n in _candidates(q, noun, (target,))}
        return _best(scores, smallest=relation == 'closest to')
    if m := re.fullmatch(r'which (\w+) is farthest (to the left|to the right|towards the top|towards the bottom)\?',
                         text):
        noun, side = m.groups()
        axis = 0 if side.startswith('to the') else 1
        return _best({n: p[n][axis] for n in _candidates(q, noun, ())}, smallest=side in ('to the left',
                                                                                           'towards the bottom'))
    if m := re.fullmatch(r'which (\w+) is (second|third) from the (left|right|top|bottom)\?', text):
        noun, ordinal, side = m.groups()
        index = {'second': 1, 'third': 2}[ordinal]
        axis, reverse = {'left': (0, False), 'right': (0, True), 'top': (1, True), 'bottom': (1, False)}[side]
        values = sorted((p[n][axis], n) for n in _candidates(q, noun, ()))
        values = values[::-1] if reverse else values
        gaps = [abs(values[i][0] - values[i + 1][0]) for i in (index - 1, index) if i + 1 < len(values)]
        return values[index][1], min(gaps)
    if m := re.fullmatch(r'which (\w+) is between the (.+) and the (.+)\?', text):
        noun, a, b = m.groups()
        segment = shapely.LineString([p[a], p[b]])
        scores = {n: segment.distance(shapely.Point(p[n])) for n in _candidates(q, noun, (a, b))}
        answer, margin = _best(scores)
        assert scores[answer] <= 0.03  # it lies on the segment, not merely nearest to it
        return answer, margin
    if m := re.fullmatch(r'which (\w+) is inside the rectangle with x from (\S+) to (\S+) and y from (\S+) to (\S+)\?',
                         text):
        noun, x0, x1, y0, y1 = m.groups()
        return _only_inside(q, _candidates(q, noun, ()), shapely.box(float(x0), float(y0), float(x1), float(y1)))
    if m := re.fullmatch(r'which (\w+) is within (\d+) cm of the (.+)\?', text):
        noun, cm, target = m.groups()
        circle = shapely.Point(p[target]).buffer(int(cm) / 100, quad_segs=256)
        return _only_inside(q, _candidates(q, noun, (target,)), circle)
    if m := re.fullmatch(r'which (\w+) is inside the triangle formed by the (.+), the (.+) and the (.+)\?', text):
        noun, *corners = m.groups()
        return _only_inside(q, _candidates(q, noun, corners), shapely.Polygon([p[c] for c in corners]))
    if m := re.fullmatch(r'which (\w+) is to the (left|right) of the (.+) and (above|below) the (.+)\?', text):
        noun, side, beside, vertical, level = m.groups()
        names = _candidates(q, noun, (beside, level))
        dx = {n: (p[n][0] - p[beside][0]) * (1 if side == 'right' else -1) for n in names}
        dy = {n: (p[n][1] - p[level][1]) * (1 if vertical == 'above' else -1) for n in names}
        matching = [n for n in names if dx[n] > 0 and dy[n] > 0]
        assert len(matching) == 1, matching
        return matching[0], min(min(abs(dx[n]), abs(dy[n])) for n in names)
    raise AssertionError(f'{q.id}: no formula in the test reads {text!r}')


_DIRECTION = {'to the right of': (1, 0), 'to the left of': (-1, 0), 'above': (0, 1), 'below': (0, -1)}
_DIRECTIONS = '|'.join(_DIRECTION)


def _position_oracle(q):
    p = {n: complex(*xy) for n, xy in q.objects.items()}  # complex numbers: x + iy
    text = q.question
    pair = r'(?:the point halfway between|the midpoint of|the point midway between) the (.+) and the (.+)'
    if m := re.fullmatch(rf'a point (\d+) cm ({_DIRECTIONS}) {pair}', text):
        cm, direction, a, b = m.groups()
        return (p[a] + p[b]) / 2 + complex(*_DIRECTION[direction]) * int(cm) / 100
    if m := re.fullmatch(rf'a point (\d+) cm ({_DIRECTIONS}) the (.+)', text):
        cm, direction, target = m.groups()
        return p[target] + complex(*_DIRECTION[direction]) * int(cm) / 100
    if m := re.fullmatch(pair, text):
        return (p[m[1]] + p[m[2]]) / 2
    if m := re.fullmatch(r'the (?:centroid|average position) of the (.+), the (.+) and the (.+)', text):
        return sum(p[n] for n in m.groups()) / 3
    if m := re.fullmatch(r'the point (a quarter|one third|three quarters) of the way from the (.+) to the (.+)', text):
        fraction = {'a quarter': 1 / 4, 'one third': 1 / 3, 'three quarters': 3 / 4}[m[1]]
        return p[m[2]] * (1 - fraction) + p[m[3]] * fraction
    if m := re.fullmatch(r'the (top|bottom) (left|right) corner of the bounding box of (?:the (\w+)s|all the objects)',
                         text):
        minx, miny, maxx, maxy = shapely.MultiPoint([(v.real, v.imag) for v in
                                                     (p[n] for n in _candidates(q, m[3] or 'object', ()))]).bounds
        return complex(minx if m[2] == 'left' else maxx, maxy if m[1] == 'top' else miny)
    if m := re.fullmatch(r'the centre of the bounding box of the (\w+)s', text):
        box = shapely.MultiPoint([q.objects[n] for n in _candidates(q, m[1], ())]).envelope
        return complex(box.centroid.x, box.centroid.y)
    if m := re.fullmatch(r'the point on the other side of the (.+) from the (.+), at the same distance', text):
        return 2 * p[m[1]] - p[m[2]]
    if m := re.fullmatch(r'the reflection of the (.+) through the (.+)', text):
        return 2 * p[m[2]] - p[m[1]]
    if m := re.fullmatch(r'the mirror image of the (.+) across the vertical line through the (.+)', text):
        return complex(2 * p[m[2]].real - p[m[1]].real, p[m[1]].imag)
    if m := re.fullmatch(r'the (top|bottom) (left|right) corner of a (\d+) cm square centred on the (.+)', text):
        half = int(m[3]) / 200
        return p[m[4]] + complex(half if m[2] == 'right' else -half, half if m[1] == 'top' else -half)
    if m := re.fullmatch(r'the fourth corner of the parallelogram whose first three corners, in order, are the (.+), '
                         r'the (.+) and the (.+)', text):
        a, b, c = (p[n] for n in m.groups())
        return a + (c - b)  # the side from b to c, again from a
    if m := re.fullmatch(r'the point the (.+) reaches when turned 90 degrees counter-clockwise around the (.+)', text):
        return p[m[2]] + (p[m[1]] - p[m[2]]) * 1j
    raise AssertionError(f'{q.id}: no formula in the test reads {text!r}')


@pytest.mark.parametrize('q', OBJECTS, ids=lambda q: q.id)
def test_each_object_answer_follows_from_the_question_with_a_clear_margin(q):
    answer, margin = _object_oracle(q)
    assert answer == q.answer
    assert margin >= MARGIN_M


@pytest.mark.parametrize('q', POSITIONS, ids=lambda q: q.id)
def test_each_position_answer_follows_from_the_question(q):
    expected = _position_oracle(q)
    assert math.dist(q.answer, (expected.real, expected.imag)) < 1e-6


# -- reference answers pass, wrong ones fail -------------------------------------------------------------------------
def test_the_context_line_is_a_literal_the_program_sees_as_the_scene():
    q = question('object-01')
    assert context_line(q).startswith("objects = {'yellow block': (0.01, 0.22), ")
    assert all(literal_assignment(context_line(q)) == ('objects', dict(q.objects)) for q in QUESTIONS)


@pytest.mark.parametrize('q', QUESTIONS, ids=lambda q: q.id)
def test_reference_code_is_sandbox_valid_and_its_ret_val_is_judged_correct(sandbox, q):
    sandbox.check(q.reference_code)
    # the harness cuts the model's answer at the next comment or context line: the program has none
    assert not any(line.startswith(('#', 'objects = {')) for line in q.reference_code.splitlines())
    value = _run(sandbox, context_line(q), q.reference_code)
    reported = value.tolist() if isinstance(value, np.ndarray) else value  # arrays may cross as lists
    for raw in (value, reported):
        normalised = normalise_code_answer(q, raw)
        assert judge(q, normalised)[0], (raw, q.answer)


@pytest.mark.parametrize('q', QUESTIONS, ids=lambda q: q.id)
def test_reference_texts_parse_to_the_right_answer(q):
    assert q.reference_vanilla == format_answer(q.answer) and '\n' not in q.reference_vanilla
    assert q.reference_cot.splitlines()[-1] == f'So the answer is {format_answer(q.answer)}.'
    assert len(q.reference_cot.splitlines()) >= 2  # reasoning comes first
    for style, text in (('vanilla', q.reference_vanilla), ('cot', q.reference_cot)):
        ok, reason = judge(q, parse_answer(q, style, text))
        assert ok, (style, reason)


@pytest.mark.parametrize('q', OBJECTS, ids=lambda q: q.id)
def test_another_object_is_rejected(q):
    for other in q.objects:
        if other != q.answer:
            ok, reason = judge(q, other)
            assert not ok and q.answer in reason
            assert not judge(q, parse_answer(q, 'cot', f'Maybe the {q.answer}.\nSo the answer is {other}.'))[0]
    assert judge(q, q.answer.upper())[0]
    assert judge(q, None) == (False, 'no answer')


@pytest.mark.parametrize('q', POSITIONS, ids=lambda q: q.id)
def test_a_point_2_cm_off_is_rejected_and_one_inside_1_cm_accepted(q):
    x, y = q.answer
    for dx, dy in ((0.02, 0), (0, -0.02), (0.0142, 0.0142)):
        ok, reason = judge(q, (x + dx, y + dy))
        assert not ok and '2.0 cm' in reason
    assert judge(q, (x + 0.007, y - 0.007))[0]
    assert judge(q, (x, y + POSITION_TOLERANCE_M))[0]
    assert not judge(q, parse_answer(q, 'vanilla', f'({x + 0.02:.3f}, {y:.3f})'))[0]
    assert not judge(q, 'red block')[0] and not judge(q, None)[0]


# -- reading text and ret_val ---------------------------------------------------------------------------------------
def test_positions_are_read_in_the_usual_notations():
    q = question('position-01')
    for text in ('(0.12, -0.30)', 'x=0.12, y=-0.3', '[0.12, -0.3]', 'X: 0.12 m and Y: \u22120.3 m', '0.12, -0.3',
                 'np.array([0.12, -0.30, 0.02])', '(12 cm, -30 cm)', 'It is at (0.5, 0.5), no: (0.12, -0.3).'):
        assert parse_answer(q, 'vanilla', text) == pytest.approx((0.12, -0.3)), text
    assert parse_answer(q, 'vanilla', 'the red block') is None
    assert parse_answer(q, 'cot', 'The red block is at (-0.11, -0.39). Move right.\nSo the answer is (-0.01, -0.39).') \
        == pytest.approx((-0.01, -0.39))
    # the vanilla answer is its first line; what the model adds after it is not read
    assert parse_answer(q, 'vanilla', '(0.1, 0.2)\nor (0.3, 0.4)') == pytest.approx((0.1, 0.2))


def test_object_names_are_read_case_insensitively_the_last_on_the_answer_line():
    q = question('object-13')
    assert parse_answer(q, 'vanilla', 'Orange Block') == 'orange block'
    assert parse_answer(q, 'vanilla', 'A: the orange block.') == 'orange block'
    cot = ('The green block is far, the yellow block too.\nThe orange block is on the segment.\n'
           'So the answer is not the red bowl but the orange block.')
    assert parse_answer(q, 'cot', cot) == 'orange block'
    assert parse_answer(q, 'cot', 'It is the orange block.\nThe green block is far.') == 'green block'
    assert parse_answer(q, 'cot', 'The answer is: yellow block') == 'yellow block'
    assert parse_answer(q, 'vanilla', 'the purple block') is None and parse_answer(q, 'cot', '') is None
    with pytest.raises(ValueError):
        parse_answer(q, 'poetry', 'orange block')


def test_ret_val_values_normalise_to_names_and_points():
    obj, pos = question('object-13'), question('position-01')
    assert normalise_code_answer(obj, 'Orange block') == 'orange block'
    assert normalise_code_answer(obj, ['orange block']) == 'orange block'
    assert normalise_code_answer(obj, np.array(['orange block'])) == 'orange block'
    for not_a_name in (None, 3, (0.12, 0.05), 'a cup'):
        assert normalise_code_answer(obj, not_a_name) is None
    for value in (np.array([0.1, 0.2]), [0.1, 0.2, 0.0], (np.float64(0.1), 0.2), [[0.1, 0.2]], 'array([0.1, 0.2])',
                  {'x': 0.1, 'y': 0.2}):
        assert normalise_code_answer(pos, value) == pytest.approx((0.1, 0.2)), value
    for not_a_point in (None, 'red block', [0.1], [0.1, 0.2, 0.3, 0.4], [True, False], [0.1, 'y'],
                        [float('nan'), 0.2], 0.5):
        assert normalise_code_answer(pos, not_a_point) is None, not_a_point


# -- prompts -------------------------------------------------------------------------------------------------------
def _prompt(style):
    return load_prompt(PROMPTS, style)


def _code_examples():
    """(context line, query, code) of each example in code.txt."""
    examples, lines = [], _prompt('code').splitlines()
    starts = [i for i, line in enumerate(lines) if line.startswith('objects = {')]
    for start, end in zip(starts, starts[1:] + [len(lines)]):
        examples.append((lines[start], lines[start + 1], '\n'.join(lines[start + 2:end])))
    return examples


def _language_examples(style):
    """(Q line, answer text) of each example."""
    blocks = _prompt(style).split('\n\nQ: ')[1:]
    return [('Q: ' + block.split('\nA: ', 1)[0], block.split('\nA: ', 1)[1].strip()) for block in blocks]


def test_every_prompt_says_the_coordinate_convention_first():
    for style in STYLES:
        first = _prompt(style).splitlines()[0]
        assert first.startswith('# ') and 'x to the right, y up' in first and 'metres' in first


def test_code_examples_are_sandbox_valid_and_agree_with_the_language_examples(sandbox):
    code, vanilla, cot = _code_examples(), _language_examples('vanilla'), _language_examples('cot')
    assert 4 <= len(code) <= 6 and len(vanilla) == len(cot) == len(code)
    for (context, query, program), (v_question, v_answer), (c_question, c_answer) in zip(code, vanilla, cot):
        assert query.startswith('# ') and query.endswith('.') and v_question == c_question
        assert not any(line.startswith('#') for line in program.splitlines())
        sandbox.check(program)
        value = _run(sandbox, context, program)
        expected = c_answer.splitlines()[-1]
        assert expected == f'So the answer is {v_answer}.' and len(c_answer.splitlines()) >= 2
        if isinstance(value, str):
            assert value == v_answer
        else:
            assert format_answer(tuple(float(v) for v in value)) == v_answer


def test_no_benchmark_question_or_scene_appears_in_a_prompt():
    texts = {style: _prompt(style).lower() for style in STYLES}
    for q in QUESTIONS:
        for style, text in texts.items():
            assert q.question.rstrip('?').lower() not in text, (q.id, style)
            assert code_query(q).lower() not in text, (q.id, style)
            assert context_line(q).lower() not in text and answers.scene_text(q).lower() not in text


def test_the_language_prompt_appends_the_question_in_the_examples_layout():
    q = question('position-04')
    base = _prompt('vanilla')
    prompt = language_prompt(q, 'vanilla', base)
    assert prompt.startswith(base.rstrip()) and prompt.endswith('\nA:')
    asked = prompt[len(base.rstrip()):]
    assert asked == ('\n\nQ: On the table: yellow bowl at (0.17, 0.36), purple bowl at (-0.18, -0.37), red block at '
                     '(0.31, -0.07). Where is a point 5 cm below the yellow bowl?\nA:')
    assert language_prompt(question('object-01'), 'cot', _prompt('cot')).endswith('Which block is closest to the '
                                                                                   'green bowl?\nA:')
    with pytest.raises(ValueError):
        language_prompt(q, 'code', base)
    # a model that goes on to invent the next question is cut before it
    assert '\nQ:' in LANGUAGE_STOP
    for style in ('vanilla', 'cot'):
        for _, answer in _language_examples(style):
            assert not any(stop in answer for stop in LANGUAGE_STOP)
