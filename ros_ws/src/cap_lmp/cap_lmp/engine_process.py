"""The sandbox process: one session's Engine, scope and generated code, apart from lmp_node.

Started by IsolatedEngine (isolated_engine.py) as `python -m cap_lmp.engine_process <data fd> <control fd>` with
one end of two socket pairs. On the data socket, the first message is the setup (the engine builder's module and
name, robot API names, sandbox limits, engine options such as the model deadline, address-space limit); then the
parent sends run / reset / close and the replies to the robot API calls and model requests this process makes, and
this process sends engine events, API calls ('call'), model requests ('complete', the CompletionRequest's fields),
the result of each run, and a heartbeat every HEARTBEAT_S while it can run Python. The main thread reads the data
socket itself, also for the reply to a request (a hand-off between threads would cost about a millisecond per
call). The control socket carries only cancel; a thread of its own watches it, and its closing means the parent is
gone.

Functions as arguments: a robot API function named in the setup's `function_arguments` may be passed a function of
the program (`run_controller(f, ...)`); it travels as a handle ({'$callable': id, 'name': ...}), and while that
call waits for its reply the parent may ask for the function to be called ('invoke': handle, arguments, time
budget), answered with 'invoke_result' (value or error, and the call's own time). The call runs on the program's
thread under its watchdog, with the budget as a deadline of its own (Watchdog.call_budget); robot calls and model
requests from inside it are refused. Handles end with the robot call they were passed to.

No rclpy and no model client here: the robot and the model live in the parent, behind the `call` and `complete`
messages, so this process needs no network, and the parent measures the model's time exactly (its reply carries
that time, which the watchdog excludes from the program's time, as the parent's clock does).
"""
from __future__ import annotations

import dataclasses
import gc
import importlib
import itertools
import os
import resource
import sys
import threading
import time
from multiprocessing.connection import Connection
from typing import Any, Callable

from cap_lmp import wire
from cap_lmp.sandbox.jail import enter_jail
from cap_lmp.engine import CommandResult
from cap_lmp.errors import CodeRejected, ExecutionStopped, LLMError, NotApproved, RobotApiError
from cap_lmp.llm import Completion, CompletionRequest
from cap_lmp.wire import API_ERRORS, MAX_CODE_CHARS, MAX_PROMPT_CHARS, MEMORY_EXIT_CODE

HEARTBEAT_S = 0.25


class _Channel:
    """The data socket to the parent: sends from several threads; the main thread receives."""

    def __init__(self, connection: Connection) -> None:
        self._connection = connection
        self._send_lock = threading.Lock()
        self._ids = itertools.count(1)
        self.waiting_for_parent = threading.Event()  # an API call is out: the parent is busy, not us
        self.call_seconds: list[float] = []  # round trips as the program sees them, reported with each result
        self.handles: dict[int, Callable[..., Any]] = {}  # functions passed to the robot call that is out
        self._handle_ids = itertools.count(1)
        self.on_invoke: Callable[[dict[str, Any]], dict[str, Any]] | None = None
        self.invoking = False  # a function passed to a robot call runs for the parent
        # Ends the run (message, reason) when the parent says a call met the program's end: its clock, which
        # counts the robot's time, passed the time limit before this side's watchdog did.
        self.on_stop: Callable[[str, str], None] | None = None

    def send(self, message: dict[str, Any]) -> None:
        data = wire.encode(message)
        with self._send_lock:
            self._connection.send_bytes(data)

    def receive(self) -> dict[str, Any]:
        return wire.decode(self._connection.recv_bytes(wire.MAX_MESSAGE_BYTES))

    def request(self, message: dict[str, Any]) -> dict[str, Any]:
        """Send a request to the parent and wait for its reply (which must answer this request); meanwhile answer
        the parent's 'invoke' messages (calls of the functions this request passed)."""
        if self.invoking:
            raise RobotApiError('a controller function cannot call the robot or ask the model: it gets the state '
                                'from its arguments or the state functions, and returns its output')
        request_id = message['id'] = next(self._ids)
        self.send(message)
        self.waiting_for_parent.set()
        try:
            reply = self.receive()
            while reply.get('op') == 'invoke' and self.on_invoke is not None:
                self.send(self.on_invoke(reply))
                reply = self.receive()
        except (EOFError, OSError, wire.WireError):
            os._exit(0)  # the parent is gone (or spoke nonsense): nothing here is worth keeping
        finally:
            self.waiting_for_parent.clear()
        if reply.get('op') != 'reply' or reply.get('id') != request_id:
            raise RobotApiError('the node answered out of turn')
        return reply

    def call(self, name: str, args: tuple, kwargs: dict, functions: bool = False) -> Any:
        """A robot API call; with `functions`, the program's functions among its arguments travel as handles."""
        started = time.perf_counter()
        if functions:
            args = tuple(self._export(value) for value in args)
            kwargs = {key: self._export(value) for key, value in kwargs.items()}
        try:
            reply = self.request({'op': 'call', 'name': name, 'args': list(args), 'kwargs': kwargs})
        except wire.WireError as error:
            raise TypeError(f'{name}: {error}') from None
        finally:
            self.handles.clear()
        self.call_seconds.append(time.perf_counter() - started)
        error = reply.get('error')
        if error:
            message = str(error.get('message', ''))
            if error.get('stop') == 'timeout' and self.on_stop is not None:
                self.on_stop(message, 'timeout')  # raises the run's stop, which the program cannot catch
            raise API_ERRORS.get(str(error.get('type')), RobotApiError)(message)
        return reply.get('value')


    def _export(self, value: Any) -> Any:
        """A function becomes a handle the parent can invoke while this call is out; anything else as it is."""
        if not callable(value) or isinstance(value, type):
            return value
        handle = next(self._handle_ids)
        self.handles[handle] = value
        return {wire.CALLABLE_KEY: handle, 'name': str(getattr(value, '__name__', 'function'))[:200]}


