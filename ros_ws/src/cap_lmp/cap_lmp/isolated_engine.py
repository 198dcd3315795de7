"""An Engine in a process of its own, so that no generated program can take lmp_node down with it, and limits the
program cannot reach: they are enforced here, in the node.

The in-process sandbox (sandbox.py) stops what Python can see: loops, recursion, known expensive operations. Some
C-level work it cannot interrupt or survive: hashing a 300,000-deep nested tuple overflows the C stack and kills
the interpreter; `str([row] * 1000)` of a million-element row holds the interpreter for hours; a GEOS call runs
without the interpreter while the process looks alive. IsolatedEngine runs the session (engine, scope, generated
functions) in `python -m cap_lmp.engine_process` and keeps the robot and the model client here: the program's robot
API calls and the engine's model requests arrive as messages (wire.py: JSON, never pickle) and are answered by the
functions and the LLMClient given to the constructor.

The sandbox process is treated as hostile: it may send anything, half a message, or nothing. This side reads
frames from a polled socket (a half-sent frame never blocks), sends with a timeout, checks every field it receives
(model answers too: text, counts and size, wire.MAX_PROGRAM_CHARS), and kills the process (its whole process group)
when:

- **deadline**: the command's clock passed `time_limit_s` + KILL_MARGIN_S (0.5 s) ('timeout'). The clock runs from
  the run message, and again from the program's start (its first 'executing' event), so generation and execution
  each get the time limit; robot API calls count (a call still running at the limit is ended by `on_deadline`,
  which stops the robot; a call after it is not made), the model's time does not (this side answers the model requests,
  so it knows that time exactly, and tells the sandbox process, whose watchdog excludes the same figure). The
  watchdog in the process stops the program at `time_limit_s` with a friendly error and keeps the session; the kill
  bounds everything it cannot see (a program that disabled tracing, one long C call, GEOS). After a robot call that
  ended past the deadline, the process has KILL_MARGIN_S to stop by itself. Heartbeats do not extend it.
- **model deadline**: the model requests of one command together may take `model_time_limit_s`; each is sent with the
  budget left (`time_budget_s`), and if the client has not answered 1 s after that budget, the request fails here
  with a message naming the model deadline (the engine then stops the command: reason 'model_timeout').
- **crash**: the process died (a signal, an exit) ('crashed'; 'memory' when it exited for lack of memory);
- **stall**: no message for `stall_limit_s` while it works (its heartbeat thread cannot run while one C call holds
  the interpreter); time spent in robot API calls and model requests does not count ('stalled');
- **cancel**: cancel() was called and no result came within `cancel_grace_s` of the cancel or of the end of the
  robot call that was running then ('cancelled'); a model request that is waiting is answered at once with an error;
- **protocol**: a malformed, over-long or out-of-turn message, or a send that did not complete within
  `send_timeout_s` ('protocol').

Approval (cap_lmp.approval): with `approval` set, each run asks the sandbox process for a plan-only run, and its
'approve' request (the code and the recorded calls, checked here) is answered by the gate, on a thread of its own
so that a cancel or a dead process does not wait; the time it waits counts neither as the program's nor as the
model's, and is no stall.

The process also has an address-space limit (RLIMIT_AS): a MemoryError inside the program is reported like any
exception, and the engine then drops what the command bound (or resets the session if it still holds too much, and
says so). A lost process means a lost session (variables and generated functions); a new process is started at once
(its start is awaited by the next command), and the result's message says so.

The process has no terminal of the node: stdin and stdout are /dev/null, stderr (its log) a pipe whose lines this
side copies to its own stderr. Unless `jail='off'`, the process enters the kernel jail before its first program
(sandbox/jail.py: only the system calls and files it needs, read-only); `jail` says whether a kernel that cannot
hold the whole jail stops the start ('required') or is logged ('best_effort'). What the jail does not cover (the
same uid; what Landlock cannot express) is listed there; for models you do not trust at all, also run the node in
a container or as a user of its own.
"""
from __future__ import annotations

import dataclasses
import importlib
import os
import select
import signal
import socket
import subprocess
import sys
import threading
import time
from typing import IO, Any, Callable, Mapping, Sequence

from cap_lmp import wire
from cap_lmp.wire import CallableHandle
from cap_lmp.approval import MAX_PLANNED_CALLS, ApprovalGate, planned_call
from cap_lmp.engine import CODE, DONE, ERROR, EXECUTING, GENERATING, CommandResult, EngineEvent, check_program_size
from cap_lmp.errors import CapLLMError, CodeRejected, ExecutionStopped, NotApproved, SandboxProcessLost
from cap_lmp.llm import Completion, CompletionRequest, LLMClient
from cap_lmp.outcome import Outcome, outcome_of
from cap_lmp.safe_text import MAX_MESSAGE_CHARS, wire_text
from cap_lmp.sandbox import SandboxLimits

