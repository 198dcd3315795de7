"""An Engine in a process of its own, so that no generated program can take lmp_node down with it.

The in-process sandbox (sandbox.py) stops what Python can see: loops, recursion, known expensive operations. Some
C-level work it cannot interrupt or survive: hashing a 300,000-deep nested tuple overflows the C stack and kills
the interpreter; `str([row] * 1000)` of a million-element row holds the interpreter for hours. IsolatedEngine runs
the session (engine, scope, generated functions, LLM client) in `python -m cap_llm.engine_process` and keeps the
robot here: the program's robot API calls arrive as messages (wire.py: JSON, never pickle) and are answered by the
functions given to the constructor.

The sandbox process is treated as hostile: it may send anything, half a message, or nothing. This side reads
frames from a polled socket (a half-sent frame never blocks), sends with a timeout, checks every field it receives,
and kills the process (its whole process group) when:

- **crash**: the process died (a signal, an exit) ('crashed'; 'memory' when it exited for lack of memory);
- **stall**: no message for `stall_limit_s` while it works (its heartbeat thread cannot run while one C call holds
  the interpreter); time the node spends in robot API calls does not count ('stalled');
- **cancel**: cancel() was called and no result came within `cancel_grace_s` of the cancel or of the end of the
  robot call that was running then ('cancelled');
- **deadline**: the command ran past `time_limit_s` + `model_allowance_s` (a process that keeps talking but never
  finishes) ('timeout');
- **protocol**: a malformed, over-long or out-of-turn message, or a send that did not complete within
  `send_timeout_s` ('protocol').

The process also has an address-space limit (RLIMIT_AS): a MemoryError inside the program is reported like any
exception. A lost process means a lost session (variables and generated functions); a new process starts at once,
and the result's message says so.

What it is not: a security jail. The sandbox process runs as the same user, sees the same files and may open
sockets; generated code that escaped the in-process checks could reach them. It bounds crashes, stalls, memory and
stops; for models you do not trust at all, also run the node in a container or as a user of its own.
"""
from __future__ import annotations

import dataclasses
import os
import select
import signal
import socket
import subprocess
import sys
import threading
import time
from typing import Any, Callable, Mapping, Sequence

from cap_llm import wire
from cap_llm.engine import CODE, DONE, ERROR, EXECUTING, GENERATING, CommandResult, EngineEvent
from cap_llm.errors import SandboxProcessLost
from cap_llm.sandbox import SandboxLimits

_SESSION_LOST = 'the session was lost (earlier variables and generated functions are forgotten) and a new one started'
_STAGES = (GENERATING, CODE, EXECUTING, DONE, ERROR)
_MAX_MESSAGE_CHARS = 10_000
# Environment the sandbox process keeps: what Python, the model client and its TLS need; nothing of ROS.
_KEPT_ENVIRONMENT = ('PATH', 'HOME', 'LANG', 'LC_ALL', 'TMPDIR', 'HTTP_PROXY', 'HTTPS_PROXY', 'NO_PROXY',
                     'http_proxy', 'https_proxy', 'no_proxy', 'SSL_CERT_FILE', 'SSL_CERT_DIR', 'REQUESTS_CA_BUNDLE',
                     'OPENAI_API_KEY')


