"""The console's parts without ROS: images to JPEG, the page's state from status events, and the web server's
guards (this host, this page, the page token, one log line per malformed request), page and camera streams, against a
backend in memory (the console node is the real one; see
tests/test_console.py for the page in a browser against the graph)."""
from __future__ import annotations

import array
import asyncio
import http.client
import json
import logging
import re
import socket
import threading
import time

import cv2
import numpy as np
import pytest
from aiohttp import ClientSession, WSServerHandshakeError

from cap_bringup.console.frames import FrameChannel, RawImage, UnsupportedImage, encode_jpeg, image_array
from cap_bringup.console.server import ConsoleServer, guard
from cap_bringup.console.state import ConsoleState, StatusRecord


def _rgb(width: int = 64, height: int = 48, colour: tuple[int, int, int] = (255, 0, 0)) -> RawImage:
    pixels = np.zeros((height, width, 3), np.uint8)
    pixels[:] = colour
    return RawImage('rgb8', width, height, width * 3, array.array('B', pixels.tobytes()), 1.5, 2.5)


def test_an_rgb_image_becomes_a_jpeg_of_the_same_picture():
    decoded = cv2.imdecode(np.frombuffer(encode_jpeg(_rgb()), np.uint8), cv2.IMREAD_COLOR)
    assert decoded.shape == (48, 64, 3)
    assert np.allclose(decoded[24, 32], [0, 0, 255], atol=8)  # BGR: red


def test_depth_is_shown_as_grey_and_other_encodings_are_refused_with_a_reason():
    depth = np.full((4, 4), 1.0, np.float32)
    depth[0, 0] = np.inf
    grey = image_array(RawImage('32FC1', 4, 4, 16, depth.tobytes()))
    assert grey.dtype == np.uint8 and grey[0, 0] == 0 and 0 < grey[1, 1] < 255
    with pytest.raises(UnsupportedImage, match='yuv422'):
        image_array(RawImage('yuv422', 4, 4, 8, bytes(32)))
    with pytest.raises(UnsupportedImage, match='less data'):
        image_array(RawImage('rgb8', 4, 4, 12, bytes(10)))


def test_padded_rows_are_read_by_their_step():
    pixels = np.zeros((2, 8), np.uint8)
    pixels[:, :2] = 200  # 2 pixels of mono8 per row, then 6 bytes of padding
    assert image_array(RawImage('mono8', 2, 2, 8, pixels.tobytes())).tolist() == [[200, 200], [200, 200]]


def test_a_channel_encodes_each_frame_once_whoever_asks():
    channel = FrameChannel('/cap/sim/cameras/front/color')
    assert channel.frame() is None
    channel.put(_rgb())
    first = channel.frame()
    assert first is channel.frame() and first.number == 1 and first.stamp_s == 1.5
    channel.put(_rgb(colour=(0, 255, 0)))
    assert channel.frame().number == 2


def test_the_state_follows_a_command_from_receipt_to_outcome():
    state = ConsoleState(history_size=2)
    state.on_status(StatusRecord('', '', 'model', message='ready: domain tabletop'))
    state.on_status(StatusRecord('cmd-1', 'stack the blocks', 'received'))
    state.on_status(StatusRecord('cmd-1', 'stack the blocks', 'awaiting_approval', code='put_first_on_second()',
                                 plan=({'description': 'put the red block on the blue block'},)))
    assert state.awaiting_approval() == ['cmd-1']
    state.on_status(StatusRecord('cmd-1', 'stack the blocks', 'executing'))
    state.on_say('stacking')
    state.on_status(StatusRecord('cmd-1', 'stack the blocks', 'done', message='done'))
    (entry,) = state.snapshot()['commands']
    assert entry['outcome'] == 'done' and entry['said'] == ['stacking'] and entry['code'] == 'put_first_on_second()'
    assert entry['plan'] == [{'description': 'put the red block on the blue block'}]
    assert state.snapshot()['graph'] == 'ready: domain tabletop' and state.awaiting_approval() == []
    for number in range(2, 5):
        state.on_status(StatusRecord(f'cmd-{number}', 'say hi', 'done'))
    assert [c['id'] for c in state.snapshot()['commands']] == ['cmd-3', 'cmd-4']  # the history is bounded