_SESSION_LOST = 'the session was lost (earlier variables and generated functions are forgotten) and a new one started'
_STAGES = (GENERATING, CODE, EXECUTING, DONE, ERROR)
# How long after time_limit_s the process is killed when no result came: room for the watchdog's own stop and the
# result message (milliseconds), small enough that the time limit holds within a second whatever the program does.
KILL_MARGIN_S = 0.5
# How long a cancelled program may take to stop by itself before its process is killed: a Python loop stops within
# milliseconds; what is still running after this is one C call that nothing else can end. Short enough that every
# stop ends the program within a second (benchmarks/stop_latency.py), at the price of the session when it kills.
CANCEL_GRACE_S = 0.7
_MODEL_GRACE_S = 1.0  # a model client that overruns its time budget by this much is no longer waited for
# Environment the sandbox process keeps: what Python needs; nothing of ROS, and no model credentials (the model is
# asked from here).
_KEPT_ENVIRONMENT = ('PATH', 'HOME', 'LANG', 'LC_ALL', 'TMPDIR')


def _unpin(pid: int) -> None:
    """Let the sandbox process run on every CPU. A graph pinned to one CPU (cap_bringup.cpu_affinity, as benchmark
    jobs are) passes the pin on to its children, and the session's interpreter, which has a lock of its own and gains
    nothing from that CPU, would then compete for it with the graph's physics loop and executor threads."""
    if not hasattr(os, 'sched_setaffinity'):
        return
    try:
        os.sched_setaffinity(pid, range(os.cpu_count() or 1))
    except OSError:  # CPUs this process may not use (a cgroup's cpuset), or the process is gone: keep what it has
        pass


def _forward_log(pipe: IO[bytes]) -> threading.Thread:
    """Copy the sandbox process' log (its stderr, a pipe) to this process' stderr as it comes, on a thread that ends
    with the pipe. The process gets no terminal of the node: nothing there for it to read, resize or reconfigure."""

    def copy() -> None:
        try:
            while chunk := os.read(pipe.fileno(), 1 << 16):
                try:
                    while chunk:
                        chunk = chunk[os.write(2, chunk):]
                except OSError:  # our stderr is closed or would block: this part is lost, the process goes on
                    pass
        except OSError:
            pass
        finally:
            pipe.close()

    thread = threading.Thread(target=copy, name='sandbox_log', daemon=True)
    thread.start()
    return thread


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
                       wire.MAX_CODE_CHARS), _text(message.get('message', ''), MAX_MESSAGE_CHARS))


def _count(value: Any) -> int:
    return min(max(value, 0), 10 ** 9) if isinstance(value, int) and not isinstance(value, bool) else 0


def _model_request(fields: Any) -> CompletionRequest:
    """The CompletionRequest in a 'complete' message, every field checked (ValueError if one is wrong)."""
    if not isinstance(fields, dict):
        raise ValueError('not an object')
    texts = {name: fields.get(name, '') for name in ('lmp', 'prompt', 'query', 'context')}
    if not all(isinstance(text, str) and len(text) <= wire.MAX_PROMPT_CHARS for text in texts.values()):
        raise ValueError('a text field is missing or too long')
    stop = fields.get('stop', [])
    if not isinstance(stop, list) or len(stop) > 16 or not all(isinstance(t, str) and len(t) <= 200 for t in stop):
        raise ValueError('malformed stop sequences')
    max_tokens, temperature = fields.get('max_tokens', 512), fields.get('temperature', 0.0)
    if not isinstance(max_tokens, int) or isinstance(max_tokens, bool) or not 0 < max_tokens <= 1_000_000:
        raise ValueError('malformed max_tokens')
    if not isinstance(temperature, (int, float)) or isinstance(temperature, bool) or not 0 <= temperature <= 2:
        raise ValueError('malformed temperature')
    seed = fields.get('seed')
    if seed is not None and (not isinstance(seed, int) or isinstance(seed, bool) or not 0 <= seed < 2 ** 31):
        raise ValueError('malformed seed')
    budget = fields.get('time_budget_s')
    if budget is not None and (not isinstance(budget, (int, float)) or isinstance(budget, bool) or budget != budget):
        raise ValueError('malformed time budget')
    return CompletionRequest(lmp=texts['lmp'][:200], prompt=texts['prompt'], query=texts['query'],
                             context=texts['context'], stop=tuple(stop), max_tokens=max_tokens,
                             temperature=float(temperature), seed=seed, time_budget_s=budget)