def _invoker(channel: _Channel, engine: Any) -> Callable[[dict[str, Any]], dict[str, Any]]:
    """The answer to the parent's 'invoke': call the handle's function on this (the program's) thread, under the
    run's watchdog with the message's time budget."""
    from cap_lmp.sandbox.watchdog import StopSignal

    def invoke(message: dict[str, Any]) -> dict[str, Any]:
        reply: dict[str, Any] = {'op': 'invoke_result', 'id': message.get('id'), 'seconds': 0.0}
        function = channel.handles.get(message.get('handle'))
        args, budget = message.get('args'), message.get('budget_s')
        watchdog = engine.sandbox.watchdog
        if function is None or not isinstance(args, list) or watchdog is None or \
                not isinstance(budget, (int, float)) or isinstance(budget, bool) or not budget > 0:
            reply['error'] = {'type': 'RobotApiError', 'message': 'no such function of the running program'}
            return reply
        name = str(getattr(function, '__name__', 'the controller'))
        channel.invoking = True
        started = time.thread_time()  # the budget is CPU time too (Watchdog.call_budget)
        try:
            with watchdog.call_budget(float(budget), f'{name}()'):
                reply['value'] = function(*args)
            wire.encode(reply)  # a value that cannot travel is the function's error
        except StopSignal as stop:  # the budget, the run's limit or a cancel: the parent stops the loop
            if stop.reason == 'call_budget':
                watchdog.resume_after_call_stop()  # only this call ends; the program gets the parent's verdict
            reply.pop('value', None)
            reply['error'] = {'type': 'ControllerOverrun' if stop.reason == 'call_budget' else 'ExecutionStopped',
                              'message': str(stop)}
        except wire.WireError as error:
            reply.pop('value', None)
            reply['error'] = {'type': 'TypeError', 'message': f'{name} returned a value that cannot be sent: {error}'}
        except Exception as error:  # the function's own exception, reported with its line
            reply.pop('value', None)
            try:
                text = engine.error_text(error)
            except Exception:
                text = type(error).__name__
            reply['error'] = {'type': type(error).__name__, 'message': text[:2000]}
        finally:
            channel.invoking = False
            reply['seconds'] = time.thread_time() - started
        return reply

    return invoke


