"""A real HTTP server on 127.0.0.1 speaking the OpenAI chat and legacy completions protocols, with scripted answers.

For tests and offline demos: it answers `POST /v1/chat/completions` and `POST /v1/completions` (also without the
`/v1` prefix) from rules that match the query of the prompt, and can be told to fail or stall first (429, 500,
a delay longer than the client's timeout, a connection closed mid-answer, an answer trickled out byte by byte).
It records every request it received.

    with ScriptedOpenAIServer({'put the red block': 'say("ok")'}) as server:
        client = OpenAICompatibleClient(server.base_url, model=server.model)
"""
from __future__ import annotations

import json
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any, Callable, Mapping


@dataclass
class ScriptedReply:
    """A one-off reply served before the rules: a status with an error, a delay, or a fixed text.

    `close_after_bytes`: announce the whole body, send only this many bytes of it and close the connection.
    `trickle_s`: send the body one byte at a time, this long apart (each read of the client then succeeds quickly).
    """

    status: int = 200
    text: str | None = None
    delay_s: float = 0.0
    headers: dict[str, str] = field(default_factory=dict)
    close_after_bytes: int | None = None
    trickle_s: float = 0.0


@dataclass
class RecordedRequest:
    path: str
    headers: dict[str, str]
    body: dict[str, Any]

    @property
    def prompt(self) -> str:
        if 'messages' in self.body:
            return '\n'.join(str(m.get('content', '')) for m in self.body['messages'] if m.get('role') == 'user')
        return str(self.body.get('prompt', ''))


def last_query_line(prompt: str) -> str:
    """The last non-empty line of a prompt: where an LMP puts its query."""
    for line in reversed(prompt.splitlines()):
        if line.strip():
            return line.strip()
    return ''


def by_attempt(answers: Mapping[str, tuple[str, str]]) -> Callable[[RecordedRequest], str | None]:
    """A responder: for a query containing a key, the first answer when asked at temperature 0, the second when
    sampled (a request with a seed: the engine asking again after an answer that could not run)."""
    def respond(request: RecordedRequest) -> str | None:
        query = last_query_line(request.prompt)
        for key, (first, sampled) in answers.items():
            if key in query:
                return sampled if request.body.get('seed') is not None else first
        return None
    return respond


class ScriptedOpenAIServer:
    """See the module docstring. `answers` maps a substring of the query line to the completion text; the longest
    matching key wins. `responder(request) -> str | None` may be given instead or in addition."""

    def __init__(self, answers: Mapping[str, str] | None = None, *, model: str = 'scripted-model',
                 responder: Callable[[RecordedRequest], str | None] | None = None, fence_chat: bool = True) -> None:
        self.answers = dict(answers or {})
        self.model = model
        self.responder = responder
        self.fence_chat = fence_chat
        self.requests: list[RecordedRequest] = []
        self._queue: deque[ScriptedReply] = deque()
        self._lock = threading.Lock()
        self._server: ThreadingHTTPServer | None = None
        self._thread: threading.Thread | None = None

    # -- script -------------------------------------------------------------------------------------------
    def push(self, *replies: ScriptedReply) -> None:
        """Serve these replies, in order, to the next requests (before any rule)."""
        with self._lock:
            self._queue.extend(replies)

    def answer_for(self, request: RecordedRequest) -> str | None:
        if self.responder is not None:
            text = self.responder(request)
            if text is not None:
                return text
        query = last_query_line(request.prompt)
        matches = [key for key in self.answers if key in query]
        if not matches:
            return None
        return self.answers[max(matches, key=len)]

    # -- server -------------------------------------------------------------------------------------------
    @property
    def base_url(self) -> str:
        assert self._server is not None, 'start the server first'
        host, port = self._server.server_address[:2]
        return f'http://{host}:{port}/v1'

    def start(self) -> 'ScriptedOpenAIServer':
        self._server = ThreadingHTTPServer(('127.0.0.1', 0), _handler_for(self))
        self._server.daemon_threads = True
        self._thread = threading.Thread(target=self._server.serve_forever, name='scripted-openai', daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        if self._server is not None:
            self._server.shutdown()
            self._server.server_close()
            self._server = None

    def __enter__(self) -> 'ScriptedOpenAIServer':
        return self.start()

    def __exit__(self, *exc_info: object) -> None:
        self.stop()

    def _next_scripted(self) -> ScriptedReply | None:
        with self._lock:
            return self._queue.popleft() if self._queue else None

    def _respond(self, path: str, request: RecordedRequest
                 ) -> tuple[int, dict[str, Any], dict[str, str], ScriptedReply | None]:
        with self._lock:
            self.requests.append(request)
        chat = path.endswith('/chat/completions')
        if not chat and not path.endswith('/completions'):
            return 404, {'error': {'message': f'no endpoint {path}'}}, {}, None
        scripted = self._next_scripted()
        if scripted is not None:
            if scripted.delay_s:
                time.sleep(scripted.delay_s)
            if scripted.status != 200:
                return (scripted.status, {'error': {'message': f'scripted status {scripted.status}'}},
                        scripted.headers, scripted)
        text = scripted.text if scripted is not None and scripted.text is not None else self.answer_for(request)
        if text is None:
            return 400, {'error': {'message': f'no scripted answer for {last_query_line(request.prompt)!r}'}}, {}, None
        usage = {'prompt_tokens': len(request.prompt.split()), 'completion_tokens': len(text.split())}
        usage['total_tokens'] = usage['prompt_tokens'] + usage['completion_tokens']
        if chat:
            content = f'```python\n{text}\n```' if self.fence_chat else text
            choice = {'index': 0, 'message': {'role': 'assistant', 'content': content}, 'finish_reason': 'stop'}
            kind = 'chat.completion'
        else:
            choice = {'index': 0, 'text': text, 'finish_reason': 'stop'}
            kind = 'text_completion'
        body = {'id': f'scripted-{len(self.requests)}', 'object': kind, 'created': int(time.time()),
                'model': request.body.get('model') or self.model, 'choices': [choice], 'usage': usage}
        return 200, body, {}, scripted


def _handler_for(server: ScriptedOpenAIServer) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        protocol_version = 'HTTP/1.1'

        def do_POST(self) -> None:  # noqa: N802 (http.server's naming)
            length = int(self.headers.get('Content-Length') or 0)
            raw = self.rfile.read(length) if length else b''
            try:
                body = json.loads(raw or b'{}')
            except ValueError:
                self._send(400, {'error': {'message': 'the request body is not JSON'}}, {}, None)
                return
            request = RecordedRequest(self.path, {k.lower(): v for k, v in self.headers.items()}, body)
            self._send(*server._respond(self.path, request))

        def _send(self, status: int, payload: dict[str, Any], headers: dict[str, str],
                  scripted: ScriptedReply | None) -> None:
            data = json.dumps(payload).encode()
            try:
                self.send_response(status)
                self.send_header('Content-Type', 'application/json')
                self.send_header('Content-Length', str(len(data)))
                for key, value in headers.items():
                    self.send_header(key, value)
                self.end_headers()
                if scripted is not None and scripted.close_after_bytes is not None:
                    self.wfile.write(data[:scripted.close_after_bytes])
                    self.wfile.flush()
                    self.close_connection = True
                elif scripted is not None and scripted.trickle_s:
                    for index in range(len(data)):
                        self.wfile.write(data[index:index + 1])
                        self.wfile.flush()
                        time.sleep(scripted.trickle_s)
                else:
                    self.wfile.write(data)
            except (BrokenPipeError, ConnectionResetError):
                pass  # the client gave up (timeout test)

        def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 (signature of the base class)
            pass

    return Handler