class _Clock:
    """The parent's clocks of one command: model time, and the program's time (the model's excluded)."""

    def __init__(self) -> None:
        self.started = self.clock_started = self.last_call_end = time.monotonic()
        self.model_s = 0.0  # of the whole command
        self.model_in_clock_s = 0.0  # since clock_started
        self.paused_in_clock_s = 0.0  # waiting for approval, since clock_started
        self.executing = False

    def start_execution(self, now: float) -> None:
        if not self.executing:  # once per command: a process cannot restart its clock by repeating the event
            self.executing = True
            self.clock_started, self.model_in_clock_s, self.paused_in_clock_s = now, 0.0, 0.0

    def add_model_time(self, seconds: float) -> None:
        self.model_s += seconds
        self.model_in_clock_s += seconds

    def add_paused_time(self, seconds: float) -> None:
        self.paused_in_clock_s += seconds

    def program_s(self, now: float) -> float:
        return now - self.clock_started - self.model_in_clock_s - self.paused_in_clock_s


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
    try:
        fields['outcome'] = Outcome(values.get('outcome'))
    except ValueError:
        raise _ProcessLost('protocol') from None
    if fields['success'] != (fields['outcome'] is Outcome.DONE):
        raise _ProcessLost('protocol')
    source = values.get('error_source')
    fields['error_source'] = _text(source, 1000) if source is not None else None
    timings, functions = values.get('timings'), values.get('generated_functions')
    if not isinstance(timings, dict) or not isinstance(functions, list):
        raise _ProcessLost('protocol')
    fields['timings'] = {str(k): float(v) for k, v in list(timings.items())[:20]
                         if isinstance(v, (int, float)) and not isinstance(v, bool)}
    fields['generated_functions'] = [_text(name, 200) for name in functions[:100]]
    return CommandResult(**fields)


