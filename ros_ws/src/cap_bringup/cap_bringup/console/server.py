"""The console's web server: the page, a websocket for events and commands, MJPEG camera streams. No rclpy: it talks
to the graph through a ConsoleBackend (the console node), and runs its own asyncio loop in a thread of its own.

Why aiohttp: one small, long-kept asyncio library (aio-libs) serves plain HTTP, a websocket and a streamed
response; an ASGI stack would need a server and a framework. Why MJPEG: an <img> shows it with no script, and
each frame is a JPEG the server encodes once for every browser watching.

Only this host, only this page: the server listens on 127.0.0.1 and answers only requests addressed to 127.0.0.1 or
localhost at its port (a page of another site that rebinds its own name to 127.0.0.1 gets 403). A browser sends
requests here for any page it shows, another site's too, so every request it marks as made elsewhere is refused
(`guard`):
- Sec-Fetch-Site (sent by every current browser): only `same-origin` or `none` (an address typed or bookmarked)
  pass; a cross-site or same-site request (another port of this host is the same site) passes only as a top-level
  navigation to the page itself, which shows the page to the person and nothing to the other site.
- Origin, when sent (always for a websocket: browsers let any site open one): only this console's.
- Referer, when sent and there is no Sec-Fetch-Site (an older browser): only this console's page.
- Camera streams (`/stream/<topic>`) and the twin's pictures (`/twin/<command id>`) need the page token as well: a
  random secret of this server, put into the page it serves and passed by the page in each address (`?token=`). A
  page of another site cannot read the console's page, so it cannot name a stream even from a browser that sends
  none of the headers above (an `<img>` sends no Origin); this holds whatever a browser sends, which is why streams
  rely on it and not on headers only.
A program without those headers (curl, a script) is a local user, as any process on this host that can reach the
graph is: it may do what the page does, the page token read from the page first.

A request HTTP itself cannot read (a duplicated Host header, a bad method, an oversized line) gets aiohttp's 400 and
one line in the log, not a traceback: it is the client's mistake, and a flood of them must not flood the log.
Everything the page needs is in static/ and served from here: no network beyond this host.
"""
from __future__ import annotations

import asyncio
import concurrent.futures
import hmac
import json
import logging
import pathlib
import secrets
import sys
import threading
from typing import Any, Mapping, Protocol
from urllib.parse import urlsplit

from aiohttp import WSMsgType, web
from aiohttp.http_exceptions import HttpProcessingError
from aiohttp.log import server_logger

from cap_bringup.console.frames import FrameChannel
from cap_bringup.console.state import ConsoleState
from cap_lmp.safe_text import one_line

STATIC_DIR = pathlib.Path(__file__).resolve().parent / 'static'
STATIC_FILES = {'console.js': 'text/javascript', 'console.css': 'text/css'}
MAX_COMMAND_CHARS = 2000  # a longer one is not forwarded (lmp_node refuses over 1,000 anyway, saying why)
_STATE_POLL_S = 0.1  # how often each page's writer looks for a new state
_BOUNDARY = 'cap-frame'
PAGE_TOKEN_MARK = '{{page_token}}'  # where index.html carries the page token
_FROM_ELSEWHERE_SITES = ('cross-site', 'same-site')  # Sec-Fetch-Site values of a request another page made


def guard(host: str, path: str, headers: Mapping[str, str], hosts: set[str]) -> str:
    """Why a request to this console is refused, in words; '' when it may pass (see the module docstring). `host`:
    the request's Host; `hosts`: this console's host:port names."""
    if host not in hosts:
        return 'the console answers only at 127.0.0.1 or localhost'
    site = headers.get('Sec-Fetch-Site')
    if site in _FROM_ELSEWHERE_SITES and not (path == '/' and headers.get('Sec-Fetch-Mode') == 'navigate'
                                              and headers.get('Sec-Fetch-Dest') == 'document'):
        return 'only the console page itself may use the console'
    if site is not None and site not in _FROM_ELSEWHERE_SITES + ('same-origin', 'none'):
        return 'only the console page itself may use the console'  # a value no browser sends
    origin = headers.get('Origin')
    if origin is not None and origin.removeprefix('http://') not in hosts:
        return 'only the console page itself may use the console'
    referer = headers.get('Referer')
    if site is None and referer is not None and path != '/' and not _own_page(referer, hosts):
        return 'only the console page itself may use the console'
    return ''


def _own_page(url: str, hosts: set[str]) -> bool:
    try:
        parts = urlsplit(url)
    except ValueError:
        return False
    return parts.scheme == 'http' and parts.netloc in hosts


class _OneLineLog(logging.LoggerAdapter):
    """aiohttp's server log, where a request HTTP cannot read is one line (what was wrong), never a traceback; the
    server's own failures keep theirs."""

    def log(self, level: int, msg: Any, *args: Any, **kwargs: Any) -> None:
        error = kwargs.get('exc_info')
        if error is True:
            error = sys.exc_info()[1]
        if isinstance(error, HttpProcessingError):
            kwargs['exc_info'] = None
            level = min(level, logging.WARNING)  # the client's mistake, not the server's
            text = msg % args if args else str(msg)
            msg, args = '%s: a malformed request, answered %s: %s', (text, error.code, one_line(error.message, 300))
        super().log(level, msg, *args, **kwargs)


