"""Threads a process depends on: when one dies, it says so in one line and the process ends with a non-zero status.

A node whose worker (or executor) thread died keeps its topics, services and actions, so it looks alive while it
answers nothing. A ThreadWatch wraps the targets of the threads that matter (`guard`), or catches any thread's
uncaught exception (`install_excepthook`, for a process of its own), reports the first death as one line naming
the thread and the error (`failure`, `died`), and runs the callbacks that end the process (`on_death`,
`add_callback`; e.g. wake the main loop, which then exits with FATAL_EXIT_CODE).

Plain Python (no rclpy), so a one-process graph can share one watch between its nodes and its executor threads.
"""
from __future__ import annotations

import sys
import threading
from typing import Any, Callable

from cap_lmp.safe_text import one_line, terminal_text

FATAL_EXIT_CODE = 70  # EX_SOFTWARE of sysexits.h: an internal error, not a bad command line
_ERROR_CHARS = 500


def death_line(thread_name: str, error: BaseException) -> str:
    """One printable line naming the thread and the error."""
    try:
        detail = str(error)
    except Exception:  # an error whose text cannot be built still has a type
        detail = ''
    text = f'thread {thread_name!r} died: {type(error).__name__}' + (f': {detail}' if detail else '')
    return terminal_text(one_line(text, limit=_ERROR_CHARS))


def _print_to_stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


class ThreadWatch:
    """See the module docstring.

    `on_death(line)` runs on the first death (more with `add_callback`); `log(line)` writes the line. With neither
    (an `on_death` is expected to tell the user itself), the line goes to standard error. After `stop()` (the
    process is shutting down) deaths are no longer reported.
    """

    def __init__(self, on_death: Callable[[str], None] | None = None,
                 log: Callable[[str], None] | None = None) -> None:
        self.log = log
        self.failure = ''  # the line of the first death, once there was one
        self.died = threading.Event()
        self._callbacks: list[Callable[[str], None]] = [on_death] if on_death is not None else []
        self._owner_tells = on_death is not None
        self._stopped = False
        self._lock = threading.Lock()

    def wait(self, timeout: float | None = None) -> bool:
        """Block until a watched thread died (True) or the timeout passed (False)."""
        return self.died.wait(timeout)

    def add_callback(self, callback: Callable[[str], None]) -> None:
        """Call `callback(line)` on the first death (at once if one already happened)."""
        with self._lock:
            self._callbacks.append(callback)
            line = self.failure
        if line:
            callback(line)

    def stop(self) -> None:
        """From now on a thread that ends by an exception is part of shutting down, not a failure."""
        with self._lock:
            self._stopped = True

    def report(self, thread_name: str, error: BaseException) -> None:
        """Record the death of `thread_name`; only the first one is logged and runs the callbacks."""
        line = death_line(thread_name, error)
        with self._lock:
            if self.failure or self._stopped:
                return
            self.failure = line
            callbacks = list(self._callbacks)
        self.died.set()
        if self.log is not None:
            try:
                self.log(line)
            except Exception:  # the logger itself may be gone: standard error still works
                _print_to_stderr(line)
        elif not self._owner_tells:
            _print_to_stderr(line)
        for callback in callbacks:
            try:
                callback(line)
            except Exception as error:  # one failing callback must not keep the others from ending the process
                _print_to_stderr(death_line(f'{thread_name} (callback)', error))

    def guard(self, target: Callable[[], Any], thread_name: str) -> Callable[[], None]:
        """`target` as a thread's target that reports its death (an exception escaping it) here."""
        def run() -> None:
            try:
                target()
            except BaseException as error:  # a dying thread is reported whatever killed it
                self.report(thread_name, error)

        return run

    def start(self, target: Callable[[], Any], thread_name: str) -> threading.Thread:
        """Start a daemon thread named `thread_name` running `target`, watched."""
        thread = threading.Thread(target=self.guard(target, thread_name), name=thread_name, daemon=True)
        thread.start()
        return thread

    def install_excepthook(self) -> None:
        """Report every thread's uncaught exception here (process-wide: for a process of its own)."""
        def hook(arguments: threading.ExceptHookArgs) -> None:
            name = arguments.thread.name if arguments.thread is not None else 'unknown'
            self.report(name, arguments.exc_value if arguments.exc_value is not None else RuntimeError('?'))

        threading.excepthook = hook
