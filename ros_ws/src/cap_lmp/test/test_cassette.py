"""Cassettes: offline replay, clear misses, recording with provenance, keys that survive prompt edits."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

from cap_lmp.cassette import HAND_WRITTEN, Cassette, CassetteClient, CassetteEntry, cassette_key, make_client
from cap_lmp.errors import CassetteMissError
from cap_lmp.cassette import FORMAT as CASSETTE_FORMAT
from cap_lmp.llm import CompletionRequest, OpenAICompatibleClient
from cap_lmp.testing.openai_server import ScriptedOpenAIServer
from cap_lmp.testing.toy_domain import build_engine, toy_lmp_configs
from cap_lmp.testing.toy_world import ToyWorld

SCENE = {'red block': (-0.1, -0.4), 'blue block': (0.1, -0.45), 'red bowl': (-0.15, -0.65), 'blue bowl': (0.15, -0.3)}
CONTEXT = "objects = ['red block', 'blue block', 'red bowl', 'blue bowl']"


def write_cassette(path, entries) -> None:
    path.write_text(yaml.safe_dump({'format': CASSETTE_FORMAT, 'entries': entries}, sort_keys=False))


def test_replay_runs_a_command_offline(tmp_path):
    path = tmp_path / 'demo.yaml'
    write_cassette(path, [
        {'lmp': 'toy_ui', 'query': 'Put the blocks in the bowls with matching colors', 'context': CONTEXT,
         'source': HAND_WRITTEN,
         'completion': "for name in parse_obj_name('the blocks', f'objects = {get_obj_names()}'):\n"
                       "    put_first_on_second(name, name.replace('block', 'bowl'))"},
        {'lmp': 'parse_obj_name', 'query': 'the blocks', 'context': '*', 'source': HAND_WRITTEN,
         'completion': "ret_val = [name for name in objects if 'block' in name]"},
    ])
    world = ToyWorld.with_objects(SCENE)
    engine = build_engine(world.api(), CassetteClient(path))
    result = engine.run('put the  blocks in the bowls with matching colors.')
    assert result.success, result.message
    assert np.allclose(world.get_obj_pos('red block'), SCENE['red bowl'])
    assert np.allclose(world.get_obj_pos('blue block'), SCENE['blue bowl'])


def test_a_missing_entry_names_the_lmp_and_the_query(tmp_path):
    client = CassetteClient(tmp_path / 'empty.yaml')
    with pytest.raises(CassetteMissError) as caught:
        client.complete(CompletionRequest(lmp='parse_position', prompt='...', query='top left corner'))
    assert "LMP 'parse_position'" in str(caught.value) and "query 'top left corner'" in str(caught.value)

    world = ToyWorld.with_objects(SCENE)
    result = build_engine(world.api(), client).run('stack all the blocks')
    assert not result.success and result.error_type == 'CassetteMissError'
    assert "'toy_ui'" in result.message and "'stack all the blocks'" in result.message


def test_record_mode_wraps_a_real_backend_and_writes_provenance(tmp_path):
    path = tmp_path / 'recorded.yaml'
    with ScriptedOpenAIServer({'put the red block in the blue bowl': "put_first_on_second('red block', 'blue bowl')"},
                              model='model-x') as server:
        backend = OpenAICompatibleClient(server.base_url, 'model-x', backoff_s=0.01)
        world = ToyWorld.with_objects(SCENE)
        engine = build_engine(world.api(), CassetteClient(path, mode='record', backend=backend))
        assert engine.run('put the red block in the blue bowl').success
        assert len(server.requests) == 1
    saved = yaml.safe_load(path.read_text())
    assert saved['entries'] == [{'lmp': 'toy_ui', 'query': 'put the red block in the blue bowl',
                                 'context': CONTEXT, 'source': 'recorded from model-x',
                                 'completion': "put_first_on_second('red block', 'blue bowl')"}]
    # the server is gone: replay answers from the file
    world = ToyWorld.with_objects(SCENE)
    replayed = build_engine(world.api(), CassetteClient(path)).run('put the red block in the blue bowl')
    assert replayed.success and np.allclose(world.get_obj_pos('red block'), SCENE['blue bowl'])


def test_keys_survive_prompt_edits_but_not_scene_changes(tmp_path):
    """The key is LMP + normalised query + context line: editing the prompt does not invalidate an entry."""
    path = tmp_path / 'c.yaml'
    cassette = Cassette(path, [CassetteEntry('toy_ui', 'say hello', CONTEXT, "say('hello')", HAND_WRITTEN)])
    cassette.save()
    client = CassetteClient(path)
    config = toy_lmp_configs()[0]
    for prompt in (config.prompt, config.prompt.replace('the bell', 'the gong'), '# a different prompt\n'):
        request = CompletionRequest('toy_ui', prompt + f'{CONTEXT}\n# say hello.\n', 'Say  hello.', CONTEXT)
        assert client.complete(request).text == "say('hello')"
    other_scene = CompletionRequest('toy_ui', '', 'say hello', "objects = ['green block']")
    with pytest.raises(CassetteMissError):
        client.complete(other_scene)
    assert cassette_key('x', ' Say   Hello. ', 'a  =  1') == ('x', 'say hello', 'a = 1')


def test_saved_cassettes_are_readable_yaml_with_literal_code(tmp_path):
    path = tmp_path / 'c.yaml'
    Cassette(path, [CassetteEntry('fgen', 'define function: f(x)', '', 'def f(x):\n    return x\n',
                                  'recorded from m')]).save()
    text = path.read_text()
    assert 'completion: |' in text and '    def f(x):\n        return x' in text
    assert Cassette.load(path).find('fgen', 'define function: f(x)', '').completion == 'def f(x):\n    return x\n'


def test_make_client_picks_the_backend(tmp_path, monkeypatch):
    path = tmp_path / 'made.yaml'
    with ScriptedOpenAIServer({'say hello': "say('hello')"}, model='model-y') as server:
        monkeypatch.setenv('CAP_LLM_BASE_URL', server.base_url)
        monkeypatch.setenv('CAP_LLM_MODEL', 'model-y')
        request = CompletionRequest('toy_ui', '# say hello.\n', 'say hello')
        assert make_client().complete(request).source == 'http'
        assert make_client(path, record=True).complete(request).text == "say('hello')"
    replayed = make_client(path).complete(request)
    assert replayed.text == "say('hello')" and replayed.source == 'recorded from model-y'


def test_replay_ignores_the_time_budget(tmp_path):
    path = tmp_path / 'c.yaml'
    Cassette(path, [CassetteEntry('toy_ui', 'say hello', '*', "say('hello')", HAND_WRITTEN)]).save()
    request = CompletionRequest('toy_ui', '# say hello.\n', 'say hello', CONTEXT, time_budget_s=0.0)
    assert CassetteClient(path).complete(request).text == "say('hello')"