class ConsoleBackend(Protocol):
    """What the web server needs of the graph (the console node provides it). Called from the server's threads."""

    state: ConsoleState

    def run_command(self, text: str) -> None: ...

    def stop(self) -> None: ...

    def reset_session(self) -> None: ...

    def approve(self, command_id: str, approve: bool) -> None: ...

    def watch(self, topic: str) -> FrameChannel | None:
        """The channel of an image topic the graph offers (one more viewer), or None for any other name."""
        ...

    def unwatch(self, topic: str) -> None:
        """One viewer less (after `watch` gave a channel)."""
        ...


class ConsoleServer:
    """Serves the console on 127.0.0.1:`port` (0: a free port) from a thread of its own; `start()` returns the URL."""

    def __init__(self, backend: ConsoleBackend, port: int = 0, max_fps: float = 10.0) -> None:
        self.backend = backend
        self.port = port
        self.max_fps = max_fps
        self.url = ''
        self._loop: asyncio.AbstractEventLoop | None = None
        self._runner: web.AppRunner | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        # JPEG encoding off the event loop; two workers: one per camera streaming at a time is typical.
        self._pool = concurrent.futures.ThreadPoolExecutor(2, thread_name_prefix='console_jpeg')
        self.frames_sent = 0
        # The page token (module docstring): new for every server, so an old page's stream addresses die with it.
        self.page_token = secrets.token_hex(24)
        self._page = (STATIC_DIR / 'index.html').read_text(encoding='utf-8').replace(PAGE_TOKEN_MARK, self.page_token)

    # -------------------------------------------------------------------------------------------- life
    def start(self) -> str:
        self._thread = threading.Thread(target=self._serve, name='console_web', daemon=True)
        self._thread.start()
        self._ready.wait(30.0)
        if self._error is not None:
            raise OSError(f'the console cannot listen on 127.0.0.1:{self.port}: {self._error}') from self._error
        return self.url

    def _serve(self) -> None:
        loop = self._loop = asyncio.new_event_loop()
        asyncio.set_event_loop(loop)
        try:
            loop.run_until_complete(self._open())
        except BaseException as error:  # noqa: BLE001 - reported by start()
            self._error = error
            self._ready.set()
            return
        self._ready.set()
        loop.run_forever()
        loop.run_until_complete(self._runner.cleanup())
        loop.close()

    async def _open(self) -> None:
        app = web.Application(middlewares=[self._only_this_page], client_max_size=64 * 1024)
        app.router.add_get('/', self._index)
        app.router.add_get('/static/{name}', self._static)
        app.router.add_get('/api/events', self._events)
        app.router.add_get('/stream/{topic:.+}', self._stream)
        app.router.add_get('/twin/{command_id}', self._twin)
        self._runner = web.AppRunner(app, access_log=None, handle_signals=False, shutdown_timeout=1.0,
                                     logger=_OneLineLog(server_logger, {}))
        await self._runner.setup()
        site = web.TCPSite(self._runner, '127.0.0.1', self.port)
        await site.start()
        self.port = site._server.sockets[0].getsockname()[1]  # the port bound, when 0 asked for a free one
        self.url = f'http://127.0.0.1:{self.port}/'

    def close(self) -> None:
        loop = self._loop
        if loop is not None and loop.is_running():
            loop.call_soon_threadsafe(loop.stop)
        if self._thread is not None:
            self._thread.join(5.0)
        self._pool.shutdown(wait=False, cancel_futures=True)

    # -------------------------------------------------------------------------------------------- guards
    def _hosts(self) -> set[str]:
        return {f'127.0.0.1:{self.port}', f'localhost:{self.port}'}

    @web.middleware
    async def _only_this_page(self, request: web.Request, handler: Any) -> web.StreamResponse:
        refusal = guard(request.host, request.path, request.headers, self._hosts())
        if refusal:
            return web.Response(status=403, text=refusal + '\n')
        return await handler(request)

    # -------------------------------------------------------------------------------------------- page
    async def _index(self, _request: web.Request) -> web.Response:
        return web.Response(text=self._page, content_type='text/html', headers=_PAGE_HEADERS)

    async def _static(self, request: web.Request) -> web.StreamResponse:
        name = request.match_info['name']
        if name not in STATIC_FILES:  # a fixed list: no path from the request reaches the file system
            raise web.HTTPNotFound()
        return web.FileResponse(STATIC_DIR / name, headers={**_PAGE_HEADERS, 'Content-Type': STATIC_FILES[name]})

    # -------------------------------------------------------------------------------------------- events
    async def _events(self, request: web.Request) -> web.WebSocketResponse:
        socket = web.WebSocketResponse(max_msg_size=64 * 1024, heartbeat=20.0)
        await socket.prepare(request)
        writer = asyncio.ensure_future(self._send_states(socket))
        try:
            async for message in socket:
                if message.type != WSMsgType.TEXT:
                    continue
                reply = self._handle(message.data)
                if reply:
                    await socket.send_json({'type': 'reply', 'text': reply})
        finally:
            writer.cancel()
        return socket

    async def _send_states(self, socket: web.WebSocketResponse) -> None:
        state, sent = self.backend.state, -1
        while not socket.closed:
            if state.version != sent:
                sent = state.version
                await socket.send_json({'type': 'state', 'state': state.snapshot()})
            await asyncio.sleep(_STATE_POLL_S)

    def _handle(self, data: str) -> str:
        """Carry out one request of the page; a problem with it comes back as words for the page."""
        try:
            request = json.loads(data)
        except ValueError:
            return 'not a request'
        if not isinstance(request, dict):
            return 'not a request'
        op = request.get('op')
        if op == 'run':
            text = request.get('command')
            if not isinstance(text, str) or len(text) > MAX_COMMAND_CHARS:
                return f'a command is text of at most {MAX_COMMAND_CHARS} characters'
            self.backend.run_command(text)
        elif op == 'stop':
            self.backend.stop()
        elif op == 'reset':
            self.backend.reset_session()
        elif op in ('approve', 'reject'):
            command_id = request.get('command_id')
            if not isinstance(command_id, str) or len(command_id) > 100:
                return 'which command? (command_id)'
            self.backend.approve(command_id, op == 'approve')
        else:
            return f'unknown request {str(op)[:50]!r}'
        return ''

    # -------------------------------------------------------------------------------------------- cameras
    async def _twin(self, request: web.Request) -> web.Response:
        """The twin's picture shown with a command's approval (a PNG), with the page token like a stream."""
        if not hmac.compare_digest(request.query.get('token', '').encode(), self.page_token.encode()):
            return web.Response(status=403, text='the twin\'s picture is shown only on the console page\n')
        picture = self.backend.state.twin_picture(request.match_info['command_id'])
        if not picture:
            raise web.HTTPNotFound(text='no picture of the twin for that command\n')
        return web.Response(body=picture, content_type='image/png', headers={'Cache-Control': 'no-store'})

    async def _stream(self, request: web.Request) -> web.StreamResponse:
        if not hmac.compare_digest(request.query.get('token', '').encode(), self.page_token.encode()):
            return web.Response(status=403, text='a camera stream is shown only on the console page: its address '
                                                 'carries the page token\n')
        topic = '/' + request.match_info['topic'].strip('/')
        channel = self.backend.watch(topic)
        if channel is None:
            raise web.HTTPNotFound(text=f'no image topic {topic}\n')
        loop = asyncio.get_running_loop()
        arrived = asyncio.Event()

        def notify() -> None:
            loop.call_soon_threadsafe(arrived.set)

        channel.add_listener(notify)
        response = web.StreamResponse(headers={
            'Content-Type': f'multipart/x-mixed-replace; boundary={_BOUNDARY}', 'Cache-Control': 'no-store'})
        try:
            await response.prepare(request)
            await response.write(f'--{_BOUNDARY}\r\n'.encode())
            seen, sent_number, sent_at, told = 0, 0, -1.0, False
            while True:
                arrived.clear()
                if channel.number == seen:
                    await arrived.wait()
                pause = sent_at + 1.0 / self.max_fps - loop.time()
                if pause > 0:  # at most max_fps: what arrives meanwhile replaces the frame
                    await asyncio.sleep(pause)
                seen = channel.number
                frame = await loop.run_in_executor(self._pool, channel.frame)
                if frame is None:
                    if channel.error and not told:  # an image it cannot show: said once, then the next image
                        self.backend.state.notice('error', channel.error)
                        told = True
                    continue
                if frame.number == sent_number:
                    continue
                sent_number, sent_at = frame.number, loop.time()
                # Each part ends with the next boundary at once, so the browser shows it without waiting for more.
                await response.write(
                    f'Content-Type: image/jpeg\r\nContent-Length: {len(frame.jpeg)}\r\n'
                    f'X-Stamp: {frame.stamp_s:.6f}\r\nX-Received: {frame.received_s:.6f}\r\n\r\n'.encode()
                    + frame.jpeg + f'\r\n--{_BOUNDARY}\r\n'.encode())
                self.frames_sent += 1
        except (ConnectionError, asyncio.CancelledError):
            pass  # the browser stopped watching
        finally:
            channel.remove_listener(notify)
            self.backend.unwatch(topic)
        return response


# The page may be framed by nobody and load nothing from elsewhere.
_PAGE_HEADERS = {'Cache-Control': 'no-store', 'X-Frame-Options': 'DENY', 'X-Content-Type-Options': 'nosniff',
                 'Content-Security-Policy': "default-src 'self'; img-src 'self'; connect-src 'self'; "
                                            "frame-ancestors 'none'"}


__all__ = ['ConsoleBackend', 'ConsoleServer', 'MAX_COMMAND_CHARS', 'PAGE_TOKEN_MARK', 'STATIC_DIR', 'guard']
