"""What the model is asked and how its answers are read and judged, for the reasoning benchmark.

The code answer sees the scene as the context line `objects = {name: (x, y), ...}` above the query comment, as
the project's LMPs do; its `ret_val` is read back with `normalise_code_answer`. The language answers see the same
scene written out in a `Q:` line and answer after `A:`; `parse_answer` reads the object name (the last one named on
the answer line) or the (x, y) pair from the text. `judge` applies the paper's rules: an object answer must name the
right object, a position answer must be within 1 cm.
"""
from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from numbers import Real
from typing import Any

import numpy as np

from cap_bench.reasoning.questions import SCENE_DIGITS, STYLES, Answer, Position, Question, format_position

POSITION_TOLERANCE_M = 0.01
_FLOAT_SLACK_M = 1e-9  # an answer exactly 1 cm off must not fail on float rounding

LANGUAGE_STOP: tuple[str, ...] = ('\nQ:', '\n#')  # the next question, or a comment the prompts start with
LANGUAGE_STYLES = ('vanilla', 'cot')


# -- what the model is asked ----------------------------------------------------------------------------------------
def context_line(q: Question) -> str:
    """"objects = {'red block': (0.12, -0.3), ...}": the code's context line, a literal the program sees as a dict."""
    return f'objects = {dict(q.objects)!r}'


_WHICH = re.compile(r'which (?P<noun>[a-z]+) is (?P<rest>.+)\?')
_ORDINAL = re.compile(r'(?P<ordinal>first|second|third|fourth|fifth) (?P<rest>from .+)')


def code_query(q: Question) -> str:
    """The query comment's text: 'the block farthest from the green bowl' for 'which block is farthest from ...?'."""
    if q.kind == 'position':
        return q.question
    match = _WHICH.fullmatch(q.question)
    if match is None:
        raise ValueError(f'{q.id}: an object question reads "which <noun> is ...?", not {q.question!r}')
    noun, rest = match['noun'], match['rest']
    ordinal = _ORDINAL.fullmatch(rest)
    if ordinal is not None:  # 'second from the left' -> 'the second block from the left'
        return f'the {ordinal["ordinal"]} {noun} {ordinal["rest"]}'
    return f'the {noun} {rest}'


def scene_text(q: Question) -> str:
    """'red block at (0.12, -0.30), green bowl at (-0.20, 0.15)'."""
    return ', '.join(f'{name} at {format_position(xy, SCENE_DIGITS)}' for name, xy in q.objects.items())


def language_question(q: Question) -> str:
    """The `Q:` line of the language prompts: the scene, then the question."""
    asked = q.question[0].upper() + q.question[1:] if q.kind == 'object' else f'Where is {q.question}?'
    return f'Q: On the table: {scene_text(q)}. {asked}'


def language_prompt(q: Question, style: str, base_prompt: str) -> str:
    """The full prompt of a language answer: the style's few-shot prompt, then this question, then 'A:'."""
    if style not in LANGUAGE_STYLES:
        raise ValueError(f'a language prompt is {" or ".join(LANGUAGE_STYLES)}, not {style!r}')
    return f'{base_prompt.rstrip()}\n\n{language_question(q)}\nA:'


# -- reading answers ------------------------------------------------------------------------------------------------
_NUMBER = r'[-+]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][-+]?\d+)?'
_UNIT = r'\s*(?P<{}>cm|mm|m)?(?![a-z])'
_KEYED = re.compile(rf'\bx\s*[=:]\s*(?P<x>{_NUMBER}){_UNIT.format("xu")}\s*[,;]?\s*(?:and\s+)?'
                    rf'\by\s*[=:]\s*(?P<y>{_NUMBER}){_UNIT.format("yu")}', re.IGNORECASE)
_BRACKETED = re.compile(rf'[(\[]\s*(?P<x>{_NUMBER}){_UNIT.format("xu")}\s*,\s*(?P<y>{_NUMBER}){_UNIT.format("yu")}'
                        rf'\s*(?:,\s*{_NUMBER}\s*(?:cm|mm|m)?\s*)?[)\]]', re.IGNORECASE)
_BARE = re.compile(rf'(?P<x>{_NUMBER}){_UNIT.format("xu")}\s*,\s*(?P<y>{_NUMBER}){_UNIT.format("yu")}',
                   re.IGNORECASE)
_METRES = {None: 1.0, 'm': 1.0, 'cm': 0.01, 'mm': 0.001}
MAX_ANSWER_CHARS = 1_000  # of a text answer's final part that is read (answers are a name or a pair)
_FINAL = re.compile(r'answer\s*(?:is|:)', re.IGNORECASE)


def _plain(text: str) -> str:
    return text.replace('\u2212', '-').replace('\u2013', '-')  # a typographic minus is still a minus