class _ProcessLost(Exception):
    """Internal: the sandbox process must be (or was) ended for `reason`."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


def _text(value: Any, limit: int) -> str:
    if not isinstance(value, str):
        raise _ProcessLost('protocol')
    return value[:limit]


def _event(message: Mapping[str, Any]) -> EngineEvent:
    command_id, stage = message.get('command_id'), message.get('stage')
    if not isinstance(command_id, int) or stage not in _STAGES:
        raise _ProcessLost('protocol')
    return EngineEvent(command_id, stage, _text(message.get('lmp'), 200), _text(message.get('code', ''),
                       wire.MAX_CODE_CHARS), _text(message.get('message', ''), _MAX_MESSAGE_CHARS))


def _result(values: Any) -> CommandResult:
    """A CommandResult from the sandbox process' message, every field checked."""
    if not isinstance(values, dict):
        raise _ProcessLost('protocol')
    checks = {'command': str, 'command_id': int, 'success': bool, 'code': str, 'message': str, 'error_type': str,
              'stop_reason': str, 'model_calls': int, 'prompt_tokens': int, 'completion_tokens': int}
    fields: dict[str, Any] = {}
    for name, kind in checks.items():
        value = values.get(name)
        if not isinstance(value, kind) or (kind is int and isinstance(value, bool)):
            raise _ProcessLost('protocol')
        fields[name] = value[:wire.MAX_CODE_CHARS] if isinstance(value, str) else value
    line = values.get('error_line')
    if line is not None and (not isinstance(line, int) or isinstance(line, bool)):
        raise _ProcessLost('protocol')
    fields['error_line'] = line
    source = values.get('error_source')
    fields['error_source'] = _text(source, 1000) if source is not None else None
    timings, functions = values.get('timings'), values.get('generated_functions')
    if not isinstance(timings, dict) or not isinstance(functions, list):
        raise _ProcessLost('protocol')
    fields['timings'] = {str(k): float(v) for k, v in list(timings.items())[:20]
                         if isinstance(v, (int, float)) and not isinstance(v, bool)}
    fields['generated_functions'] = [_text(name, 200) for name in functions[:100]]
    return CommandResult(**fields)


