"""The local model server: a real llama.cpp server on loopback with the default model (`make model`).

Without the installed model these tests are skipped, unless CAP_REQUIRE_LOCAL_MODEL=1 (CI) makes that a failure.
"""
import os
import signal
import threading
import time
import zipfile

import pytest

from cap_lmp.errors import LLMError
from cap_lmp.llm import CompletionRequest
from cap_lmp.local_model import ModelFile
from cap_lmp.local_server import (LocalModelClient, LocalModelError, LocalModelServer, ServerSettings,
                                  local_model_installed, warm_up)
from cap_lmp.model_install import file_sha256, join_parts

needs_model = pytest.mark.skipif(not local_model_installed() and os.environ.get('CAP_REQUIRE_LOCAL_MODEL') != '1',
                                 reason='the local model is not installed (make model)')


def test_a_missing_model_file_says_how_to_install_it(tmp_path):
    server = LocalModelServer(ServerSettings(model_file=str(tmp_path / 'absent.gguf')))
    with pytest.raises(LocalModelError, match='make model'):
        server.start()


def test_parts_are_joined_in_order_and_checked(tmp_path):
    import hashlib
    data = [b'first part ', b'second part ', b'third']
    wheels = {}
    for index, chunk in enumerate(data, start=1):
        wheels[index] = tmp_path / f'p{index}.whl'
        with zipfile.ZipFile(wheels[index], 'w') as wheel:
            wheel.writestr(f'toy_part{index}/data/part{index:02d}.bin', chunk)
    whole = b''.join(data)
    model = ModelFile('toy.gguf', hashlib.sha256(whole).hexdigest(), len(whole), 'none',
                      tuple(f'toy-part{i}==1.0' for i in (1, 2, 3)), '{module}/data/part{index:02d}.bin')
    target = tmp_path / 'toy.gguf'
    assert join_parts(model, wheels, target) == model.sha256
    assert target.read_bytes() == whole and file_sha256(target) == model.sha256


def _ask(client, prompt: str, tokens: int) -> str:
    return client.complete(CompletionRequest(lmp='test', prompt=prompt, query='', max_tokens=tokens)).text


@pytest.mark.slow
@needs_model
def test_the_server_answers_is_restarted_after_its_death_and_stops_with_its_owner():
    events = []
    server = LocalModelServer(ServerSettings(threads=1, context_size=2048), on_event=events.append)
    server.start()
    try:
        client = LocalModelClient(server)
        assert 'return' in _ask(client, 'def add(a, b):\n    """The sum of a and b."""\n', 12)

        # killed while idle: started again, and answers again
        first = server.pid
        os.kill(first, signal.SIGKILL)
        deadline = time.monotonic() + 30
        while server.generation < 2 and time.monotonic() < deadline:
            time.sleep(0.1)
        server.wait_ready(120)
        assert server.pid != first and server.deaths[-1].exit_code == -signal.SIGKILL
        assert any('died (exit code -9); restarting' in event for event in events)

        # killed while answering: that request fails saying so; the next one is answered by the restarted server
        killer = threading.Timer(1.5, lambda: os.kill(server.pid, signal.SIGKILL))
        killer.start()
        with pytest.raises(LocalModelError, match='stopped during the request .*send the command again'):
            _ask(client, 'Count from one to two hundred, in words, one number per line:\n', 600)
        killer.join()
        server.wait_ready(120)
        assert _ask(client, 'def add(a, b):\n    """The sum of a and b."""\n', 12)
    finally:
        pid = server.pid
        server.stop()
    with pytest.raises(ProcessLookupError):  # gone, not a zombie left to the caller
        os.kill(pid, 0)


def test_errors_of_the_local_model_are_model_errors():
    assert issubclass(LocalModelError, LLMError)  # the engine reports them as "the model gave no usable answer"


def _uncached_prompt_tokens(server: LocalModelServer, prompt: str) -> tuple[int, str]:
    """How many tokens of `prompt` the server evaluated (llama.cpp's `timings.prompt_n`), and its greedy answer."""
    import requests
    reply = requests.post(f'{server.base_url}/completions', timeout=120, json={
        'model': server.model_name, 'prompt': prompt, 'max_tokens': 8, 'temperature': 0.0}).json()
    return int(reply['timings']['prompt_n']), reply['choices'][0]['text']


@pytest.mark.slow
@needs_model
def test_prompts_read_once_are_restored_by_the_next_start_and_answer_the_same(tmp_path):
    # two prompts of a few hundred tokens sharing their first line, as a domain's LMPs do
    lines = [f'# {name}: the position of the {name} block, in metres' for name in ('red', 'green', 'blue', 'pink')]
    first = 'import numpy as np\n' + '\n'.join(lines * 6) + '\n'
    second = 'import numpy as np\n' + '\n'.join(reversed(lines * 6)) + '\n'
    prompts = [('ui', first), ('parse_obj_name', second)]
    settings = ServerSettings(threads=1, context_size=2048, prompt_cache_dir=str(tmp_path))

    with LocalModelServer(settings) as cold:
        said = warm_up(LocalModelClient(cold), prompts)
        assert said.startswith('2 prompts,') and 'restored' not in said, said
        answer_cold = _uncached_prompt_tokens(cold, first + '# yellow:')[1]
    assert len(list(tmp_path.glob('*.kv'))) == 2 and not list(tmp_path.glob('*.tmp'))

    with LocalModelServer(settings) as warm:
        said = warm_up(LocalModelClient(warm), prompts)
        assert '2 restored' in said and ', 0 tokens read' in said, said
        # both prompts are in the server's cache: only the new words are read, and the answer is the one the
        # freshly read prompt gave
        evaluated, answer_warm = _uncached_prompt_tokens(warm, first + '# yellow:')
        assert evaluated <= 6 and answer_warm == answer_cold
        assert _uncached_prompt_tokens(warm, second + '# yellow:')[0] <= 6
        # a prompt that changed is read afresh, never served from another prompt's file
        said = warm_up(LocalModelClient(warm), [('ui', first + '# one more line\n')])
        assert said.startswith('1 prompt,') and 'restored' not in said, said