def test_a_restarted_lmp_node_ends_what_was_open_and_its_reused_ids_are_new_commands():
    state = ConsoleState()
    state.on_status(StatusRecord('cmd-1', 'wave', 'done'))
    state.on_status(StatusRecord('cmd-2', 'stack the blocks', 'executing'))
    state.on_status(StatusRecord('', '', 'model', message='ready: domain tabletop'))
    state.on_status(StatusRecord('cmd-1', 'say hi', 'received'))
    commands = state.snapshot()['commands']
    assert [(c['id'], c['command'], c['outcome']) for c in commands] == [
        ('cmd-1', 'wave', 'done'), ('cmd-2', 'stack the blocks', 'lost'), ('cmd-1', 'say hi', '')]


def test_what_the_robot_says_stays_with_the_running_command_even_before_its_later_statuses_arrive():
    state = ConsoleState()
    state.on_status(StatusRecord('cmd-1', 'say hello', 'received'))
    state.on_status(StatusRecord('cmd-2', 'wave', 'received'))  # queued behind cmd-1
    state.on_say('hello')  # cmd-1's program spoke before its 'executing' status reached the console
    commands = state.snapshot()['commands']
    assert [(c['id'], c['said']) for c in commands] == [('cmd-1', ['hello']), ('cmd-2', [])]
    assert state.snapshot()['notices'] == []


class MemoryBackend:
    """The ConsoleBackend of these tests: one image topic, requests recorded."""

    TOPIC = '/cap/sim/cameras/front/color'

    def __init__(self) -> None:
        self.state = ConsoleState()
        self.channel = FrameChannel(self.TOPIC)
        self.requests: list[tuple] = []
        self.unwatched = threading.Event()

    def run_command(self, text: str) -> None:
        self.requests.append(('run', text))

    def stop(self) -> None:
        self.requests.append(('stop',))

    def reset_session(self) -> None:
        self.requests.append(('reset',))

    def approve(self, command_id: str, approve: bool) -> None:
        self.requests.append(('approve', command_id, approve))

    def watch(self, topic: str):
        if topic != self.TOPIC:
            return None
        self.channel.viewers += 1
        return self.channel

    def unwatch(self, topic: str) -> None:
        self.channel.viewers -= 1
        self.unwatched.set()


@pytest.fixture
def served():
    backend = MemoryBackend()
    server = ConsoleServer(backend, port=0, max_fps=50.0)
    server.start()
    yield backend, server
    server.close()


def _get(server: ConsoleServer, path: str, host: str | None = None, **headers: str) -> tuple[int, bytes, dict]:
    """GET `path`; `headers` by their names with '_' for '-' (Sec_Fetch_Site='cross-site')."""
    connection = http.client.HTTPConnection('127.0.0.1', server.port, timeout=10)
    sent = {name.replace('_', '-'): value for name, value in headers.items()}
    connection.request('GET', path, headers={**sent, 'Host': host} if host else sent)
    response = connection.getresponse()
    body = response.read()
    connection.close()
    return response.status, body, dict(response.getheaders())


def test_the_page_and_its_files_are_served_from_here_only(served):
    _, server = served
    status, body, headers = _get(server, '/')
    assert status == 200 and b'/static/console.js' in body and b'http' not in body.replace(b'http-equiv', b'')
    assert "default-src 'self'" in headers['Content-Security-Policy']
    assert _get(server, '/static/console.js')[0] == 200
    assert _get(server, '/static/..%2Fserver.py')[0] == 404
    assert _get(server, '/', host='evil.example:80')[0] == 403  # a rebound name is not this console


