"""Fixtures the engine's tests share."""
import pytest

from cap_lmp.testing.openai_server import ScriptedOpenAIServer


@pytest.fixture
def server():
    """A real OpenAI-protocol server on loopback that answers with what the test scripts."""
    with ScriptedOpenAIServer() as scripted:
        yield scripted
