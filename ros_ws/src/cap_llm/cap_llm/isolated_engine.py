"""An Engine in a process of its own, so that no generated program can take lmp_node down with it.

The in-process sandbox (sandbox.py) stops what Python can see: loops, recursion, known expensive operations. Some
C-level work it cannot interrupt or survive: hashing a 300,000-deep nested tuple overflows the C stack and kills
the interpreter; `str([row] * 1000)` of a million-element row holds the interpreter for hours. IsolatedEngine runs
the session (engine, scope, generated functions, LLM client) in `python -m cap_llm.engine_process` and keeps the
robot here: the program's robot API calls arrive as messages (wire.py: JSON, never pickle) and are answered by the
functions given to the constructor. This side enforces what the sandbox cannot:

- **crash**: the process died (a signal, an exit): the command fails with SandboxProcessLost('crashed');
- **stall**: no message for `stall_limit_s` while the process works (its heartbeat thread cannot run while one C
  call holds the interpreter): the process is killed ('stalled');
- **memory**: the process has an address-space limit (RLIMIT_AS); a MemoryError inside the program is reported
  like any exception, and if the process dies of it the command fails with 'memory';
- **cancel**: cancel() asks the sandbox to stop; if no result comes within `cancel_grace_s`, the process is
  killed ('cancelled').

A lost process means a lost session (variables and generated functions); a new process is started at once, and the
result's message says so. Time spent in robot API calls is the parent's own and never counts as a stall.
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
from multiprocessing.connection import Connection
from typing import Any, Callable, Mapping

from cap_llm import wire
from cap_llm.engine import ERROR, CommandResult, EngineEvent
from cap_llm.errors import SandboxProcessLost
from cap_llm.sandbox import SandboxLimits

# Exception types that reach the program by name (engine_process._API_ERRORS); others go as their nearest base.
_FORWARDED_ERRORS = ('StoppedError', 'RobotApiError', 'ValueError', 'TypeError', 'KeyError', 'IndexError',
                     'RuntimeError')
_MEMORY_EXIT_CODE = 3
_SESSION_LOST = 'the session was lost (earlier variables and generated functions are forgotten) and a new one started'


def _fields(cls: type, values: Mapping[str, Any]) -> dict[str, Any]:
    names = {f.name for f in dataclasses.fields(cls)}
    return {key: value for key, value in values.items() if key in names}


class IsolatedEngine:
    """run / cancel / reset / add_listener / close, like Engine, with the session in a sandbox process."""

    def __init__(self, api: Mapping[str, Callable[..., Any]], client_options: Mapping[str, Any],
                 limits: SandboxLimits | None = None, *, domain: str = 'tabletop', stall_limit_s: float = 10.0,
                 cancel_grace_s: float = 2.0, start_timeout_s: float = 60.0,
                 address_space_extra_bytes: int | None = None) -> None:
        self.limits = limits or SandboxLimits()
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
        self.default_lmp = ''
        self.restarts = 0
        # Robot API round trips as generated code saw them (socket and node included), over recent commands.
        self.api_call_seconds: list[float] = []
        self._listeners: list[Callable[[EngineEvent], None]] = []
        self._run_lock = threading.Lock()
        self._send_lock = threading.Lock()
        self._cancel_at: float | None = None
        self._running = False
        self._closed = False
        self._process: subprocess.Popen | None = None
        self._connection: Connection | None = None  # setup, run, reset, replies; events, calls, results
        self._control: Connection | None = None  # cancel only, so that it never waits behind a reply
        self._start()

    # -------------------------------------------------------------------------------------------- process
    def _start(self) -> None:
        parent_end, child_end = socket.socketpair()
        control_end, child_control_end = socket.socketpair()
        env = dict(os.environ)
        # The same modules as here; one BLAS thread (the program's arrays are small, threads cost memory).
        env['PYTHONPATH'] = os.pathsep.join(path for path in sys.path if path)
        env.setdefault('OPENBLAS_NUM_THREADS', '1')
        env.setdefault('OMP_NUM_THREADS', '1')
        with child_end, child_control_end:
            fds = (child_end.fileno(), child_control_end.fileno())
            self._process = subprocess.Popen([sys.executable, '-m', 'cap_llm.engine_process', *map(str, fds)],
                                             pass_fds=fds, env=env, stdin=subprocess.DEVNULL)
        self._connection = Connection(parent_end.detach())
        self._control = Connection(control_end.detach())
        # One poll object for the life of the connection (Connection.poll builds a selector at every call).
        self._poller = select.poll()
        self._poller.register(self._connection.fileno(), select.POLLIN)
        self._send(self._setup)
        ready = self._wait_for('ready', self.start_timeout_s)
        if ready is None:
            reason = self._describe_exit()
            self._kill()
            raise RuntimeError(f'the sandbox process did not start ({reason}); see its log above')
        self.default_lmp = str(ready.get('default_lmp', ''))

    def _send(self, message: dict[str, Any]) -> None:
        connection = self._connection
        if connection is None:
            return
        with self._send_lock:
            connection.send_bytes(wire.encode(message))

    def _receive(self, timeout_s: float) -> dict[str, Any] | None:
        """The next message, None if nothing came within `timeout_s`; EOFError when the process is gone."""
        assert self._connection is not None
        if not self._poller.poll(timeout_s * 1000):
            return None
        return wire.decode(self._connection.recv_bytes(wire.MAX_MESSAGE_BYTES))

    def _wait_for(self, op: str, timeout_s: float) -> dict[str, Any] | None:
        deadline = time.monotonic() + timeout_s
        try:
            while time.monotonic() < deadline:
                message = self._receive(0.05)
                if message is not None and message.get('op') == op:
                    return message
                if message is None and self._process is not None and self._process.poll() is not None:
                    return None
        except (EOFError, OSError, wire.WireError):
            return None
        return None

    def _kill(self) -> None:
        if self._process is not None and self._process.poll() is None:
            self._process.kill()
        if self._process is not None:
            self._process.wait()
        for connection in (self._connection, self._control):
            if connection is not None:
                connection.close()
        self._connection = self._control = None

    def _describe_exit(self) -> str:
        if self._process is None:
            return 'not started'
        try:
            code = self._process.wait(timeout=1.0)
        except subprocess.TimeoutExpired:
            return 'still running'
        if code < 0:
            return f'killed by {signal.Signals(-code).name}'
        return f'exit code {code}'

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
        if not self._running:
            return
        self._cancel_at = time.monotonic()
        control = self._control
        try:
            if control is not None:
                control.send_bytes(wire.encode({'op': 'cancel'}))
        except OSError:
            pass  # the process is gone: run() reports it

    def run(self, command: str) -> CommandResult:
        """Run one command in the sandbox process. Never raises for problems of the generated code."""
        with self._run_lock:
            if self._closed:
                return CommandResult(command=command, command_id=0, success=False, error_type='SandboxProcessLost',
                                     message='the sandbox process was closed: the node is shutting down')
            if self._connection is None:
                self._restart()
            self._cancel_at = None
            self._running = True
            try:
                return self._run(command)
            finally:
                self._running = False

    def reset(self) -> None:
        """Start a new session (in the same process)."""
        with self._run_lock:
            try:
                self._send({'op': 'reset'})
                if self._wait_for('reset_done', self.start_timeout_s) is not None:
                    return
            except (OSError, wire.WireError):
                pass
            self._restart()  # a process that cannot reset is replaced: a new process is a new session

    def close(self) -> None:
        """End the sandbox process."""
        self._closed = True
        try:
            self._send({'op': 'close'})
        except (OSError, wire.WireError):
            pass
        if self._process is not None:
            try:
                self._process.wait(timeout=2.0)
            except subprocess.TimeoutExpired:
                pass
        self._kill()

    # -------------------------------------------------------------------------------------------- running
    def _restart(self) -> None:
        self._kill()
        self.restarts += 1
        self._start()

    def _run(self, command: str) -> CommandResult:
        started = time.monotonic()
        code = ''
        try:
            self._send({'op': 'run', 'command': command})
            last_heard = time.monotonic()
            while True:
                message = self._receive(0.05)
                now = time.monotonic()
                if message is None:
                    if self._process is not None and self._process.poll() is not None:
                        return self._lost(command, code, started, 'crashed')
                    if self._cancel_at is not None and now - self._cancel_at > self.cancel_grace_s:
                        return self._lost(command, code, started, 'cancelled')
                    if now - last_heard > self.stall_limit_s:
                        return self._lost(command, code, started, 'stalled')
                    continue
                last_heard = now
                op = message.get('op')
                if op == 'event':
                    event = EngineEvent(**_fields(EngineEvent, message))
                    if event.stage == 'code' and event.lmp == self.default_lmp:
                        code = event.code
                    self._emit(event)
                elif op == 'call':
                    self._send(self._answer(message))
                    last_heard = time.monotonic()  # the robot's time is not the program's stall
                elif op == 'result':
                    calls = message.get('api_call_seconds')
                    if isinstance(calls, list):
                        self.api_call_seconds.extend(float(t) for t in calls if isinstance(t, (int, float)))
                        del self.api_call_seconds[:-10_000]
                    return CommandResult(**_fields(CommandResult, message.get('result') or {}))
        except (EOFError, OSError):
            return self._lost(command, code, started, 'crashed')
        except wire.WireError:
            return self._lost(command, code, started, 'protocol')

    def _answer(self, message: dict[str, Any]) -> dict[str, Any]:
        """Run one robot API call for the program; the reply carries the value or the error."""
        reply: dict[str, Any] = {'op': 'reply', 'id': message.get('id')}
        name, args, kwargs = message.get('name'), message.get('args'), message.get('kwargs')
        function = self._api.get(name) if isinstance(name, str) else None
        if function is None or not isinstance(args, list) or not isinstance(kwargs, dict):
            reply['error'] = {'type': 'RobotApiError', 'message': f'there is no robot function {name!r}'}
            return reply
        try:
            reply['value'] = function(*args, **kwargs)
            wire.encode(reply)  # a value that cannot travel is an error of the call, not of the channel
        except Exception as error:  # every failure of a robot call goes back to the program that made it
            reply.pop('value', None)
            kind = next((cls.__name__ for cls in type(error).__mro__ if cls.__name__ in _FORWARDED_ERRORS),
                        'RobotApiError')
            reply['error'] = {'type': kind, 'message': str(error)[:2000]}
        return reply

    def _lost(self, command: str, code: str, started: float, reason: str) -> CommandResult:
        exit_text = self._describe_exit()
        if self._process is not None and self._process.poll() is None:
            self._process.kill()
        exit_code = self._process.wait() if self._process is not None else None
        if reason == 'crashed' and exit_code == _MEMORY_EXIT_CODE:
            reason = 'memory'
        what = {
            'crashed': f'the sandbox process running the program died ({exit_text})',
            'memory': 'the program ran out of memory and the sandbox process ended',
            'stalled': f'the program stopped responding (one operation ran for more than {self.stall_limit_s:g} s '
                       f'without a pause), so its sandbox process was killed',
            'cancelled': f'the program did not stop within {self.cancel_grace_s:g} s, so its sandbox process was killed',
            'protocol': 'the sandbox process sent a malformed message and was killed',
        }[reason]
        message = f'{what}; {_SESSION_LOST}'
        error = SandboxProcessLost(message, reason)
        if self._closed:
            self._kill()
        else:
            try:
                self._restart()
            except RuntimeError as restart_error:
                message += f' (restart failed: {restart_error})'
                self._connection = None
        total = time.monotonic() - started
        result = CommandResult(command=command, command_id=0, success=False, code=code, message=message,
                               error_type=type(error).__name__, stop_reason=reason,
                               timings={'total_s': total, 'model_s': 0.0, 'execute_s': total, 'overhead_s': total})
        self._emit(EngineEvent(0, ERROR, self.default_lmp, code, message))
        return result

    def _emit(self, event: EngineEvent) -> None:
        for listener in self._listeners:
            try:
                listener(event)
            except Exception:  # a listener's failure must not end the run
                pass
