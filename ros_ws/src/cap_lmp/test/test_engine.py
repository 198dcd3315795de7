"""The engine end to end against a real OpenAI-protocol HTTP server on 127.0.0.1 with scripted answers, over the toy
domain's world in memory."""
from __future__ import annotations

import threading

import numpy as np
import pytest

from cap_lmp.engine import CODE, DONE, ERROR, EXECUTING, GENERATING, Engine, LMPConfig
from cap_lmp.llm import OpenAICompatibleClient
from cap_lmp.sandbox import SandboxLimits
from cap_lmp.testing.openai_server import ScriptedOpenAIServer, ScriptedReply
from cap_lmp.testing.toy_domain import build_engine
from cap_lmp.testing.toy_world import ToyWorld

SCENE = {'red block': (-0.1, -0.4), 'blue block': (0.1, -0.45), 'green block': (0.0, -0.6),
         'red bowl': (-0.15, -0.65), 'blue bowl': (0.15, -0.3)}


@pytest.fixture
def world() -> ToyWorld:
    return ToyWorld.with_objects(SCENE)


def make_engine(server: ScriptedOpenAIServer, world: ToyWorld, api: str = 'chat', **options) -> Engine:
    client = OpenAICompatibleClient(server.base_url, model='scripted-model', api=api, backoff_s=0.01,
                                    timeout_s=5.0)
    options.setdefault('limits', SandboxLimits(time_limit_s=1.0))
    return build_engine(world.api(), client, **options)


def fgen_requests(server: ScriptedOpenAIServer) -> list[str]:
    return [r.prompt.splitlines()[-1] for r in server.requests if 'define function:' in r.prompt.splitlines()[-1]]


def test_three_levels_of_generated_functions(server, world):
    server.answers.update({
        'put the blocks in a row on the top side': (
            "block_names = ['red block', 'blue block', 'green block']\n"
            "row_pts = get_row_pts(parse_position('top side'), len(block_names))\n"
            "for name, pt in zip(block_names, row_pts):\n"
            "    put_first_on_second(name, pt)"),
        '# top side.': 'ret_val = np.array([0.0, -0.25])',
        'define function: row_pts = get_row_pts(': (
            'def get_row_pts(center, n):\n'
            '    return [offset_pt(center, dx) for dx in spread(n, 0.1)]'),
        'define function: offset_pt(': 'def offset_pt(pt, dx):\n    return np.array(pt) + np.array([dx, 0.0])',
        'define function: spread(': (
            'def spread(n, gap):\n'
            '    return [centered_offset(i, n, gap) for i in range(n)]'),
        'define function: centered_offset(': 'def centered_offset(i, n, gap):\n    return (i - (n - 1) / 2) * gap',
    })
    engine = make_engine(server, world)
    result = engine.run('put the blocks in a row on the top side')
    assert result.success, result.message
    positions = [world.get_obj_pos(name) for name in ('red block', 'blue block', 'green block')]
    assert np.allclose(positions, [[-0.1, -0.25], [0.0, -0.25], [0.1, -0.25]])
    # depth first: get_row_pts -> offset_pt, spread -> centered_offset (three levels)
    assert result.generated_functions == ['get_row_pts', 'offset_pt', 'spread', 'centered_offset']
    for name in result.generated_functions:
        assert f'def {name}(' in result.code
    # asked with parameter names, not the call's values (a small model copies values into its `def` line)
    assert fgen_requests(server)[0] == '# define function: row_pts = get_row_pts(position, n).'
    assert fgen_requests(server)[1] == '# define function: offset_pt(center, dx).'

    # the functions stay for later commands: no new definitions are asked for
    server.answers['now spread them again'] = (
        "for name, pt in zip(['red block', 'blue block'], get_row_pts(np.array([0.0, -0.5]), 2)):\n"
        "    put_first_on_second(name, pt)")
    asked_before = len(fgen_requests(server))
    again = engine.run('now spread them again')
    assert again.success, again.message
    assert len(fgen_requests(server)) == asked_before
    assert np.allclose(world.get_obj_pos('red block'), [-0.05, -0.5])


def test_a_session_remembers_variables_until_reset(server, world):
    server.answers.update({
        'remember where the red block is': "saved_pos = get_obj_pos('red block')\nsay('Ok')",
        'put the blue block where the red block was': (
            "put_first_on_second('red block', 'blue bowl')\nput_first_on_second('blue block', saved_pos)"),
    })
    engine = make_engine(server, world)
    assert engine.run('remember where the red block is').success
    second = engine.run('put the blue block where the red block was')
    assert second.success, second.message
    assert np.allclose(world.get_obj_pos('blue block'), SCENE['red block'])
    # the second prompt carried the first command and its code
    assert "# remember where the red block is.\nsaved_pos = get_obj_pos('red block')" in server.requests[-1].prompt

    engine.reset()
    third = engine.run('put the blue block where the red block was')
    assert not third.success
    assert third.error_type == 'NameError' and 'saved_pos' in third.message
    assert 'remember where the red block is' not in server.requests[-1].prompt