def test_the_websocket_takes_requests_from_the_console_page_only(served):
    backend, server = served

    async def talk() -> list[dict]:
        replies = []
        async with ClientSession() as session:
            with pytest.raises(WSServerHandshakeError):
                await session.ws_connect(f'{server.url}api/events', origin='http://evil.example')
            async with session.ws_connect(f'{server.url}api/events', origin=server.url.rstrip('/')) as socket:
                replies.append(await socket.receive_json(timeout=10))
                for request in ({'op': 'run', 'command': 'stack the blocks'}, {'op': 'stop'},
                                {'op': 'approve', 'command_id': 'cmd-1'}, {'op': 'run', 'command': 'x' * 3000},
                                {'op': 'launch'}):
                    await socket.send_str(json.dumps(request))
                for _ in range(2):
                    replies.append(await socket.receive_json(timeout=10))
        return replies

    state, *refusals = asyncio.run(talk())
    assert state['type'] == 'state' and state['state']['commands'] == []
    assert backend.requests == [('run', 'stack the blocks'), ('stop',), ('approve', 'cmd-1', True)]
    assert [r['text'] for r in refusals] == ['a command is text of at most 2000 characters',
                                             "unknown request 'launch'"]


def _page_token(server: ConsoleServer) -> str:
    """The token the console's page carries, read from the page as the page's script reads it."""
    _, page, _ = _get(server, '/')
    return re.search(rb'<meta name="cap-page-token" content="([0-9a-f]+)">', page).group(1).decode()


def test_a_camera_stream_sends_jpeg_frames_while_watched_and_lets_go_after(served):
    backend, server = served
    token = _page_token(server)
    assert _get(server, f'/stream/cap/sim/cameras/nowhere/color?token={token}')[0] == 404
    connection = http.client.HTTPConnection('127.0.0.1', server.port, timeout=10)
    connection.request('GET', f'/stream{MemoryBackend.TOPIC}?token={token}')
    response = connection.getresponse()
    assert response.getheader('Content-Type') == 'multipart/x-mixed-replace; boundary=cap-frame'
    assert backend.channel.viewers == 1
    backend.channel.put(_rgb())
    assert response.readline() == b'--cap-frame\r\n'
    headers = {}
    while (line := response.readline()) != b'\r\n':
        name, _, value = line.decode().partition(':')
        headers[name] = value.strip()
    assert headers['Content-Type'] == 'image/jpeg' and headers['X-Stamp'] == '1.500000'
    jpeg = response.read(int(headers['Content-Length']))
    assert cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR).shape == (48, 64, 3)
    backend.channel.put(RawImage('yuv422', 4, 4, 8, bytes(32)))  # one it cannot show: the page is told, once
    assert _wait(lambda: [n['text'] for n in backend.state.snapshot()['notices']] == [
        f"{MemoryBackend.TOPIC}: cannot show images encoded 'yuv422'"])
    connection.close()
    backend.channel.put(_rgb())  # the next write finds the browser gone
    assert backend.unwatched.wait(10.0) and backend.channel.viewers == 0


def test_a_camera_stream_needs_the_token_of_the_console_page(served):
    backend, server = served
    token = _page_token(server)
    assert token == server.page_token and len(token) == 48
    for address in (f'/stream{MemoryBackend.TOPIC}', f'/stream{MemoryBackend.TOPIC}?token=',
                    f'/stream{MemoryBackend.TOPIC}?token={token[:-1]}0', f'/stream{MemoryBackend.TOPIC}?token=x'):
        status, body, _ = _get(server, address)
        assert status == 403 and b'console page' in body, address
    assert backend.channel.viewers == 0  # refused before the topic is subscribed
    backend.channel.put(_rgb())
    connection = http.client.HTTPConnection('127.0.0.1', server.port, timeout=10)
    connection.request('GET', f'/stream{MemoryBackend.TOPIC}?token={token}')  # a local program, as the page does
    response = connection.getresponse()
    assert response.status == 200 and response.readline() == b'--cap-frame\r\n'
    connection.close()
    other = ConsoleServer(MemoryBackend(), port=0)  # another console: another token
    assert other.page_token != token
    other.close()


