"""The watchdog of a sandboxed run (step 4 of the sandbox): a trace function that checks the time limit, the
cancel event, the call depth and memory growth, and stops the program with a signal it cannot catch."""
from __future__ import annotations

import inspect
import os
import sys
import threading
import time
from contextlib import contextmanager
from typing import Any, Iterator

from cap_lmp.sandbox.limits import SANDBOX_FILE_PREFIX, SandboxLimits


class StopSignal(BaseException):
    """Raised by the tracer inside generated code; BaseException so `except Exception` cannot swallow it."""

    def __init__(self, message: str, reason: str) -> None:
        super().__init__(message)
        self.reason = reason


_RESUMABLE = inspect.CO_GENERATOR | inspect.CO_COROUTINE | inspect.CO_ASYNC_GENERATOR
_PAGE_SIZE = os.sysconf('SC_PAGE_SIZE') if hasattr(os, 'sysconf') else 4096


def resident_bytes() -> int:
    """Resident memory of this process (Linux); 0 where /proc is missing, which disables the memory check."""
    try:
        with open('/proc/self/statm', 'rb') as statm:
            return int(statm.read().split()[1]) * _PAGE_SIZE
    except (OSError, ValueError, IndexError):
        return 0


class Watchdog:
    """Deadline, cancel, depth and memory checks for the sandboxed frames of one run on the calling thread."""

    def __init__(self, limits: SandboxLimits, cancel_event: threading.Event | None,
                 memory_baseline: int | None = None) -> None:
        self.limits = limits
        self.cancel_event = cancel_event or threading.Event()
        self.deadline = time.monotonic() + limits.time_limit_s
        self.depth = 0
        self.memory_baseline = resident_bytes() if memory_baseline is None else memory_baseline
        self.next_memory_check = 0.0
        self.stopped: StopSignal | None = None
        # A call of generated code made by the host within the run (a controller's tick): its deadline in this
        # thread's CPU time.
        self.call_deadline: float | None = None
        self._call_wall_deadline = 0.0
        self._call_text = ''
        self.tracer = self.trace  # one bound method, so `sys.gettrace() is self.tracer` is a cheap identity test

    @contextmanager
    def paused(self) -> Iterator[None]:
        """Time inside this block (waiting for the model) does not count against the wall-clock limit."""
        started = time.monotonic()
        try:
            yield
        finally:
            self.exclude(time.monotonic() - started)

    def exclude(self, seconds: float) -> None:
        """`seconds` (spent waiting for the model) do not count against the wall-clock limit."""
        self.deadline += max(seconds, 0.0)

    def stop(self, message: str, reason: str) -> None:
        """End the run now with `reason` (e.g. the command's model deadline passed): raised, and sticky."""
        self._stop(message, reason)

    @contextmanager
    def suspended(self) -> Iterator[None]:
        """Host work on behalf of the program (generating a nested LMP's code) runs untraced, then tracing resumes.

        Frames already running keep their local tracer, so the program's own frames stay watched.
        """
        sys.settrace(None)
        try:
            yield
        finally:
            sys.settrace(self.tracer)

    @contextmanager
    def call_budget(self, seconds: float, what: str) -> Iterator[None]:
        """The host calls generated code (a controller function, once per tick) that may take at most `seconds` of
        this thread's CPU time (what the code costs, whatever else the machine runs meanwhile; generated code cannot
        sleep or wait): past them the call is stopped (StopSignal, reason 'call_budget'). The stop stays, like any
        stop, unless the host caught it as it left the call and says so with `resume_after_call_stop()`; a stop that
        generated code swallowed thus still ends the run. The run's own time limit and cancel hold inside the call
        too."""
        self.call_deadline = time.thread_time() + max(float(seconds), 0.0)
        # CPU time never runs ahead of wall time: until the wall clock has passed the budget, the CPU clock (a
        # system call) need not be read.
        self._call_wall_deadline = time.monotonic() + max(float(seconds), 0.0)
        self._call_text = f'{what} took longer than its time budget of {seconds * 1000:.3g} ms and was stopped'
        try:
            yield
        finally:
            self.call_deadline = None

    def resume_after_call_stop(self) -> None:
        """The host caught the call budget's stop leaving the call (nothing swallowed it): the run goes on, traced
        again (a stop raised by the trace function switches tracing off)."""
        if self.stopped is not None and self.stopped.reason == 'call_budget':
            self.stopped = None
            sys.settrace(self.tracer)

    def check(self) -> None:
        """Raise the stop signal if the run must end (used by the tracer and between model calls).

        A stop is sticky: CPython swallows an exception raised while a generator is finalized (and removes the
        trace function with it), so every later check raises it again.
        """
        if self.stopped is not None:
            raise StopSignal(str(self.stopped), self.stopped.reason)
        if self.cancel_event.is_set():
            self._stop('the program was cancelled', 'cancelled')
        now = time.monotonic()
        if self.call_deadline is not None and now > self._call_wall_deadline and \
                time.thread_time() > self.call_deadline:
            self._stop(self._call_text, 'call_budget')
        if now > self.deadline:
            self._stop(f'the program ran longer than the time limit of {self.limits.time_limit_s:g} s and was '
                       'stopped', 'timeout')
        if now > self.next_memory_check:
            self.next_memory_check = now + self.limits.memory_check_interval_s
            growth = resident_bytes() - self.memory_baseline
            if growth > self.limits.max_memory_growth_bytes:
                self._stop(f'the program used more than {self.limits.max_memory_growth_bytes // (1 << 20)} MiB of '
                           'memory and was stopped', 'memory')

    def checkpoint(self) -> None:
        """Explicit check from loop bodies and wrapped calls. While the tracer is installed it has just checked
        deadline and cancel at this call's 'call' event; once it was removed (a stop swallowed in a finalizer), no
        trace event comes again and this check raises the stop."""
        if sys.gettrace() is self.tracer and self.stopped is None:
            return
        if self.stopped is None:
            self._stop('the program disabled the time limit and was stopped', 'timeout')
        self.check()

    def _stop(self, message: str, reason: str) -> None:
        self.stopped = StopSignal(message, reason)
        raise StopSignal(message, reason)

    def _check_depth(self) -> None:
        if self.depth > self.limits.max_call_depth:
            self._stop(f'the program nested calls deeper than {self.limits.max_call_depth} levels (runaway '
                       'recursion?) and was stopped', 'recursion')

    def _trace_local(self, frame: Any, event: str, arg: Any) -> Any:
        if event == 'return':
            self.depth -= 1
        elif event == 'line':
            if self.depth > self.limits.max_call_depth:
                self._check_depth()
            self.check()
        return self._trace_local

    def trace(self, frame: Any, event: str, arg: Any) -> Any:
        if event != 'call' or not frame.f_code.co_filename.startswith(SANDBOX_FILE_PREFIX):
            return None
        self.depth += 1
        if not frame.f_code.co_flags & _RESUMABLE:
            # Generator frames are resumed by finalizers too, where a raised stop would be swallowed: their
            # checks happen at their first line event instead.
            if self.depth > self.limits.max_call_depth:
                self._check_depth()
            self.check()
        return self._trace_local