class _ParentModel:
    """The LLMClient of this process: every request goes to the parent, which asks the model."""

    def __init__(self, channel: _Channel) -> None:
        self._channel = channel

    def complete(self, request: CompletionRequest) -> Completion:
        if len(request.prompt) > MAX_PROMPT_CHARS:
            raise LLMError(f'the prompt has {len(request.prompt):,} characters, more than the limit of '
                           f'{MAX_PROMPT_CHARS:,} (the session history grows with every command): reset the session')
        fields = dataclasses.asdict(request)
        fields['stop'] = list(request.stop)
        try:
            reply = self._channel.request({'op': 'complete', 'request': fields})
        except wire.WireError as error:
            raise LLMError(f'the model request cannot be sent: {error}') from None
        error = reply.get('error')
        if error:
            kind = CodeRejected if error.get('type') == 'CodeRejected' else LLMError
            raise kind(str(error.get('message', '')))
        value = reply.get('completion')
        return Completion(text=str(value['text']), model=str(value['model']),
                          prompt_tokens=int(value['prompt_tokens']), completion_tokens=int(value['completion_tokens']),
                          latency_s=float(value['latency_s']), source=str(value['source']))


def _approval_gate(channel: _Channel) -> Callable[[str, list], None]:
    """The engine's approval gate here: the parent asks a person (cap_lmp.approval) and answers go or why not."""

    def ask(code: str, plan: list) -> None:
        try:
            reply = channel.request({'op': 'approve', 'code': code[:MAX_CODE_CHARS],
                                     'plan': [call.to_wire() for call in plan]})
        except wire.WireError as error:
            raise NotApproved(f'the plan could not be sent for approval ({error}); nothing ran', 'rejected') from None
        error = reply.get('error')
        if error:
            text = str(error.get('message', ''))
            if error.get('type') == 'ExecutionStopped':
                raise ExecutionStopped(text or 'the program was cancelled', 'cancelled')
            raise NotApproved(text, str(error.get('reason', 'rejected'))[:50])

    return ask


def _run_stopper(engine: Any) -> Callable[[str, str], None]:
    """Stop the run on this (the program's) thread with a reason, as its own watchdog would have."""
    def stop(message: str, reason: str) -> None:
        watchdog = engine.sandbox.watchdog
        if watchdog is not None:
            watchdog.stop(message, reason)
    return stop


def _proxy(channel: _Channel, name: str, functions: bool = False) -> Callable[..., Any]:
    def call_robot(*args: Any, **kwargs: Any) -> Any:
        return channel.call(name, args, kwargs, functions)
    call_robot.__name__ = name
    return call_robot


def _limit_address_space(extra_bytes: int) -> None:
    """Cap virtual memory at what is mapped now plus `extra_bytes`: a runaway allocation fails with MemoryError."""
    if extra_bytes <= 0:
        return
    with open('/proc/self/status', encoding='ascii') as status:
        mapped = next(int(line.split()[1]) * 1024 for line in status if line.startswith('VmSize:'))
    limit = mapped + extra_bytes
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))


def _build_engine(setup: dict[str, Any], channel: _Channel):
    """The session's Engine, from the builder the parent named ('module:function') over proxies of its API."""
    from cap_lmp.sandbox import SandboxLimits

    module, _, name = str(setup['build_engine']).partition(':')
    build_engine = getattr(importlib.import_module(module), name)
    limits = SandboxLimits(**setup.get('limits', {}))
    takes_functions = set(setup.get('function_arguments') or ())
    api = {name: _proxy(channel, name, name in takes_functions) for name in setup['api']}
    return build_engine(api, _ParentModel(channel), limits, **dict(setup.get('engine_options') or {}))


def freeze_setup_heap() -> None:
    """Move every object alive now (modules, the engine, its prompts) out of the garbage collector's reach.

    They live as long as the process, and a full collection walks every tracked object: about 5-7 ms for the
    engine's 35,000, run on whichever thread allocates. Inside a controller's call that was more than its whole
    time budget (5 ms at 100 Hz, counted in the thread's CPU time), so a collection falling into a call stopped
    a correct controller. Frozen, a collection walks only what the programs made since.
    """
    gc.collect()
    gc.freeze()