def test_what_a_browser_marks_as_from_another_page_is_refused_everywhere(served):
    _, server = served
    token = _page_token(server)
    stream = f'/stream{MemoryBackend.TOPIC}?token={token}'
    foreign = [  # (path, headers) of requests other pages make
        (stream, {'Sec_Fetch_Site': 'cross-site', 'Sec_Fetch_Mode': 'no-cors', 'Sec_Fetch_Dest': 'image'}),
        (stream, {'Sec_Fetch_Site': 'same-site', 'Sec_Fetch_Mode': 'no-cors', 'Sec_Fetch_Dest': 'image'}),
        ('/static/console.js', {'Sec_Fetch_Site': 'same-site', 'Sec_Fetch_Mode': 'no-cors',
                                'Sec_Fetch_Dest': 'script'}),
        ('/', {'Sec_Fetch_Site': 'cross-site', 'Sec_Fetch_Mode': 'navigate', 'Sec_Fetch_Dest': 'iframe'}),
        (stream, {'Sec_Fetch_Site': 'cross-site', 'Sec_Fetch_Mode': 'navigate', 'Sec_Fetch_Dest': 'document'}),
        (stream, {'Referer': 'http://127.0.0.1:1/page.html'}),  # an older browser: no Sec-Fetch-Site
        ('/static/console.css', {'Referer': 'http://localhost.evil.example/'}),
        (stream, {'Origin': 'http://127.0.0.1:1'}), (stream, {'Origin': 'null'}),
        ('/', {'Sec_Fetch_Site': 'no-such-value'}),
    ]
    for path, headers in foreign:
        status, body, _ = _get(server, path, **headers)
        assert status == 403 and body == b'only the console page itself may use the console\n', (path, headers)
    own = f'http://127.0.0.1:{server.port}/'
    allowed = [  # the console's own page, a person opening it (typed, or a link from elsewhere), a local program
        ('/', {'Sec_Fetch_Site': 'none', 'Sec_Fetch_Mode': 'navigate', 'Sec_Fetch_Dest': 'document'}),
        ('/', {'Sec_Fetch_Site': 'cross-site', 'Sec_Fetch_Mode': 'navigate', 'Sec_Fetch_Dest': 'document'}),
        ('/static/console.js', {'Sec_Fetch_Site': 'same-origin', 'Sec_Fetch_Mode': 'no-cors',
                                'Sec_Fetch_Dest': 'script', 'Referer': own}),
        ('/static/console.css', {'Referer': f'http://localhost:{server.port}/'}), ('/static/console.css', {}),
    ]
    for path, headers in allowed:
        assert _get(server, path, **headers)[0] == 200, (path, headers)
    stream_headers = {'Sec-Fetch-Site': 'same-origin', 'Sec-Fetch-Mode': 'no-cors', 'Sec-Fetch-Dest': 'image',
                      'Referer': own}
    assert guard(f'127.0.0.1:{server.port}', '/stream/x', stream_headers, {f'127.0.0.1:{server.port}'}) == ''
    assert guard('evil.example', '/', {}, {f'127.0.0.1:{server.port}'}).startswith('the console answers only')


def test_a_malformed_request_is_answered_400_and_logged_in_one_line(served, caplog):
    _, server = served
    requests = [f'GET / HTTP/1.1\r\nHost: 127.0.0.1:{server.port}\r\nHost: evil.example\r\n\r\n'.encode(),
                b'GET / HTTP/1.1\r\nHost: x\r\nX-\x1b[31mBad: 1\r\n\r\n',
                b'GET / HTTP/1.1\r\nHost: x\r\nX-Long: ' + b'a' * 20000 + b'\r\n\r\n']
    with caplog.at_level(logging.DEBUG, logger='aiohttp.server'):
        for number, request in enumerate(requests, start=1):
            with socket.create_connection(('127.0.0.1', server.port), timeout=10) as connection:
                connection.sendall(request)
                assert connection.recv(100).startswith(b'HTTP/1.0 400 Bad Request'), request[:60]
            assert _wait(lambda: len(caplog.records) >= number), request[:60]
    assert len(caplog.records) == len(requests)
    for record in caplog.records:
        line = record.getMessage()
        assert record.exc_info is None and not record.exc_text and record.levelno == logging.WARNING
        assert '\n' not in line and '\x1b' not in line and 'a malformed request, answered 400' in line, line
    assert "Duplicate 'Host' header found" in caplog.records[0].getMessage()
    assert len(caplog.records[2].getMessage()) < 500
    assert _get(server, '/')[0] == 200  # and the server goes on


def _wait(predicate, timeout: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and not predicate():
        time.sleep(0.01)
    return predicate()