def _position_in(text: str) -> Position | None:
    """The last (x, y) pair written in `text`: keyed (x=..., y=...) first, then bracketed, then a bare 'x, y'."""
    text = _plain(text[-MAX_ANSWER_CHARS:])  # the patterns backtrack over long runs of digits: bound the work
    for pattern in (_KEYED, _BRACKETED, _BARE):
        matches = list(pattern.finditer(text))
        if matches:
            last = matches[-1]
            x = float(last['x']) * _METRES[(last['xu'] or '').lower() or None]
            y = float(last['y']) * _METRES[(last['yu'] or '').lower() or None]
            return (x, y) if math.isfinite(x) and math.isfinite(y) else None
    return None


def _words(text: str) -> str:
    return re.sub(r'[\s_-]+', ' ', text.lower())


def _name_in(q: Question, text: str) -> str | None:
    """The object of the scene named last in `text` (case-insensitive; a longer name wins over one inside it)."""
    text = _words(text[-MAX_ANSWER_CHARS:])  # the overlap test below is quadratic in the names found
    found: list[tuple[int, int, str]] = []
    for name in q.objects:
        pattern = rf'(?<![a-z0-9]){re.escape(_words(name))}(?:s|es)?(?![a-z0-9])'
        found += [(m.start(), m.end(), name) for m in re.finditer(pattern, text)]
    kept = [f for f in found if not any(o[0] <= f[0] and f[1] <= o[1] and o[1] - o[0] > f[1] - f[0] for o in found)]
    return max(kept)[2] if kept else None


def _answer_line(style: str, text: str) -> str:
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    if not lines:
        return ''
    if style == 'vanilla':  # the answer alone; anything the model adds after it is not the answer
        return re.sub(r'^A:\s*', '', lines[0])
    for line in reversed(lines):  # chain of thought: the last line that gives "the answer is ..."
        matches = list(_FINAL.finditer(line))
        if matches:
            return line[matches[-1].end():]
    return lines[-1]


def parse_answer(q: Question, style: str, text: str) -> Answer | None:
    """The answer a text gives: an object of the scene, or an (x, y) pair in metres; None if it gives none.

    'vanilla' reads the first line; 'cot' the final answer line ('So the answer is ...', else the last line); 'code'
    reads the text as the reported value of ret_val."""
    if style not in STYLES:
        raise ValueError(f'a style is one of {", ".join(STYLES)}, not {style!r}')
    if not isinstance(text, str):
        return None
    if style == 'code':
        return normalise_code_answer(q, text)
    line = _answer_line(style, text)
    return _name_in(q, line) if q.kind == 'object' else _position_in(line)


def _exact_name(q: Question, value: str) -> str | None:
    wanted = _words(value).strip()
    return next((name for name in q.objects if _words(name) == wanted), None)


def normalise_code_answer(q: Question, value: Any) -> Answer | None:
    """ret_val as the sandbox reports it -> an object of the scene, an (x, y) pair in metres, or None.

    Object questions take a name (any case; a one-element list of it too; a longer text: the last name in it).
    Position questions take 2 or 3 numbers (list, tuple, array; z is dropped), {'x': .., 'y': ..}, or a text
    showing the pair; a bare object name is not a position."""
    if value is None:
        return None
    if q.kind == 'object':
        if isinstance(value, (list, tuple)) and len(value) == 1:
            value = value[0]
        if isinstance(value, np.ndarray) and value.size == 1 and value.dtype.kind in 'US':
            value = str(value.reshape(-1)[0])
        if not isinstance(value, str):
            return None
        return _exact_name(q, value) or _name_in(q, value)
    if isinstance(value, str):
        return None if _exact_name(q, value) else _position_in(value)
    if isinstance(value, Mapping):
        value = [value.get('x'), value.get('y')]
    if not isinstance(value, (Sequence, np.ndarray)):
        return None
    try:
        items = np.asarray(value, dtype=object).reshape(-1)
        if any(isinstance(v, (bool, np.bool_)) or not isinstance(v, Real) for v in items):
            return None  # True/False or nested text are no coordinates
        numbers = np.asarray(items, dtype=float)
    except (TypeError, ValueError):
        return None
    if numbers.size not in (2, 3) or not np.all(np.isfinite(numbers)):
        return None
    return (float(numbers[0]), float(numbers[1]))


# -- judging ------------------------------------------------------------------------------------------------------
def judge(q: Question, value: Answer | None) -> tuple[bool, str]:
    """(correct, why): an object answer names the right object; a position is within POSITION_TOLERANCE_M."""
    if value is None:
        return False, 'no answer'
    if q.kind == 'object':
        if not isinstance(value, str):
            return False, f'{value!r} is not an object name (expected {q.answer!r})'
        if _words(value).strip() == _words(q.answer):
            return True, f'{q.answer!r}'
        return False, f'{value!r}, expected {q.answer!r}'
    if isinstance(value, str) or len(value) != 2 or not all(isinstance(v, Real) for v in value):
        return False, f'{value!r} is not an (x, y) position (expected {format_position(q.answer)})'
    distance = math.dist(value, q.answer)
    within = distance <= POSITION_TOLERANCE_M + _FLOAT_SLACK_M
    verdict = 'within' if within else 'beyond'
    return within, (f'{format_position(value)} is {distance * 100:.1f} cm from {format_position(q.answer)} '
                    f'({verdict} {POSITION_TOLERANCE_M * 100:.0f} cm)')