def serve(connection: Connection, control: Connection) -> None:
    channel = _Channel(connection)
    setup = channel.receive()
    engine = _build_engine(setup, channel)
    freeze_setup_heap()
    channel.on_invoke = _invoker(channel, engine)
    channel.on_stop = _run_stopper(engine)
    _limit_address_space(int(setup.get('address_space_extra_bytes', 0)))
    # The jail comes last of the setup (the engine's modules are loaded, the memory cap is set) and before the
    # threads start: Landlock and the capability drop bind the calling thread and the threads it starts later.
    jail = setup.get('jail', 'required')
    if jail != 'off':
        enter_jail(required=(jail != 'best_effort'))
    stopped = threading.Event()
    busy = threading.Event()  # a request is being handled: the parent is listening for heartbeats
    # A cancel names its run: a late one must not stop the next command, an early one (read before its run
    # message) is applied at the run's first event, after Engine.run has cleared the previous cancel.
    runs = {'current': 0, 'cancelled': 0}

    def forward(event) -> None:
        if runs['cancelled'] == runs['current']:
            engine.cancel()
        fields = dataclasses.asdict(event)
        fields['code'] = fields['code'][:MAX_CODE_CHARS]
        fields['message'] = fields['message'][:MAX_CODE_CHARS]
        channel.send({'op': 'event', **fields})

    engine.add_listener(forward)
    gate = _approval_gate(channel)

    def watch_control() -> None:
        try:
            while True:
                message = wire.decode(control.recv_bytes(1024))
                run_id = message.get('run')
                if message.get('op') == 'cancel' and isinstance(run_id, int) and run_id >= runs['current']:
                    runs['cancelled'] = run_id
                    if run_id == runs['current']:
                        engine.cancel()
        except MemoryError:
            os._exit(MEMORY_EXIT_CODE)
        except BaseException:  # EOF: the parent is gone; anything else: it spoke nonsense
            pass
        stopped.set()
        os._exit(0)

    def beat() -> None:
        try:
            while not stopped.wait(HEARTBEAT_S):
                if busy.is_set() and not channel.waiting_for_parent.is_set():
                    channel.send({'op': 'alive'})
        except MemoryError:
            os._exit(MEMORY_EXIT_CODE)
        except BaseException:  # without heartbeats the parent would call the next long step a stall
            os._exit(4)

    threading.Thread(target=watch_control, name='engine_process_control', daemon=True).start()
    threading.Thread(target=beat, name='engine_process_heartbeat', daemon=True).start()
    channel.send({'op': 'ready', 'default_lmp': engine.default_lmp})
    while True:
        try:
            message = channel.receive()
        except (EOFError, OSError, wire.WireError):
            os._exit(0)
        op = message.get('op')
        busy.set()
        if op == 'run':
            run_id = message.get('run')
            runs['current'] = run_id if isinstance(run_id, int) else 0
            channel.call_seconds.clear()
            lmp, context = message.get('lmp'), message.get('context')
            engine.approval = gate if message.get('approval') is True else None
            engine.rehearse = engine.approval is not None and message.get('rehearse') is True
            command = str(message.get('command', ''))
            if lmp is not None and (not isinstance(lmp, str) or lmp not in engine.lmps):
                outcome = CommandResult(command=command, command_id=0, success=False,
                                        message=f'this session has no LMP named {str(lmp)[:100]!r}',
                                        error_type='ValueError')
            else:
                outcome = engine.run(command, lmp, context if isinstance(context, str) else None)
            result = dataclasses.asdict(outcome)
            result['outcome'] = result['outcome'].value
            result['code'] = result['code'][:MAX_CODE_CHARS]  # the node accepts at most wire.MAX_RESULT_BYTES
            channel.send({'op': 'result', 'result': result, 'api_call_seconds': channel.call_seconds[-10_000:]})
        elif op == 'reset':
            engine.reset()
            channel.send({'op': 'reset_done'})
        elif op == 'close':
            os._exit(0)
        busy.clear()


def main() -> None:
    connection, control = Connection(int(sys.argv[1])), Connection(int(sys.argv[2]))
    # Output of the process goes to the parent's stderr; stdout stays free of stray prints.
    sys.stdout = sys.stderr
    try:
        serve(connection, control)
    except MemoryError:
        os._exit(MEMORY_EXIT_CODE)


if __name__ == '__main__':
    main()