def test_generated_code_calls_another_lmp(server, world):
    server.answers.update({
        'put the blocks in the red bowl': (
            "block_names = parse_obj_name('the blocks', f'objects = {get_obj_names()}')\n"
            "for name in block_names:\n    put_first_on_second(name, 'red bowl')"),
        '# the blocks.': "ret_val = [name for name in objects if 'block' in name]",
    })
    engine = make_engine(server, world)
    events = []
    engine.add_listener(events.append)
    result = engine.run('put the blocks in the red bowl')
    assert result.success, result.message
    for name in ('red block', 'blue block', 'green block'):
        assert np.allclose(world.get_obj_pos(name), SCENE['red bowl'])
    nested_prompt = server.requests[-1].prompt
    assert nested_prompt.rstrip().endswith(
        "objects = ['red block', 'blue block', 'green block', 'red bowl', 'blue bowl']\n# the blocks.")
    assert result.model_calls == 2
    assert [(e.stage, e.lmp) for e in events] == [
        (GENERATING, 'toy_ui'), (CODE, 'toy_ui'), (EXECUTING, 'toy_ui'),
        (GENERATING, 'parse_obj_name'), (CODE, 'parse_obj_name'), (DONE, 'toy_ui')]


def test_a_nested_lmp_that_forgets_ret_val_returns_its_last_assignment(server, world):
    server.answers.update({
        'put the blocks in the blue bowl': (
            "block_names = parse_obj_name('the blocks', f'objects = {get_obj_names()}')\n"
            "for name in block_names:\n    put_first_on_second(name, 'blue bowl')"),
        '# the blocks.': "block_names = [name for name in objects if 'block' in name]",  # no ret_val
        'say the bowls': "say(parse_obj_name('the bowls', f'objects = {get_obj_names()}'))",
        '# the bowls.': "print('thinking')",  # nothing assigned at the end: still an error
    })
    engine = make_engine(server, world)
    result = engine.run('put the blocks in the blue bowl')
    assert result.success, result.message
    assert np.allclose(world.get_obj_pos('green block'), SCENE['blue bowl'])
    failed = engine.run('say the bowls')
    assert not failed.success and 'the parse_obj_name program did not set ret_val' in failed.message


def test_a_syntax_error_from_the_model_is_reported_cleanly(server, world):
    server.answers['put the red block in the blue bowl'] = "put_first_on_second('red block', 'blue bowl'\nsay('x')"
    server.answers['say hello'] = "say('hello')"
    engine = make_engine(server, world)
    events = []
    engine.add_listener(events.append)
    result = engine.run('put the red block in the blue bowl')
    assert not result.success
    assert result.error_type == 'SyntaxError'
    assert 'syntax error at line 1' in result.message
    assert events[-1].stage == ERROR and events[-1].message == result.message
    assert np.allclose(world.get_obj_pos('red block'), SCENE['red block'])  # nothing ran
    assert engine.run('say hello').success and world.said == ['hello']


def test_a_429_is_retried_and_the_command_succeeds(server, world):
    server.answers['say hello'] = "say('hello')"
    server.push(ScriptedReply(status=429, headers={'Retry-After': '0'}))
    engine = make_engine(server, world)
    result = engine.run('say hello')
    assert result.success, result.message
    assert world.said == ['hello']
    assert len(server.requests) == 2


def test_an_infinite_loop_is_stopped_and_the_engine_keeps_working(server, world):
    server.answers['count forever'] = 'i = 0\nwhile True:\n    i += 1'
    server.answers['say hello'] = "say('hello')"
    engine = make_engine(server, world)
    result = engine.run('count forever')
    assert not result.success
    assert result.error_type == 'ExecutionStopped'
    assert 'time limit of 1 s' in result.message
    assert engine.run('say hello').success


def test_cancel_from_another_thread(server, world):
    server.answers['wait for ever'] = 'while True:\n    pass'
    engine = make_engine(server, world, limits=SandboxLimits(time_limit_s=60.0))
    started = threading.Event()
    engine.add_listener(lambda event: event.stage == EXECUTING and started.set())
    canceller = threading.Thread(target=lambda: started.wait(10) and engine.cancel())
    canceller.start()
    result = engine.run('wait for ever')
    canceller.join()
    assert not result.success
    assert result.error_type == 'ExecutionStopped' and 'cancelled' in result.message
    assert result.stop_reason == 'cancelled'


def test_an_api_error_names_the_object_and_the_line(server, world):
    server.answers['put the purple block in the red bowl'] = (
        "say('Ok')\nput_first_on_second('purple block', 'red bowl')")
    engine = make_engine(server, world)
    result = engine.run('put the purple block in the red bowl')
    assert not result.success
    assert result.error_type == 'UnknownObjectError'
    assert "there is no object called 'purple block'" in result.message
    assert result.error_line == 2
    assert "put_first_on_second('purple block', 'red bowl')" in result.message


def test_the_model_defining_another_function_is_an_error(server, world):
    server.answers['stack them'] = 'stack_blocks()'
    server.answers['define function: stack_blocks('] = 'def stack_all_blocks():\n    pass'
    engine = make_engine(server, world)
    result = engine.run('stack them')
    assert not result.success
    assert result.error_type == 'GenerationError'
    assert 'asked the model to define stack_blocks(), but its code defines stack_all_blocks()' in result.message


