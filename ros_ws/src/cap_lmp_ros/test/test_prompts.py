"""The prompts: only the benchmark's seen templates and attributes, valid sandboxed code, the paper's few-shot style."""
from __future__ import annotations

import ast
import re

import pytest

from cap_lmp.functions import undefined_calls
from cap_lmp.prompts import load_prompt, prompt_names
from cap_lmp_ros.domains.tabletop.lmps import PROMPTS_DIR
from cap_lmp.sandbox import check_code
from cap_lmp_ros.domains.tabletop.lmps import build_engine, tabletop_lmp_configs
from cap_lmp_ros.testing.table import Table

LMP_PROMPTS = ['tabletop_ui', 'parse_obj_name', 'parse_position', 'parse_question', 'transform_shape_pts', 'fgen']

# The benchmark's attribute values that are "unseen" (never in prompts, so the model must generalise to them).
# "right" is an unseen direction; the only allowed use of the word is the seen corner "top right corner".
UNSEEN_ATTRIBUTES = [r'pink', r'cyan', r'brown', r'gr[ae]y', r'purple', r'bottom', r'right', r'farthest', r'furthest',
                     r'a lot', r'third', r'fourth', r'3rd', r'4th', r'diagonal\w*']
# The benchmark's unseen instruction templates, whatever attribute values they are written with.
UNSEEN_TEMPLATES = {
    'different corners': r'different corners',
    'mismatched colors': r'mis-?match',
    'stack all the blocks on the <corner/side>': r'stack[^\n]*\bon the [\w ]*(corner|side)',
    'place it <magnitude> to the <direction> of the <bowl>': r'(a little|a lot|a bit)[^\n]*of the \w+ bowl',
    'place it in the corner <distance> to the <bowl>': r'corner (closest|nearest|farthest|furthest) to',
    'put all the blocks in a <line> line': r'\bin an? (\w+ )?line\b',
}


def examples(prompt: str) -> list[tuple[str, str]]:
    """(query comment, code) pairs of a prompt: the hints before the first blank line are skipped."""
    body = prompt.split('\n\n', 1)[1]
    pairs: list[tuple[str, list[str]]] = []
    for line in body.splitlines():
        if line.startswith('# '):
            pairs.append((line, []))
        elif line.startswith('objects = ['):
            continue  # context line of the next example
        elif pairs:
            pairs[-1][1].append(line)
    return [(query, '\n'.join(code)) for query, code in pairs]


def test_every_lmp_has_its_prompt():
    assert set(LMP_PROMPTS) <= set(prompt_names(PROMPTS_DIR))
    assert {config.name for config in tabletop_lmp_configs()} == set(LMP_PROMPTS)


@pytest.mark.parametrize('name', LMP_PROMPTS)
def test_prompts_contain_no_unseen_attribute(name):
    text = load_prompt(PROMPTS_DIR, name).lower().replace('top right corner', '')
    for word in UNSEEN_ATTRIBUTES:
        found = re.search(rf'\b{word}\b', text)
        assert found is None, f'{name}: unseen attribute {found.group(0)!r}'


@pytest.mark.parametrize('name', LMP_PROMPTS)
def test_prompts_contain_no_unseen_template(name):
    text = load_prompt(PROMPTS_DIR, name).lower()
    for template, pattern in UNSEEN_TEMPLATES.items():
        found = re.search(pattern, text)
        assert found is None, f'{name}: unseen template "{template}" in {found.group(0)!r}'


def test_the_checks_would_catch_unseen_text():
    """The patterns above are not vacuous: they fire on the benchmark's unseen instructions."""
    unseen = ['put all the blocks in different corners', 'put the blocks in the bowls with mismatched colors',
              'stack all the blocks on the top left corner',
              'pick up the red block and place it a little to the left of the blue bowl',
              'pick up the red block and place it in the corner closest to the blue bowl',
              'put all the blocks in a horizontal line']
    for instruction in unseen:
        assert any(re.search(pattern, instruction) for pattern in UNSEEN_TEMPLATES.values()), instruction
    assert re.search(r'\bpink\b', 'the pink block')


@pytest.mark.parametrize('name', LMP_PROMPTS)
def test_every_example_is_code_the_sandbox_accepts(name):
    pairs = examples(load_prompt(PROMPTS_DIR, name))
    assert len(pairs) >= 8
    for query, code in pairs:
        assert query.endswith('.') or query.endswith('?'), query
        assert code.strip(), f'{name}: no code for {query}'
        assert '#' not in code, f'{name}: the stop token "#" inside the code of {query}'
        check_code(code)


def test_tabletop_ui_has_thirty_examples_with_their_scene():
    prompt = load_prompt(PROMPTS_DIR, 'tabletop_ui')
    assert len(examples(prompt)) >= 30
    assert prompt.count('\nobjects = [') == len(examples(prompt))


def test_examples_call_only_the_api_the_lmps_and_functions_fgen_knows():
    """Every bare name the examples call exists for generated code, or is defined by an fgen example (so a model
    following the examples meets the same names at run time)."""
    engine = build_engine(Table().api(), client=None)  # no model needed to inspect the scope
    known = set(engine.scope) | set(engine.scope['__builtins__'])
    fgen_defined = {name for _query, code in examples(load_prompt(PROMPTS_DIR, 'fgen'))
                    for name in [node.name for node in ast.parse(code).body if isinstance(node, ast.FunctionDef)]}
    for name in LMP_PROMPTS:
        for query, code in examples(load_prompt(PROMPTS_DIR, name)):
            missing = {call.name for call in undefined_calls(ast.parse(code), known)}
            assert missing <= fgen_defined, f'{name}: {query} calls {missing - fgen_defined}'
