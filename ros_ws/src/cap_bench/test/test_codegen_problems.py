"""The robot code-generation problems: every reference is a valid sandboxed answer that passes its own cases, wrong
answers fail, test inputs are deterministic and survive being written as source, and the few-shot prompts are
valid programs that give nothing of the benchmark away."""
import ast
import inspect
import json
import re
from pathlib import Path

import numpy as np
import pytest
import shapely
from shapely.geometry import LineString, MultiLineString, MultiPoint, MultiPolygon, Point, Polygon, box
from shapely.geometry.base import BaseGeometry

from cap_bench.codegen import problems as problems_module
from cap_bench.codegen.compare import equivalent
from cap_bench.codegen.literals import call_source, to_source
from cap_bench.codegen.problems import (CATEGORIES, PROBLEMS, ROBOT_API_NAMES, WRONG_SOURCES, Case, cases, problem,
                                        reference_output, reference_source)
from cap_bench.codegen.world import API_DESCRIPTION, CodegenWorld, random_scene
from cap_lmp.functions import undefined_calls
from cap_lmp.sandbox import Sandbox

PROMPTS = Path(problems_module.__file__).with_name('prompts')
SEEDS = (0, 1, 2)
SANDBOX = Sandbox()
WORLD = CodegenWorld()


def _run_in_sandbox(item, source, case):
    """What the harness reports for one case: the function's output as it leaves the sandbox (geometries as WKT),
    with the robot actions for robot API problems."""
    WORLD.begin_case(case.scene)
    scope = SANDBOX.new_scope(WORLD.api() if item.category == 'robot_api' else None)
    program = f'{source}\ncase_result = {call_source(item.name, case.args)}\n'
    SANDBOX.execute(SANDBOX.compile(program, item.name), scope)
    output = scope['case_result']
    if isinstance(output, BaseGeometry):
        output = output.wkt
    if item.category == 'robot_api':
        return {'return': output, 'actions': list(WORLD.actions)}
    return output


def _failures(item, source, seed):
    failed = []
    for index, case in enumerate(cases(item, seed)):
        passed, reason = equivalent(item.compare, reference_output(item, case, WORLD),
                                    _run_in_sandbox(item, source, case))
        if not passed:
            failed.append(f'case {index}: {reason}')
    return failed


# ---------------------------------------------------------------------------------------------------- problems
def test_the_benchmark_has_the_papers_categories_and_counts():
    assert CATEGORIES == {'numpy': 16, 'controls': 4, 'shapely': 10, 'robot_api': 7}
    assert len(PROBLEMS) == 37
    assert [item.category for item in PROBLEMS] == [name for name, count in CATEGORIES.items() for _ in range(count)]
    assert len({item.name for item in PROBLEMS}) == 37
    assert all(problem(item.name) is item for item in PROBLEMS)
    with pytest.raises(KeyError):
        problem('get_closest_idx')


@pytest.mark.parametrize('item', PROBLEMS, ids=lambda item: item.name)
def test_signature_calls_the_function_with_the_references_parameters(item):
    statement = ast.parse(item.signature).body
    assert len(statement) == 1 and isinstance(statement[0], (ast.Assign, ast.Expr))
    call = statement[0].value
    assert isinstance(call, ast.Call) and isinstance(call.func, ast.Name) and call.func.id == item.name
    parameters = list(inspect.signature(item.reference).parameters)
    assert [arg.id for arg in call.args] == parameters
    assert item.reference.__name__ == item.name and getattr(problems_module, item.name) is item.reference
    assert item.compare in ('allclose', 'equal', 'geometry')
    assert 'def' not in item.signature and '"""' not in reference_source(item)  # no docstring to give hints


@pytest.mark.parametrize('item', PROBLEMS, ids=lambda item: item.name)
def test_reference_is_a_valid_answer_and_passes_its_own_cases(item):
    source = reference_source(item)
    SANDBOX.check(source)
    assert source.startswith(f'def {item.name}(')
    assert not any(line.lstrip().startswith('#') for line in source.splitlines())  # answers are cut at a comment
    for seed in SEEDS:
        assert _failures(item, source, seed) == [], f'seed {seed}'