class IsolatedEngine:
    """run / cancel / reset / add_listener / close, like Engine, with the session in a sandbox process."""

    def __init__(self, api: Mapping[str, Callable[..., Any]], client_options: Mapping[str, Any],
                 limits: SandboxLimits | None = None, *, domain: str = 'tabletop', stall_limit_s: float = 10.0,
                 cancel_grace_s: float = 2.0, start_timeout_s: float = 60.0, send_timeout_s: float = 5.0,
                 model_allowance_s: float = 900.0, address_space_extra_bytes: int | None = None,
                 child_command: Sequence[str] | None = None) -> None:
        self.limits = limits or SandboxLimits()
        # The sandbox process' command line; the socket fds are appended. Tests put a misbehaving process here.
        self._child_command = list(child_command or [sys.executable, '-m', 'cap_llm.engine_process'])
        self._api = dict(api)
        self._setup = {
            'op': 'setup', 'api': sorted(self._api), 'client': dict(client_options), 'domain': domain,
            'limits': dataclasses.asdict(self.limits),
            # Room for the program's own data (the sandbox's limit) plus the allocator's and libraries' slack.
            'address_space_extra_bytes': (address_space_extra_bytes if address_space_extra_bytes is not None
                                          else self.limits.max_memory_growth_bytes + (1 << 30)),
        }
        self.stall_limit_s = stall_limit_s
        self.cancel_grace_s = cancel_grace_s
        self.start_timeout_s = start_timeout_s
        self.send_timeout_s = send_timeout_s
        self.model_allowance_s = model_allowance_s
        self.default_lmp = ''
        self.restarts = 0
        # Robot API round trips as generated code saw them (socket and node included), over recent commands.
        self.api_call_seconds: list[float] = []
        self._listeners: list[Callable[[EngineEvent], None]] = []
        self._run_lock = threading.Lock()  # one run, reset or restart at a time
        self._state_lock = threading.Lock()  # _run_id, _cancel_at and _closed, shared with cancel() and close()
        self._run_id = 0
        self._running = False
        self._cancel_at: float | None = None
        self._closed = False
        self._process: subprocess.Popen | None = None
        self._data: socket.socket | None = None  # setup, run, reset, replies; events, calls, results
        self._control: socket.socket | None = None  # cancel only, so that it never waits behind a reply
        self._frames = wire.FrameBuffer(wire.MAX_RESULT_BYTES)
        self._poller: select.poll | None = None
        self._start()

    # -------------------------------------------------------------------------------------------- process
    def _start(self) -> None:
        data, child_data = socket.socketpair()
        control, child_control = socket.socketpair()
        env = {name: os.environ[name] for name in _KEPT_ENVIRONMENT if name in os.environ}
        env.update({name: value for name, value in os.environ.items() if name.startswith('CAP_LLM_')})
        # The same modules as here; one BLAS thread (the program's arrays are small, threads cost memory).
        env.update({'PYTHONPATH': os.pathsep.join(path for path in sys.path if path), 'OPENBLAS_NUM_THREADS': '1',
                    'OMP_NUM_THREADS': '1', 'PYTHONDONTWRITEBYTECODE': '1'})
        with child_data, child_control:
            fds = (child_data.fileno(), child_control.fileno())
            # A session of its own: a kill reaches whatever the process may have forked.
            self._process = subprocess.Popen([*self._child_command, *map(str, fds)], pass_fds=fds, env=env,
                                             stdin=subprocess.DEVNULL, start_new_session=True)
        data.settimeout(self.send_timeout_s)  # bounds sends; receives happen only after poll says data is there
        control.settimeout(self.send_timeout_s)
        self._data, self._control = data, control
        self._frames = wire.FrameBuffer(wire.MAX_RESULT_BYTES)
        self._poller = select.poll()
        self._poller.register(data.fileno(), select.POLLIN)
        try:
            self._send({**self._setup})
            deadline = time.monotonic() + self.start_timeout_s
            while True:
                message = self._receive(0.05)
                if message is not None and message.get('op') == 'ready':
                    break
                if self._process.poll() is not None:
                    raise _ProcessLost('crashed')
                if time.monotonic() > deadline:
                    raise _ProcessLost('protocol')
        except (_ProcessLost, OSError, wire.WireError):
            reason = self._end_process()
            raise RuntimeError(f'the sandbox process did not start ({reason}); see its log above') from None
        default_lmp = message.get('default_lmp')
        self.default_lmp = default_lmp if isinstance(default_lmp, str) else ''

    def _send(self, message: dict[str, Any] | bytes) -> None:
        """Send a message (or one already encoded)."""
        if self._data is None:
            raise _ProcessLost('crashed')
        try:
            self._data.sendall(wire.frame(message if isinstance(message, bytes) else wire.encode(message)))
        except (OSError, wire.WireError):  # a full socket the process does not read, or a closed one
            raise _ProcessLost('protocol') from None

    def _receive(self, timeout_s: float) -> dict[str, Any] | None:
        """The next whole message, or None if none is complete within `timeout_s`."""
        if self._data is None or self._poller is None:
            raise _ProcessLost('crashed')
        frame = self._frames.next_frame()
        if frame is None:
            if not self._poller.poll(timeout_s * 1000):
                return None
            try:
                chunk = self._data.recv(1 << 16)
            except (BlockingIOError, socket.timeout):
                return None
            except OSError:
                raise _ProcessLost('crashed') from None
            if not chunk:
                raise _ProcessLost('crashed')
            self._frames.feed(chunk)
            frame = self._frames.next_frame()
            if frame is None:
                return None
        return wire.decode(frame)

    def _end_process(self) -> str:
        """Kill the process group, close the sockets; return how the process ended."""
        process = self._process
        if process is not None:
            # The whole group, also when the process itself has exited: a grandchild may hold the socket.
            try:
                os.killpg(process.pid, signal.SIGKILL)
            except (ProcessLookupError, PermissionError):
                if process.poll() is None:
                    process.kill()
            code = process.wait()
        for connection in (self._data, self._control):
            if connection is not None:
                connection.close()
        self._data = self._control = self._poller = None
        if process is None:
            return 'not started'
        if code >= 0:
            return f'exit code {code}'
        try:
            return f'killed by {signal.Signals(-code).name}'
        except ValueError:  # a real-time signal has no name
            return f'killed by signal {-code}'

    @property
    def pid(self) -> int | None:
        """The sandbox process' id (for tests and logs)."""
        return self._process.pid if self._process is not None else None

    # -------------------------------------------------------------------------------------------- Engine-like API
    def add_listener(self, listener: Callable[[EngineEvent], None]) -> None:
        """Receive an EngineEvent for every stage of every command (called on the thread that called run)."""
        self._listeners.append(listener)

    def cancel(self) -> None:
        """Ask the running program to stop; it is killed if it has not stopped after `cancel_grace_s`."""
        with self._state_lock:
            if not self._running or self._cancel_at is not None:
                return
            self._cancel_at = time.monotonic()
            run_id, control = self._run_id, self._control
        try:
            if control is not None:
                control.sendall(wire.frame(wire.encode({'op': 'cancel', 'run': run_id})))
        except OSError:
            pass  # the process is gone or not listening: run() ends it after the grace period

    def run(self, command: str) -> CommandResult:
        """Run one command in the sandbox process. Never raises for problems of the generated code."""
        with self._run_lock:
            started = time.monotonic()
            if self._closed:
                return self._failure(command, '', started, 'closed',
                                     'the sandbox process was closed: the node is shutting down')
            if self._data is None:
                try:
                    self._restart()
                except RuntimeError as error:
                    return self._failure(command, '', started, 'crashed', str(error))
            with self._state_lock:
                self._run_id += 1
                self._cancel_at = None
                self._running = True
            try:
                return self._run(command, started)
            finally:
                with self._state_lock:
                    self._running = False

    def reset(self) -> None:
        """Start a new session (in the same process, or in a new one if this one does not answer)."""
        with self._run_lock:
            if self._closed:
                return
            try:
                if self._data is not None:
                    self._send({'op': 'reset'})
                    deadline = time.monotonic() + self.start_timeout_s
                    while time.monotonic() < deadline:
                        message = self._receive(0.05)
                        if message is not None and message.get('op') == 'reset_done':
                            return
                        if self._process is not None and self._process.poll() is not None:
                            break
            except (_ProcessLost, wire.WireError):
                pass
            try:
                self._restart()  # a new process is a new session
            except RuntimeError:
                pass  # the next run() tries again and reports it

    def close(self) -> None:
        """End the sandbox process (also while a command runs: that command then fails)."""
        with self._state_lock:
            self._closed = True
        process = self._process
        if process is not None and process.poll() is None:
            try:
                os.killpg(process.pid, signal.SIGKILL)
            except (ProcessLookupError, PermissionError):
                process.kill()
        if self._run_lock.acquire(timeout=self.send_timeout_s + 1.0):
            try:
                self._end_process()
            finally:
                self._run_lock.release()

    # -------------------------------------------------------------------------------------------- running
    def _restart(self) -> None:
        self._end_process()
        self.restarts += 1
        self._start()

    def _run(self, command: str, started: float) -> CommandResult:
        code = ''
        try:
            self._send({'op': 'run', 'command': command, 'run': self._run_id})
            last_heard = last_call_end = time.monotonic()
            deadline = started + self.limits.time_limit_s + self.model_allowance_s
            while True:
                message = self._receive(0.05)
                now = time.monotonic()
                if message is not None:
                    last_heard = now
                    op = message.get('op')
                    if op == 'event':
                        event = _event(message)
                        if event.stage == CODE and event.lmp == self.default_lmp:
                            code = event.code
                        self._emit(event)
                    elif op == 'call':
                        self._send(self._answer(message))
                        last_heard = last_call_end = time.monotonic()  # the robot's time is not a stall
                    elif op == 'result':
                        result = _result(message.get('result'))
                        self._keep_call_times(message.get('api_call_seconds'))
                        return result
                    elif op != 'alive':
                        raise _ProcessLost('protocol')
                # Every pass checks, so a process that floods messages is bounded too.
                if self._process is not None and self._process.poll() is not None:
                    raise _ProcessLost('crashed')
                with self._state_lock:
                    cancel_at = self._cancel_at
                if cancel_at is not None and now - max(cancel_at, last_call_end) > self.cancel_grace_s:
                    raise _ProcessLost('cancelled')
                if now - last_heard > self.stall_limit_s:
                    raise _ProcessLost('stalled')
                if now > deadline:
                    raise _ProcessLost('timeout')
        except _ProcessLost as lost:
            return self._lost(command, code, started, lost.reason)
        except (wire.WireError, ValueError, TypeError, OverflowError):
            return self._lost(command, code, started, 'protocol')

    def _keep_call_times(self, calls: Any) -> None:
        if isinstance(calls, list):
            self.api_call_seconds.extend(float(t) for t in calls[-10_000:]
                                         if isinstance(t, (int, float)) and not isinstance(t, bool))
            del self.api_call_seconds[:-10_000]

    def _answer(self, message: dict[str, Any]) -> bytes:
        """Run one robot API call for the program; the encoded reply carries the value or the error."""
        reply: dict[str, Any] = {'op': 'reply', 'id': message.get('id')}
        name, args, kwargs = message.get('name'), message.get('args'), message.get('kwargs')
        function = self._api.get(name) if isinstance(name, str) else None
        if function is None or not isinstance(args, list) or not isinstance(kwargs, dict):
            reply['error'] = {'type': 'RobotApiError', 'message': f'there is no robot function {str(name)[:100]!r}'}
            return wire.encode(reply)
        try:
            reply['value'] = function(*args, **kwargs)
            return wire.encode(reply)  # a value that cannot travel is an error of the call, not of the channel
        except Exception as error:  # every failure of a robot call goes back to the program that made it
            reply.pop('value', None)
            kind = next((cls.__name__ for cls in type(error).__mro__ if cls.__name__ in wire.API_ERRORS),
                        'RobotApiError')
            reply['error'] = {'type': kind, 'message': str(error)[:2000]}
            return wire.encode(reply)

    def _lost(self, command: str, code: str, started: float, reason: str) -> CommandResult:
        exit_text = self._end_process()  # kill first: a stalled process is not waited for
        exit_code = self._process.returncode if self._process is not None else None
        if reason == 'crashed' and exit_code == wire.MEMORY_EXIT_CODE:
            reason = 'memory'
        what = {
            'crashed': f'the sandbox process running the program died ({exit_text})',
            'memory': 'the program ran out of memory and the sandbox process ended',
            'stalled': f'the program stopped responding (one operation ran for more than {self.stall_limit_s:g} s '
                       f'without a pause), so its sandbox process was killed',
            'cancelled': f'the program did not stop within {self.cancel_grace_s:g} s, so its sandbox process was killed',
            'timeout': 'the command ran past its time limit and model allowance, so its sandbox process was killed',
            'protocol': 'the sandbox process sent a malformed message or stopped reading, and was killed',
        }[reason]
        message = f'{what}; {_SESSION_LOST}'
        if self._closed:
            message = f'{what}; the node is shutting down'
        else:
            try:
                self._restart()
            except RuntimeError as restart_error:
                message += f' (restart failed: {restart_error}; the next command tries again)'
        return self._failure(command, code, started, reason, message)

    def _failure(self, command: str, code: str, started: float, reason: str, message: str) -> CommandResult:
        total = time.monotonic() - started
        result = CommandResult(command=command, command_id=0, success=False, code=code, message=message,
                               error_type=SandboxProcessLost.__name__, stop_reason=reason,
                               timings={'total_s': total, 'model_s': 0.0, 'execute_s': total, 'overhead_s': total})
        self._emit(EngineEvent(0, ERROR, self.default_lmp, code, message))
        return result

    def _emit(self, event: EngineEvent) -> None:
        for listener in self._listeners:
            try:
                listener(event)
            except Exception:  # a listener's failure must not end the run
                pass
