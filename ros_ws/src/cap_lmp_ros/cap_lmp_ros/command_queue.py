"""The rule for commands that arrive while another runs: one runs at a time, later ones wait in a bounded FIFO.

Plain Python (no rclpy) so the rule is tested on its own. A command that finds the queue full is refused at once;
a stop empties the queue as well as ending the running command.

A command is one instruction: `normalise_command` puts it on one line (every run of white space and control
characters becomes one space) before it can reach a prompt, where a newline would start a second instruction.
An empty command, or one longer than MAX_COMMAND_CHARS once normalised, is refused with a message saying so.
"""
from __future__ import annotations

import collections
import itertools
import threading
from dataclasses import dataclass, field
from typing import Any

from cap_lmp.outcome import Outcome
from cap_lmp.safe_text import one_line, wire_text

MAX_COMMAND_CHARS = 1000  # of a normalised command: an instruction of a sentence or a few, not a document
_SHOWN_CHARS = 200  # of a refused over-long command, in its refusal


def normalise_command(text: Any) -> tuple[str, str]:
    """(the command on one line, the reason it is refused or '')."""
    if not isinstance(text, str):
        return '', 'refused: a command is text'
    command = one_line(text, limit=len(text))
    if not command:
        return '', 'refused: the command is empty'
    if len(command) > MAX_COMMAND_CHARS:
        return (wire_text(command, _SHOWN_CHARS),
                f'refused: the command is {len(command)} characters long; the limit is {MAX_COMMAND_CHARS}')
    return command, ''


@dataclass
class Job:
    command_id: str
    command: str
    source: str  # 'topic' or 'action'
    finished: threading.Event = field(default_factory=threading.Event)
    cancel_requested: bool = False
    stop_reason: str = ''  # why it was cancelled, in words
    result: Any = None  # the engine's CommandResult, or None when dropped before running
    goal_handle: Any = None  # the /cap/execute goal waiting for this job, if it came as one
    outcome: Outcome | None = None  # how it ended; None while it waits or runs
    refusal: str = ''  # why it was refused without running, in words
    awaiting_approval: bool = False  # its code waits for a person's approval (lmp_node's require_approval)
    decided: threading.Event = field(default_factory=threading.Event)  # set with `decision`
    decision: tuple[bool, str] = (False, '')  # (approved, the reason given)
    verdict: Any = None  # its rehearsal on the twin (cap_lmp.rehearsal.TwinVerdict), when it was rehearsed
    prediction: str = ''  # after a rehearsed run: the world against the twin's prediction, in words
    prediction_misses: list = field(default_factory=list)  # cap_lmp.rehearsal.PredictionMiss


class CommandQueue:
    def __init__(self, max_waiting: int = 5) -> None:
        self.max_waiting = max_waiting
        self._waiting: collections.deque[Job] = collections.deque()
        self._condition = threading.Condition()
        self._ids = itertools.count(1)
        self.running: Job | None = None
        self._closed = False

    def submit(self, command: str, source: str, goal_handle: Any = None) -> tuple[Job, bool]:
        """A new job and whether it was queued (False: refused; `job.refusal` says why)."""
        command, refusal = normalise_command(command)
        with self._condition:
            job = Job(command_id=f'cmd-{next(self._ids)}', command=command, source=source, goal_handle=goal_handle)
            if not refusal and self._closed:
                refusal = 'refused: lmp_node is shutting down'
            elif not refusal and len(self._waiting) >= self.max_waiting:
                refusal = (f'refused: the queue is full ({len(self._waiting)} commands are already waiting; '
                           f'max_queued_commands={self.max_waiting})')
            if refusal:
                job.refusal = refusal
                return job, False
            self._waiting.append(job)
            self._condition.notify()
            return job, True

    def next_job(self, timeout: float | None = None) -> Job | None:
        """Block until a job is waiting (or the queue is closed); mark it running."""
        with self._condition:
            if not self._condition.wait_for(lambda: self._waiting or self._closed, timeout):
                return None
            if self._closed:
                return None
            self.running = self._waiting.popleft()
            return self.running

    def finish(self, job: Job) -> None:
        with self._condition:
            if self.running is job:
                self.running = None
        job.finished.set()

    def withdraw(self, job: Job) -> bool:
        """Remove a job that has not started; False when it already runs or ran."""
        with self._condition:
            if job in self._waiting:
                self._waiting.remove(job)
                return True
            return False

    def drain(self) -> list[Job]:
        """Remove and return every waiting job."""
        with self._condition:
            jobs = list(self._waiting)
            self._waiting.clear()
            return jobs

    def waiting(self) -> int:
        with self._condition:
            return len(self._waiting)

    def close(self) -> None:
        with self._condition:
            self._closed = True
            self._condition.notify_all()