@pytest.mark.parametrize('item', PROBLEMS, ids=lambda item: item.name)
def test_cases_are_deterministic_small_and_varied(item):
    first = cases(item, 3)
    assert 5 <= len(first) <= 8
    assert all(isinstance(case, Case) and isinstance(case.args, tuple) for case in first)
    assert all((case.scene is not None) == (item.category == 'robot_api') for case in first)
    text = [call_source(item.name, case.args) for case in first]
    scenes = [json.dumps(case.scene) for case in first]  # JSON-like
    assert (text, scenes) == ([call_source(item.name, case.args) for case in cases(item, 3)],
                              [json.dumps(case.scene) for case in cases(item, 3)])
    assert (text, scenes) != ([call_source(item.name, case.args) for case in cases(item, 4)],
                              [json.dumps(case.scene) for case in cases(item, 4)])
    assert sum(len(line) for line in text) < 10_000  # the harness writes them into one program
    for case in first:
        reference_output(item, case, WORLD)
    assert [call_source(item.name, case.args) for case in first] == text  # the reference changed no input
    assert [json.dumps(case.scene) for case in first] == scenes


def test_robot_api_outputs_hold_the_return_value_and_json_like_actions():
    for item in PROBLEMS:
        if item.category != 'robot_api':
            continue
        outputs = [reference_output(item, case, WORLD) for case in cases(item, 0)]
        assert all(set(output) == {'return', 'actions'} for output in outputs)
        json.dumps([output['actions'] for output in outputs])
        acts = item.signature.startswith(item.name)  # no return value: the function is judged on its actions
        assert any(output['actions'] for output in outputs) == acts, item.name
        assert all((output['return'] is None) == acts for output in outputs), item.name


def test_reference_stubs_are_the_worlds_api():
    assert set(ROBOT_API_NAMES) == set(CodegenWorld().api())
    with pytest.raises(RuntimeError):
        problems_module.get_obj_names()


@pytest.mark.parametrize('category', list(CATEGORIES))
def test_a_wrong_answer_runs_and_fails(category):
    name, source = WRONG_SOURCES[category]
    item = problem(name)
    assert item.category == category
    SANDBOX.check(source)
    for seed in SEEDS:
        assert _failures(item, source, seed), f'the wrong {name} passed every case of seed {seed}'


# Other correct answers, written differently from the references: the comparison accepts them.
ALTERNATIVES = {
    'get_k_nearest_idxs': 'def get_k_nearest_idxs(points, point, k):\n'
                          '    return np.argsort(np.linalg.norm(points - point, axis=1))[:k]\n',
    'wrap_angles': 'def wrap_angles(angles):\n'
                   '    return np.arctan2(np.sin(angles), np.cos(angles))\n',
    'get_square_polygon': 'def get_square_polygon(center, side_length):\n'
                          '    x, y = center\n'
                          '    h = side_length / 2\n'
                          '    return Polygon([(x + h, y + h), (x - h, y + h), (x - h, y - h), (x + h, y - h)])\n',
    'get_closest_pt_on_line': 'def get_closest_pt_on_line(line, point):\n'
                              '    return nearest_points(line, point)[0]\n',
    'merge_polygons': 'def merge_polygons(polygons):\n'
                      '    shape = polygons[0]\n'
                      '    for polygon in polygons[1:]:\n'
                      '        shape = shape.union(polygon)\n'
                      '    return shape\n',
    'pid_step': 'def pid_step(error, prev_error, integral, dt, kp, ki, kd):\n'
                '    integral += error * dt\n'
                '    return kp * error + ki * integral + kd * (error - prev_error) / dt, integral\n',
    'line_up_objs': 'def line_up_objs(obj_names, start, end):\n'
                    '    for name, pt in zip(obj_names, np.linspace(start, end, len(obj_names))):\n'
                    '        put_first_on_second(name, pt)\n',
}


@pytest.mark.parametrize('name', list(ALTERNATIVES))
def test_other_correct_answers_pass(name):
    for seed in SEEDS:
        assert _failures(problem(name), ALTERNATIVES[name], seed) == []


# ---------------------------------------------------------------------------------------------------- literals
LITERALS = [
    None, True, False, 0, -7, 10 ** 30, 0.1, -0.0, 1e-300, 1.5e16, float('inf'), -float('inf'), 'red block',
    "it's \"quoted\"\n", (), (1,), (1, 2.5), [], [1, [2, (3,)]], {'a': 1, 'b': [0.25]},
    np.array([1.0, 2.0]), np.array([[1, 2], [3, 4]]), np.array([0.1, 1 / 3], dtype=np.float32),
    np.array([1, 2], dtype=np.int32), np.array([True, False]), np.zeros((0, 2)), np.zeros((0,), dtype=np.int64),
    np.array(2.5), np.float64(0.3), np.int64(4), np.float32(0.1),
    Point(0.1, -0.2), Point(1.0, 2.0, 3.0), Point(), LineString([(0, 0), (1, 1.5), (2, 0.3)]),
    Polygon([(0, 0), (1, 0), (1, 1), (0, 1)], [[(0.2, 0.2), (0.4, 0.2), (0.4, 0.4)]]), Polygon(),
    box(-0.1, -0.2, 0.3, 0.4), MultiPoint([(0, 0), (1 / 3, 2 / 3)]),
    MultiLineString([[(0, 0), (1, 1)], [(2, 2), (3, 1)]]),
    MultiPolygon([box(0, 0, 1, 1), box(2, 2, 3, 3)]),
]