class InvokeError(Exception):
    """A call of the program's function through a handle failed; `kind` names why (the function's exception type,
    'ControllerOverrun' past its budget or without an answer in time, 'NotRunning', 'SandboxProcessLost')."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


def _imported(value: Any) -> Any:
    """A robot call's argument as the robot function gets it: a function's handle becomes a CallableHandle."""
    if isinstance(value, dict) and set(value) == {wire.CALLABLE_KEY, 'name'} and \
            isinstance(value[wire.CALLABLE_KEY], int) and isinstance(value['name'], str):
        return CallableHandle(value[wire.CALLABLE_KEY], value['name'][:200])
    return value


# required: the process does not start without the whole jail; best_effort: what the kernel offers, the rest
# reported in the log; off: no jail (a kernel or container where it gets in the way).
JAIL_MODES = ('required', 'best_effort', 'off')


def builder_reference(build_engine: Callable[..., Any]) -> str:
    """'module:name' of a module-level function, which the sandbox process imports and calls; ValueError for
    anything else (a lambda, a nested function, a bound method cannot be found by name there)."""
    module, name = getattr(build_engine, '__module__', None), getattr(build_engine, '__qualname__', '')
    try:  # __main__ is another module in the sandbox process
        found = (getattr(importlib.import_module(module), name)
                 if module and module != '__main__' and name.isidentifier() else None)
    except (ImportError, AttributeError):
        found = None
    if found is not build_engine:
        raise ValueError(f'build_engine must be a function defined at the top level of a module (got {build_engine!r})')
    return f'{module}:{name}'


class IsolatedEngine:
    """run / cancel / reset / add_listener / close, like Engine, with the session in a sandbox process.

    `build_engine(api, client, limits, **engine_options)` builds the session's Engine in the sandbox process (a
    module-level function: it travels by its module and name); `engine_options` must be JSON values, and
    `model_time_limit_s` is passed to it as well. The robot functions named in `function_arguments` may be passed
    functions of the program: they receive a CallableHandle and may call it with invoke() while they run.
    """

    def __init__(self, build_engine: Callable[..., Any], api: Mapping[str, Callable[..., Any]], client: LLMClient,
                 limits: SandboxLimits | None = None, *, engine_options: Mapping[str, Any] | None = None,
                 stall_limit_s: float = 10.0,
                 cancel_grace_s: float = CANCEL_GRACE_S, start_timeout_s: float = 60.0, send_timeout_s: float = 5.0,
                 model_time_limit_s: float = 120.0, address_space_extra_bytes: int | None = None,
                 jail: str = 'required', child_command: Sequence[str] | None = None,
                 function_arguments: Sequence[str] = (), on_deadline: Callable[[], None] | None = None) -> None:
        if jail not in JAIL_MODES:
            raise ValueError(f'jail must be one of {", ".join(JAIL_MODES)}, not {jail!r}')
        self.limits = limits or SandboxLimits()
        # The sandbox process' command line; the socket fds are appended. Tests put a misbehaving process here.
        self._child_command = list(child_command or [sys.executable, '-m', 'cap_lmp.engine_process'])
        self._api = dict(api)
        self._client = client
        self.model_time_limit_s = model_time_limit_s
        self._setup = {
            'op': 'setup', 'api': sorted(self._api), 'build_engine': builder_reference(build_engine),
            'engine_options': {**(engine_options or {}), 'model_time_limit_s': model_time_limit_s},
            'jail': jail,
            # Robot functions that take a function of the program (as a CallableHandle, see invoke()).
            'function_arguments': sorted(set(function_arguments) & set(self._api)),
            'limits': dataclasses.asdict(self.limits),
            # Room for the program's own data (the sandbox's limit) plus the allocator's and libraries' slack.
            'address_space_extra_bytes': (address_space_extra_bytes if address_space_extra_bytes is not None
                                          else self.limits.max_memory_growth_bytes + (1 << 30)),
        }
        self.stall_limit_s = stall_limit_s
        self.cancel_grace_s = cancel_grace_s
        self.start_timeout_s = start_timeout_s
        self.send_timeout_s = send_timeout_s
        self.default_lmp = ''
        self.restarts = 0
        self.approval: ApprovalGate | None = None  # set: each command is planned and waits for it (approval.py)
        self.rehearse = False  # with approval: the plan run makes its acting calls (on a twin, cap_lmp.rehearsal)
        # Called (on a timer's thread) when the program's time limit passes while a robot call of it runs: it stops
        # the robot, which ends the call, so that the time limit bounds motions too.
        self.on_deadline = on_deadline
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
        self._log_copier: threading.Thread | None = None  # copies the process' stderr to ours
        self._data: socket.socket | None = None  # setup, run, reset, replies; events, calls, results
        self._control: socket.socket | None = None  # cancel only, so that it never waits behind a reply
        self._frames = wire.FrameBuffer(wire.MAX_RESULT_BYTES)
        self._poller: select.poll | None = None
        self._ready = False  # the process answered the setup
        self._clock = _Clock()  # of the command running (or the last one)
        # Calls of the program's functions (invoke) from other threads, while a robot call of it is out.
        self._invoke_lock = threading.Lock()
        self._call_open = False  # a robot call of the program is being answered: invoke may use the socket
        self._invoke_ids = 0
        self._start()

    # -------------------------------------------------------------------------------------------- process
    def _start(self) -> None:
        self._spawn()
        self._await_ready()

    def _spawn(self) -> None:
        """Start the process and send its setup; _await_ready() waits for it (the next command does, after a kill)."""
        data, child_data = socket.socketpair()
        control, child_control = socket.socketpair()
        env = {name: os.environ[name] for name in _KEPT_ENVIRONMENT if name in os.environ}
        # The same modules as here; one BLAS thread (the program's arrays are small, threads cost memory).
        env.update({'PYTHONPATH': os.pathsep.join(path for path in sys.path if path), 'OPENBLAS_NUM_THREADS': '1',
                    'OMP_NUM_THREADS': '1', 'PYTHONDONTWRITEBYTECODE': '1'})
        with child_data, child_control:
            fds = (child_data.fileno(), child_control.fileno())
            # A session of its own: a kill reaches whatever the process may have forked. No terminal: stdin and
            # stdout on /dev/null, its log on a pipe copied to ours.
            self._process = subprocess.Popen([*self._child_command, *map(str, fds)], pass_fds=fds, env=env,
                                             stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                             stderr=subprocess.PIPE, start_new_session=True)
        _unpin(self._process.pid)  # before it has started the threads that would inherit the pin
        self._log_copier = _forward_log(self._process.stderr)
        data.settimeout(self.send_timeout_s)  # bounds sends; receives happen only after poll says data is there
        control.settimeout(self.send_timeout_s)
        self._data, self._control = data, control
        self._frames = wire.FrameBuffer(wire.MAX_RESULT_BYTES)
        self._poller = select.poll()
        self._poller.register(data.fileno(), select.POLLIN)
        self._ready = False
        self._spawned_at = time.monotonic()
        try:
            self._send({**self._setup})
        except _ProcessLost:
            reason = self._end_process()
            raise RuntimeError(f'the sandbox process did not start ({reason}); see its log above') from None

    def _await_ready(self) -> None:
        if self._process is None:
            raise RuntimeError('the sandbox process did not start (not started)')
        try:
            deadline = self._spawned_at + self.start_timeout_s
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
        self._ready = True

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
            if self._log_copier is not None:  # its last lines (why it ended) before anyone reports the end
                self._log_copier.join(timeout=0.1)
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

    def run(self, command: str, lmp: str | None = None, context: str | None = None) -> CommandResult:
        """Run one command in the sandbox process (with the session's default LMP, or `lmp`; `context` instead of
        the LMP's own context line). Never raises for problems of the generated code; an LMP the session does not
        have is a failed result."""
        with self._run_lock:
            started = time.monotonic()
            if self._closed:
                return self._failure(command, '', started, 'closed',
                                     'the sandbox process was closed: the node is shutting down')
            try:
                if self._data is None:
                    self._restart()
                elif not self._ready:
                    self._await_ready()  # the process started after the last one was killed
            except RuntimeError as error:
                return self._failure(command, '', started, 'crashed', str(error))
            with self._state_lock:
                self._run_id += 1
                self._cancel_at = None
                self._running = True
            try:
                return self._run(command, started, lmp, context)
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
                    if not self._ready:
                        self._await_ready()
                    self._send({'op': 'reset'})
                    deadline = time.monotonic() + self.start_timeout_s
                    while time.monotonic() < deadline:
                        message = self._receive(0.05)
                        if message is not None and message.get('op') == 'reset_done':
                            return
                        if self._process is not None and self._process.poll() is not None:
                            break
            except (_ProcessLost, wire.WireError, RuntimeError):
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

    def _run(self, command: str, started: float, lmp: str | None = None,
             context: str | None = None) -> CommandResult:
        code = ''
        clock = self._clock = _Clock()
        limit_s = self.limits.time_limit_s + KILL_MARGIN_S
        run_lmp = lmp or self.default_lmp
        try:
            self._send({'op': 'run', 'command': command, 'run': self._run_id, 'lmp': lmp, 'context': context,
                        'approval': self.approval is not None, 'rehearse': self.rehearse})
            last_heard = clock.started
            while True:
                message = self._receive(0.05)
                now = time.monotonic()
                if message is not None:
                    last_heard = now
                    op = message.get('op')
                    if op == 'event':
                        event = _event(message)
                        if event.lmp == run_lmp:
                            if event.stage == CODE:
                                code = event.code
                            elif event.stage == EXECUTING:
                                clock.start_execution(now)
                        self._emit(event)
                    elif op == 'call':
                        self._send(self._answer(message, clock))
                        last_heard = clock.last_call_end = time.monotonic()  # the robot's time is not a stall
                    elif op == 'complete':
                        self._send(self._complete(message, clock))
                        last_heard = clock.last_call_end = time.monotonic()  # nor the model's
                    elif op == 'approve':
                        self._send(self._approve(message, clock))
                        last_heard = clock.last_call_end = time.monotonic()  # nor a person's
                    elif op == 'result':
                        result = _result(message.get('result'))
                        self._keep_call_times(message.get('api_call_seconds'))
                        self._time(result, clock)
                        return result
                    elif op == 'invoke_result':
                        pass  # the late answer of a call that invoke() stopped waiting for
                    elif op != 'alive':
                        raise _ProcessLost('protocol')
                # Every pass checks, so a process that floods messages is bounded too.
                if self._process is not None and self._process.poll() is not None:
                    raise _ProcessLost('crashed')
                with self._state_lock:
                    cancel_at = self._cancel_at
                if cancel_at is not None and now - max(cancel_at, clock.last_call_end) > self.cancel_grace_s:
                    raise _ProcessLost('cancelled')
                if now - last_heard > self.stall_limit_s:
                    raise _ProcessLost('stalled')
                # A heartbeat is not progress: only the clock counts, with a moment after a robot call that ended
                # late for the watchdog's own stop.
                if clock.program_s(now) > limit_s and now - clock.last_call_end > KILL_MARGIN_S:
                    raise _ProcessLost('timeout')
        except _ProcessLost as lost:
            return self._lost(command, code, started, lost.reason)
        except (wire.WireError, ValueError, TypeError, OverflowError):
            return self._lost(command, code, started, 'protocol')

    def _time(self, result: CommandResult, clock: _Clock) -> None:
        """The result's timings as this side measured them: the model's time exactly, the total."""
        total = time.monotonic() - clock.started
        result.timings.update({'total_s': total, 'model_s': clock.model_s, 'overhead_s': total - clock.model_s})

    # -------------------------------------------------------------------------------------------- the model
    def _complete(self, message: dict[str, Any], clock: _Clock) -> bytes:
        """Answer one model request of the program with the client; the encoded reply holds the answer or the
        error. The request gets the model time left of the command; the answer is checked like any message."""
        reply: dict[str, Any] = {'op': 'reply', 'id': message.get('id')}
        try:
            request = _model_request(message.get('request'))
        except ValueError as error:
            return self._model_error(reply, 'LLMError', f'malformed model request ({error})')
        remaining = self.model_time_limit_s - clock.model_s
        if remaining <= 0:
            return self._model_error(reply, 'LLMError', self._model_deadline_text(clock))
        budget = remaining if request.time_budget_s is None else max(min(request.time_budget_s, remaining), 0.0)
        request = dataclasses.replace(request, time_budget_s=budget)
        started = time.monotonic()
        elapsed = 0.0
        try:
            outcome = self._ask_model(request, started + budget + _MODEL_GRACE_S)
        finally:
            elapsed = time.monotonic() - started
            clock.add_model_time(elapsed)
        if isinstance(outcome, str):
            return self._model_error(reply, 'LLMError', outcome if outcome else self._model_deadline_text(clock))
        if isinstance(outcome, BaseException):
            return self._model_error(reply, 'CodeRejected' if isinstance(outcome, CodeRejected) else 'LLMError',
                                     outcome)
        completion = outcome
        if not isinstance(completion, Completion) or not isinstance(completion.text, str):
            return self._model_error(reply, 'LLMError', 'the model client returned no text')
        try:
            check_program_size(completion.text)
        except CodeRejected as error:
            return self._model_error(reply, 'CodeRejected', str(error))
        reply['completion'] = {
            'text': completion.text, 'model': wire_text(completion.model, 200) if isinstance(completion.model, str)
            else '', 'source': wire_text(completion.source, 200) if isinstance(completion.source, str) else '',
            'prompt_tokens': _count(completion.prompt_tokens),
            'completion_tokens': _count(completion.completion_tokens),
            'latency_s': elapsed,  # the model's time as measured here: the sandbox process' watchdog excludes it
        }
        return wire.encode(reply)

    def _ask_model(self, request: CompletionRequest, give_up_at: float) -> Any:
        """The client's Completion or exception; '' past `give_up_at`, a message if cancelled. The client runs on a
        thread of its own so that a cancel, a dead process or a client that overruns its budget never waits."""
        box: dict[str, Any] = {}
        done = threading.Event()

        def ask() -> None:
            try:
                box['outcome'] = self._client.complete(request)
            except BaseException as error:  # reported to the program as the model's failure
                box['outcome'] = error
            finally:
                done.set()

        threading.Thread(target=ask, name='model_request', daemon=True).start()
        return self._await(done, box, give_up_at, 'the command was cancelled while it waited for the model')

    def _await(self, done: threading.Event, box: dict[str, Any], give_up_at: float, cancelled: str) -> Any:
        """box['outcome'] once `done` is set; `cancelled` on a cancel, '' past `give_up_at`; _ProcessLost when the
        process died meanwhile."""
        while not done.wait(0.05):
            if self._process is None or self._process.poll() is not None:
                raise _ProcessLost('crashed')
            with self._state_lock:
                if self._cancel_at is not None:
                    return cancelled
            if time.monotonic() > give_up_at:
                return ''
        return box['outcome']

    # -------------------------------------------------------------------------------------------- approval
    def _approve(self, message: dict[str, Any], clock: _Clock) -> bytes:
        """Ask the approval gate about the program's code and plan; the encoded reply says go, or why not."""
        reply: dict[str, Any] = {'op': 'reply', 'id': message.get('id')}
        code, values = message.get('code'), message.get('plan')
        if not isinstance(code, str) or not isinstance(values, list) or len(values) > MAX_PLANNED_CALLS:
            raise _ProcessLost('protocol')
        try:
            plan = [planned_call(value) for value in values]
        except ValueError:
            raise _ProcessLost('protocol') from None
        gate = self.approval
        if gate is None:  # switched off after the run began: nobody is asked, the program may run
            return wire.encode(reply)
        box: dict[str, Any] = {}
        done = threading.Event()

        def ask() -> None:
            try:
                gate(code[:wire.MAX_CODE_CHARS], plan)
                box['outcome'] = None
            except BaseException as error:  # the gate's answer: rejected, timed out, cancelled
                box['outcome'] = error
            finally:
                done.set()

        started = time.monotonic()
        threading.Thread(target=ask, name='approval', daemon=True).start()
        try:
            outcome = self._await(done, box, float('inf'), 'cancelled')
        finally:
            clock.add_paused_time(time.monotonic() - started)
        if outcome is None:
            return wire.encode(reply)
        if outcome == 'cancelled' or isinstance(outcome, ExecutionStopped):
            reply['error'] = {'type': 'ExecutionStopped', 'message': 'the program was cancelled'}
        elif isinstance(outcome, NotApproved):
            reply['error'] = {'type': 'NotApproved', 'message': wire_text(str(outcome), 2000),
                              'reason': outcome.reason}
        else:
            reply['error'] = {'type': 'NotApproved', 'reason': 'rejected',
                              'message': wire_text(f'the approval failed: {type(outcome).__name__}: {outcome}', 2000)}
        return wire.encode(reply)

    def _model_deadline_text(self, clock: _Clock) -> str:
        return (f'the model deadline of {self.model_time_limit_s:g} s for one command passed (the model took '
                f'{clock.model_s:.1f} s)')

    @staticmethod
    def _model_error(reply: dict[str, Any], kind: str, text: Any) -> bytes:
        if isinstance(text, BaseException):  # the client's own errors speak for themselves; others get their type
            try:
                words = str(text)
            except Exception:
                words = ''
            known = isinstance(text, (CapLLMError,))
            text = words if known and words else f'{type(text).__name__}: {words}' if words else type(text).__name__
        reply['error'] = {'type': kind, 'message': wire_text(text, 2000)}
        return wire.encode(reply)

    def _keep_call_times(self, calls: Any) -> None:
        if isinstance(calls, list):
            self.api_call_seconds.extend(float(t) for t in calls[-10_000:]
                                         if isinstance(t, (int, float)) and not isinstance(t, bool))
            del self.api_call_seconds[:-10_000]

    def _answer(self, message: dict[str, Any], clock: _Clock) -> bytes:
        """Run one robot API call for the program; the encoded reply carries the value or the error. A call still
        running when the program's time limit passes is ended then (on_deadline stops the robot)."""
        reply: dict[str, Any] = {'op': 'reply', 'id': message.get('id')}
        name, args, kwargs = message.get('name'), message.get('args'), message.get('kwargs')
        function = self._api.get(name) if isinstance(name, str) else None
        if function is None or not isinstance(args, list) or not isinstance(kwargs, dict):
            reply['error'] = {'type': 'RobotApiError', 'message': f'there is no robot function {str(name)[:100]!r}'}
            return wire.encode(reply)
        left_s = self.limits.time_limit_s - clock.program_s(time.monotonic())
        if left_s <= 0:
            reply['error'] = {'type': 'StoppedError', 'message': f'the time limit of {self.limits.time_limit_s:g} s '
                              'passed; the robot was not called', 'stop': 'timeout'}
            return wire.encode(reply)
        args = [_imported(value) for value in args]
        kwargs = {key: _imported(value) for key, value in kwargs.items()}
        fired = threading.Event()
        deadline = (threading.Timer(left_s, self._deadline_passed, (fired,)) if self.on_deadline is not None
                    else None)
        with self._invoke_lock:
            self._call_open = True
        try:
            try:
                if deadline is not None:
                    deadline.start()
                reply['value'] = function(*args, **kwargs)
            finally:
                if deadline is not None:
                    deadline.cancel()
                with self._invoke_lock:  # waits for a call of the program's function in flight
                    self._call_open = False
            return wire.encode(reply)  # a value that cannot travel is an error of the call, not of the channel
        except Exception as error:  # every failure of a robot call goes back to the program that made it
            reply.pop('value', None)
            kind = next((cls.__name__ for cls in type(error).__mro__ if cls.__name__ in wire.API_ERRORS),
                        'RobotApiError')
            text = str(error)[:2000]
            reply['error'] = {'type': kind, 'message': text}
            if fired.is_set():
                reply['error'] = {'type': 'StoppedError', 'stop': 'timeout',
                                  'message': f'the time limit of {self.limits.time_limit_s:g} s passed during '
                                             f'{name}(), so the robot was stopped ({text})'}
            return wire.encode(reply)

    def _deadline_passed(self, fired: threading.Event) -> None:
        """The program's time limit passed during a robot call: stop the robot, so that the call ends now."""
        fired.set()
        on_deadline = self.on_deadline
        if on_deadline is not None:
            try:
                on_deadline()
            except Exception:  # the stop's own failure must not end the timer's thread loudly; the kill follows
                pass

    # -------------------------------------------------------------------------------------------- invoke
    def invoke(self, handle: CallableHandle | int, args: Sequence[Any], budget_s: float,
               timeout_s: float) -> tuple[Any, float]:
        """Call a function the running program passed to the robot call being answered now (from another thread
        than the one answering it): (its value, its own time in the sandbox process [s]).

        The function runs in the sandbox process under the program's watchdog with `budget_s` as its deadline;
        this side waits `timeout_s` at most. Raises InvokeError (`kind` says why) for the function's exception,
        a stop past the budget, no answer in time, or no robot call of the program being answered.
        """
        handle_id = handle.id if isinstance(handle, CallableHandle) else int(handle)
        deadline = time.monotonic() + timeout_s
        if not self._invoke_lock.acquire(timeout=max(timeout_s, 0.0)):
            raise InvokeError('ControllerOverrun', f'the previous call did not end within {timeout_s:g} s')
        try:
            if not self._call_open or self._data is None:
                raise InvokeError('NotRunning', 'no program is waiting for its function to be called')
            self._invoke_ids += 1
            invoke_id = self._invoke_ids
            try:
                self._send({'op': 'invoke', 'id': invoke_id, 'handle': handle_id, 'args': list(args),
                            'budget_s': float(budget_s)})
                while True:
                    message = self._receive(max(0.0, min(0.05, deadline - time.monotonic())))
                    if message is not None:
                        op = message.get('op')
                        if op == 'invoke_result' and message.get('id') == invoke_id:
                            return self._invoke_result(message)
                        if op in ('call', 'complete'):  # refused by the process itself; a hostile one gets this
                            self._send({'op': 'reply', 'id': message.get('id'), 'error': {
                                'type': 'RobotApiError', 'message': 'not from inside a controller function'}})
                        elif op not in ('alive', 'invoke_result'):
                            raise _ProcessLost('protocol')
                    if self._process is None or self._process.poll() is not None:
                        raise _ProcessLost('crashed')
                    if time.monotonic() > deadline:
                        raise InvokeError('ControllerOverrun', f'the function did not answer within {timeout_s:g} s')
            except (_ProcessLost, wire.WireError, ValueError, TypeError) as error:
                reason = error.reason if isinstance(error, _ProcessLost) else 'protocol'
                raise InvokeError('SandboxProcessLost', f'the sandbox process failed during the call ({reason})') \
                    from None
        finally:
            self._invoke_lock.release()

    @staticmethod
    def _invoke_result(message: dict[str, Any]) -> tuple[Any, float]:
        seconds = message.get('seconds')
        seconds = float(seconds) if isinstance(seconds, (int, float)) and not isinstance(seconds, bool) else 0.0
        error = message.get('error')
        if error is not None:
            if not isinstance(error, dict):
                raise _ProcessLost('protocol')
            raise InvokeError(_text(error.get('type', 'RobotApiError'), 100),
                              wire_text(_text(error.get('message', ''), 2000), 2000))
        return message.get('value'), seconds

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
            'cancelled': f'the program did not stop within {self.cancel_grace_s:g} s, so its sandbox process was '
                         'killed',
            'timeout': f'the program ran past its time limit of {self.limits.time_limit_s:g} s and did not stop, so '
                       'its sandbox process was killed',
            'protocol': 'the sandbox process sent a malformed message or stopped reading, and was killed',
        }[reason]
        message = f'{what}; {_SESSION_LOST}'
        if self._closed:
            message = f'{what}; the node is shutting down'
        else:
            try:
                self.restarts += 1
                self._spawn()  # the next command waits for it to be ready: this result is not delayed by the start
            except RuntimeError as restart_error:
                message += f' (restart failed: {restart_error}; the next command tries again)'
        return self._failure(command, code, started, reason, message)

    def _failure(self, command: str, code: str, started: float, reason: str, message: str) -> CommandResult:
        total = time.monotonic() - started
        model = self._clock.model_s if self._clock.started >= started else 0.0
        result = CommandResult(command=command, command_id=0, success=False, code=code, message=message,
                               outcome=outcome_of(SandboxProcessLost(message, reason)),
                               error_type=SandboxProcessLost.__name__, stop_reason=reason,
                               timings={'total_s': total, 'model_s': model, 'execute_s': total - model,
                                        'overhead_s': total - model})
        self._emit(EngineEvent(0, ERROR, self.default_lmp, code, message))
        return result

    def _emit(self, event: EngineEvent) -> None:
        for listener in self._listeners:
            try:
                listener(event)
            except Exception:  # a listener's failure must not end the run
                pass