def test_function_generation_depth_is_limited(server, world):
    server.answers['go deep'] = 'level_0()'
    for level in range(10):
        server.answers[f'define function: level_{level}('] = f'def level_{level}():\n    return level_{level + 1}()'
    engine = make_engine(server, world, max_function_depth=3)
    result = engine.run('go deep')
    assert not result.success
    assert 'deeper than 3 levels (level_0 -> level_1 -> level_2 -> level_3)' in result.message
    assert len(fgen_requests(server)) == 3


def test_mutually_recursive_functions_are_generated_once_each(server, world):
    server.answers.update({
        'is four even': "say(is_even(4))",
        'define function: is_even(': 'def is_even(n):\n    return True if n == 0 else is_odd(n - 1)',
        'define function: is_odd(': 'def is_odd(n):\n    return False if n == 0 else is_even(n - 1)',
    })
    engine = make_engine(server, world)
    result = engine.run('is four even')
    assert result.success, result.message
    assert world.said == ['True']
    assert len(fgen_requests(server)) == 2


def test_a_refused_generated_function_is_reported(server, world):
    server.answers['sneak'] = 'helper()'
    server.answers['define function: helper('] = 'def helper():\n    return say.__globals__'
    engine = make_engine(server, world)
    result = engine.run('sneak')
    assert not result.success and result.error_type == 'CodeRejected'
    assert "helper() was refused" in result.message and '__globals__' in result.message


def test_transform_shape_pts_receives_variables(server, world):
    server.answers.update({
        'move the square to the left': (
            "square = np.array([[0.0, -0.5], [0.1, -0.5], [0.1, -0.4], [0.0, -0.4]])\n"
            "moved = transform_shape_pts('move it 5cm to the left', shape_pts=square)\n"
            "say(str(np.round(moved[0], 3).tolist()))"),
        '# move it 5cm to the left.': 'new_shape_pts = shape_pts + np.array([-0.05, 0.0])',
    })
    engine = make_engine(server, world)
    result = engine.run('move the square to the left')
    assert result.success, result.message
    assert world.said == ['[-0.05, -0.5]']


def test_legacy_completions_end_to_end(server, world):
    server.answers['put the green block in the blue bowl'] = "put_first_on_second('green block', 'blue bowl')"
    engine = make_engine(server, world, api='completions')
    result = engine.run('put the green block in the blue bowl')
    assert result.success, result.message
    assert np.allclose(world.get_obj_pos('green block'), SCENE['blue bowl'])
    request = server.requests[-1]
    assert request.path == '/v1/completions'
    assert request.body['stop'] == ['#', 'objects = [']
    assert result.prompt_tokens == len(request.prompt.split()) and result.completion_tokens > 0


def test_result_reports_calls_tokens_and_timings(server, world):
    server.answers['say hello'] = "say('hello')"
    engine = make_engine(server, world)
    result = engine.run('say hello')
    assert result.model_calls == 1 and result.completion_tokens == 1
    assert set(result.timings) >= {'total_s', 'model_s', 'execute_s', 'overhead_s'}
    assert result.code == "say('hello')"


def test_plain_lmps_without_the_tabletop_domain(server):
    """An Engine over any API: a non-session LMP returns its value to the caller."""
    server.answers['the sum of the sizes'] = 'ret_val = sum(sizes())'
    client = OpenAICompatibleClient(server.base_url, model='scripted-model', backoff_s=0.01)
    engine = Engine([LMPConfig('ask', '# answer in ret_val.\n', stop=('#',), has_return=True)], client,
                    {'sizes': lambda: [1, 2, 3]}, fgen_lmp=None)
    assert engine.call_lmp('ask', 'the sum of the sizes') == 6


def test_cancel_while_waiting_for_the_model(server, world):
    """A stop during generation: the program never runs."""
    server.answers['put the red block in the blue bowl'] = "put_first_on_second('red block', 'blue bowl')"
    server.push(ScriptedReply(delay_s=0.5))
    engine = make_engine(server, world)
    engine.add_listener(lambda event: event.stage == GENERATING and threading.Timer(0.1, engine.cancel).start())
    result = engine.run('put the red block in the blue bowl')
    assert not result.success and 'cancelled' in result.message
    assert np.allclose(world.get_obj_pos('red block'), SCENE['red block'])


def test_an_error_inside_a_generated_function_names_that_function(server, world):
    server.answers['tidy up'] = "move_to_bowl('green block')"
    server.answers['define function: move_to_bowl('] = (
        "def move_to_bowl(name):\n    bowl = name.replace('block', 'bowl')\n    put_first_on_second(name, bowl)")
    engine = make_engine(server, world)
    result = engine.run('tidy up')
    assert not result.success and result.error_type == 'UnknownObjectError'
    assert "there is no object called 'green bowl'" in result.message
    assert 'line 3 of the generated function move_to_bowl: `put_first_on_second(name, bowl)`' in result.message