def _identical(a, b):
    if isinstance(a, np.ndarray):
        return isinstance(b, np.ndarray) and a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b)
    if isinstance(a, BaseGeometry):
        return type(a) is type(b) and bool(shapely.equals_identical(a, b))
    if isinstance(a, (list, tuple)):
        return type(a) is type(b) and len(a) == len(b) and all(_identical(x, y) for x, y in zip(a, b))
    if isinstance(a, dict):
        return type(b) is dict and a.keys() == b.keys() and all(_identical(a[k], b[k]) for k in a)
    if isinstance(a, float) and np.isnan(a):
        return isinstance(b, float) and np.isnan(b)
    return type(a) is type(b) and a == b and repr(a) == repr(b)


@pytest.mark.parametrize('value', LITERALS + [float('nan')], ids=repr)
def test_literals_rebuild_the_value_exactly_in_the_sandbox(value):
    source = to_source(value)
    scope = SANDBOX.new_scope()
    SANDBOX.execute(SANDBOX.compile(f'rebuilt = {source}\n'), scope)
    assert _identical(value, scope['rebuilt']), source


def test_test_inputs_rebuild_exactly():
    for item in PROBLEMS:
        for case in cases(item, 0):
            scope = SANDBOX.new_scope()
            SANDBOX.execute(SANDBOX.compile(f'rebuilt = {to_source(case.args)}\n'), scope)
            assert _identical(case.args, scope['rebuilt']), item.name


@pytest.mark.parametrize('value', [{1, 2}, 1j, np.array([object()]), np.array(['a']), object()], ids=repr)
def test_values_without_source_text_are_refused(value):
    with pytest.raises(TypeError):
        to_source(value)


# ---------------------------------------------------------------------------------------------------- comparison
def test_allclose_compares_numbers_and_shapes():
    assert equivalent('allclose', np.array([1.0, 2.0]), [1.0, 2.0 + 1e-9]) == (True, '')
    assert equivalent('allclose', (1.0, 2.0), [1.0, 2.0])[0]
    assert equivalent('allclose', (np.zeros(2), 0.5), [[0.0, 0.0], 0.5])[0]  # a tuple of differently shaped items
    passed, reason = equivalent('allclose', np.zeros(2), np.zeros((1, 2)))
    assert not passed and 'shape' in reason
    assert not equivalent('allclose', 1.0, '1.0')[0]  # text is not a number
    assert not equivalent('allclose', 1.0, None)[0]
    assert not equivalent('allclose', 0.5, 0.5001)[0]


def test_equal_normalises_containers_but_not_bools():
    assert equivalent('equal', (1, 2), [1, 2])[0]
    assert equivalent('equal', np.array([True, False]), [True, False])[0]
    assert equivalent('equal', [2], [np.float64(2.0)])[0]
    assert not equivalent('equal', True, 1)[0]
    assert not equivalent('equal', ['red block'], ['red block', 'blue bowl'])[0]


def test_geometry_compares_shapes_from_wkt():
    square = box(0, 0, 1, 1)
    assert equivalent('geometry', square, 'POLYGON ((1 1, 0 1, 0 0, 1 0, 1 1))') == (True, '')
    assert equivalent('geometry', Point(0.5, 0.5), 'POINT (0.5 0.5000000001)')[0]
    assert equivalent('geometry', LineString([(0, 0), (2, 0)]), 'LINESTRING (2 0, 1 0, 0 0)')[0]
    passed, reason = equivalent('geometry', square, 'POLYGON ((0 0, 1 0, 1 2, 0 2, 0 0))')
    assert not passed and 'area' in reason
    passed, reason = equivalent('geometry', square, 'MULTIPOLYGON (((0 0, 1 0, 1 1, 0 1, 0 0)))')
    assert not passed and 'MultiPolygon' in reason
    passed, reason = equivalent('geometry', square, 'POLYGON ((0 0, 1')
    assert not passed and 'WKT' in reason
    assert not equivalent('geometry', square, [0, 0, 1, 1])[0]
    assert not equivalent('geometry', square, 'POLYGON ((0 0, 1 1, 1 0, 0 1, 0 0))')[0]  # self-intersecting


def test_robot_api_outputs_say_which_part_differs():
    expected = {'return': None, 'actions': [{'action': 'say', 'text': 'hi'}]}
    assert equivalent('equal', expected, {'return': None, 'actions': [{'action': 'say', 'text': 'hi'}]})[0]
    passed, reason = equivalent('equal', expected, {'return': 1, 'actions': expected['actions']})
    assert not passed and 'return value' in reason
    passed, reason = equivalent('equal', expected, {'return': None, 'actions': []})
    assert not passed and 'actions' in reason
    assert not equivalent('equal', expected, None)[0]
    with pytest.raises(ValueError):
        equivalent('close enough', 1, 1)


# ---------------------------------------------------------------------------------------------------- world
def _scene():
    return {'objects': [{'name': 'red block', 'pos': [0.0, -0.5], 'size': [0.04, 0.05], 'visible': True},
                        {'name': 'blue bowl', 'pos': [0.1, -0.4], 'size': [0.1, 0.1], 'visible': False}]}


def test_world_answers_queries_and_logs_actions():
    world = CodegenWorld()
    world.begin_case(_scene())
    assert world.get_obj_names() == ['red block', 'blue bowl']
    assert world.get_obj_pos('red block').dtype == float
    np.testing.assert_allclose(world.get_bbox('red block'), [-0.02, -0.525, 0.02, -0.475])
    assert world.is_obj_visible('red block') and not world.is_obj_visible('blue bowl')
    assert not world.is_obj_visible('green block')
    world.put_first_on_second('red block', 'blue bowl')
    np.testing.assert_allclose(world.get_obj_pos('red block'), [0.1, -0.4])  # it moved with the action
    world.put_first_on_second('red block', np.array([0.1 + 0.2 - 0.1, -0.3]))
    world.say('done')
    assert world.actions == [{'action': 'put_first_on_second', 'obj': 'red block', 'target': 'blue bowl'},
                             {'action': 'put_first_on_second', 'obj': 'red block', 'target': [0.2, -0.3]},
                             {'action': 'say', 'text': 'done'}]
    world.begin_case(_scene())
    assert world.actions == [] and world.get_obj_pos('red block').tolist() == [0.0, -0.5]


@pytest.mark.parametrize('call', [
    lambda world: world.get_obj_pos('green block'),
    lambda world: world.get_obj_pos(3),
    lambda world: world.put_first_on_second('red block', 'red block'),
    lambda world: world.put_first_on_second('red block', [1.0, 0.0]),  # off the table
    lambda world: world.put_first_on_second('red block', [0.0, float('nan')]),
    lambda world: world.put_first_on_second('red block', [0.0]),
    lambda world: world.say(['hello']),
])
def test_world_refuses_bad_input_with_value_error(call):
    world = CodegenWorld()
    world.begin_case(_scene())
    with pytest.raises(ValueError):
        call(world)
    assert world.actions == []


def test_random_scenes_have_distinct_names_and_json_like_values():
    scene = random_scene(np.random.default_rng(5), {'block': 4, 'bowl': 3}, hidden=2)
    names = [entry['name'] for entry in scene['objects']]
    assert len(set(names)) == 7 and sum(name.endswith('bowl') for name in names) == 3
    assert sum(not entry['visible'] for entry in scene['objects']) == 2
    assert json.loads(json.dumps(scene)) == scene


# ---------------------------------------------------------------------------------------------------- prompts
def _examples(text):
    return re.findall(r'^# define function: (.*)\.\ndef (\w+)\(', text, flags=re.MULTILINE)


@pytest.mark.parametrize('name', ['flat', 'hierarchical'])
def test_prompt_is_a_valid_program_in_the_expected_format(name):
    text = (PROMPTS / f'{name}.txt').read_text(encoding='utf-8')
    SANDBOX.check(text)
    assert text.startswith('# Python robot-API and geometry helpers;') and API_DESCRIPTION + '\n\n' in text
    assert text.endswith('\n') and not text.endswith('\n\n')
    examples = _examples(text)
    assert 6 <= len(examples) <= 10 and len(examples) == text.count('# define function:')
    for signature, defined in examples:
        call = ast.parse(signature).body[0].value
        assert call.func.id == defined
    for item in PROBLEMS:
        assert item.name not in text


def _undefined(name):
    text = (PROMPTS / f'{name}.txt').read_text(encoding='utf-8')
    known = set(SANDBOX.new_scope(CodegenWorld().api())) | set(SANDBOX.builtins)
    return [call.name for call in undefined_calls(SANDBOX.check(text), known)]


def test_flat_prompt_calls_nothing_undefined():
    assert _undefined('flat') == []


def test_hierarchical_prompt_calls_helpers_it_does_not_define():
    assert len(_undefined('hierarchical')) >= 3
