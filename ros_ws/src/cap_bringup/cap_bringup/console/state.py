"""What the console page shows, kept from the graph's events: the commands of the session with their stage, code,
plan, words and outcome; lmp_node's own state; the image topics; notices. Plain Python, no rclpy: the node feeds it
(`on_status`, `on_say`, ...), the web server sends `snapshot()` to every page whenever `version` changed.

Everything here is text from the graph or from users (commands, generated code, what the robot says): the page
shows it as text only, never as markup (see static/console.js).
"""
from __future__ import annotations

import collections
import itertools
import threading
from dataclasses import dataclass, field
from typing import Any

FINAL_STAGES = ('done', 'error', 'cancelled', 'refused')
MAX_SAID_LINES = 50  # per command
MAX_NOTICES = 10
MAX_TEXT = 2000  # characters of a message or said line the page gets
MAX_CODE = 50_000  # characters of code (lmp_node bounds it the same way)


@dataclass(frozen=True)
class StatusRecord:
    """One /cap/status event, with the stage by name ('received', 'code', 'awaiting_approval', 'done', ...)."""

    command_id: str
    command: str
    stage: str
    code: str = ''
    message: str = ''
    plan: tuple[dict[str, Any], ...] = ()  # {'description', 'object_name', 'target_name', 'points'}
    stamp_s: float = 0.0
    twin_png: bytes = b''  # with awaiting_approval of a rehearsed program: the twin's scene after the rehearsal


@dataclass
class CommandEntry:
    command_id: str
    command: str
    stage: str
    code: str = ''
    message: str = ''
    plan: list[dict[str, Any]] = field(default_factory=list)
    said: list[str] = field(default_factory=list)
    outcome: str = ''  # the final stage once it ended; 'lost' when lmp_node started again before that
    started_s: float = 0.0
    ended_s: float = 0.0
    twin_png: bytes = b''  # the twin's picture shown with the approval (served apart: `twin_picture`)
    twin_version: int = 0  # grows with each picture, so that the page asks for the new one

    def view(self) -> dict[str, Any]:
        return {'id': self.command_id, 'command': self.command, 'stage': self.stage, 'code': self.code,
                'message': self.message, 'plan': self.plan, 'said': self.said, 'outcome': self.outcome,
                'started': self.started_s, 'ended': self.ended_s,
                'twin': self.twin_version if self.twin_png else 0}


class ConsoleState:
    """Thread-safe: ROS callbacks write, the web server reads. `version` grows with every change."""

    def __init__(self, history_size: int = 50) -> None:
        self.history_size = history_size
        self._lock = threading.Lock()
        self._commands: collections.deque[CommandEntry] = collections.deque()  # oldest first
        self._by_id: dict[str, CommandEntry] = {}  # the newest entry of each command id
        self._notices: collections.deque[dict[str, Any]] = collections.deque(maxlen=MAX_NOTICES)
        self._notice_ids = itertools.count(1)
        self._streams: list[str] = []
        self._graph_state = ''
        self._namespace = ''
        self.version = 0  # read without the lock by the web server, which polls it

    def _touch(self) -> None:
        self.version += 1

    # ---------------------------------------------------------------------------------------------- from the graph
    def on_status(self, record: StatusRecord) -> None:
        with self._lock:
            if not record.command_id:  # lmp_node's own state ('ready: ...', 'model ready: ...')
                if record.message.startswith('ready:'):  # lmp_node (re)started: what it ran before is over
                    for entry in self._commands:
                        if not entry.outcome:
                            entry.outcome, entry.message = 'lost', 'lmp_node started again before it ended'
                self._graph_state = record.message[:MAX_TEXT]
                self._touch()
                return
            entry = self._by_id.get(record.command_id)
            if entry is None or (entry.outcome and record.stage == 'received'):  # a restarted lmp_node reuses ids
                entry = CommandEntry(record.command_id, record.command[:MAX_TEXT], record.stage,
                                     started_s=record.stamp_s)
                self._commands.append(entry)
                self._by_id[record.command_id] = entry
                while len(self._commands) > self.history_size:
                    dropped = self._commands.popleft()
                    if self._by_id.get(dropped.command_id) is dropped:
                        del self._by_id[dropped.command_id]
            entry.stage = record.stage
            if record.code:
                entry.code = record.code[:MAX_CODE]
            entry.message = record.message[:MAX_TEXT]
            if record.stage == 'awaiting_approval':
                entry.plan = [dict(step) for step in record.plan]
                if record.twin_png:
                    entry.twin_png, entry.twin_version = record.twin_png, entry.twin_version + 1
            if record.stage in FINAL_STAGES:
                entry.outcome = record.stage
                entry.ended_s = record.stamp_s
            self._touch()

    def on_code(self, code: str) -> None:
        """/cap/code: the code of the command that is generating (its status may still lack it)."""
        with self._lock:
            entry = self._running()
            if entry is not None and not entry.code:
                entry.code = code[:MAX_CODE]
                self._touch()

    def on_say(self, text: str) -> None:
        """/cap/say: a line the robot said, kept with the command that runs."""
        with self._lock:
            entry = self._running()
            if entry is None:
                self._notice_locked('info', f'the robot says: {text}')
                return
            entry.said.append(text[:MAX_TEXT])
            del entry.said[:-MAX_SAID_LINES]
            self._touch()

    def _running(self) -> CommandEntry | None:
        # lmp_node runs commands one at a time in the order they came: the oldest one without an outcome is the one
        # running, even while its status still says 'received' (a say can arrive before its later statuses do)
        return next((entry for entry in self._commands if not entry.outcome), None)

    def set_streams(self, topics: list[str]) -> None:
        with self._lock:
            if topics != self._streams:
                self._streams = list(topics)
                self._touch()

    def set_namespace(self, namespace: str) -> None:
        with self._lock:
            self._namespace = namespace
            self._touch()

    def notice(self, level: str, text: str) -> None:
        """A line for the person at the page: 'info' or 'error' (a reply of the graph, a request it refused)."""
        with self._lock:
            self._notice_locked(level, text)

    def _notice_locked(self, level: str, text: str) -> None:
        self._notices.append({'id': next(self._notice_ids), 'level': level, 'text': text[:MAX_TEXT]})
        self._touch()

    # ---------------------------------------------------------------------------------------------- to the page
    def snapshot(self) -> dict[str, Any]:
        with self._lock:
            return {'version': self.version, 'namespace': self._namespace, 'graph': self._graph_state,
                    'streams': list(self._streams), 'notices': list(self._notices),
                    'commands': [entry.view() for entry in self._commands]}

    def twin_picture(self, command_id: str) -> bytes:
        """The PNG of the twin's scene shown with a command's approval (empty if it has none)."""
        with self._lock:
            entry = self._by_id.get(command_id)
            return entry.twin_png if entry is not None else b''

    def awaiting_approval(self) -> list[str]:
        """The ids of the commands whose code waits for approval."""
        with self._lock:
            return [entry.command_id for entry in self._commands
                    if entry.stage == 'awaiting_approval' and not entry.outcome]


__all__ = ['FINAL_STAGES', 'CommandEntry', 'ConsoleState', 'StatusRecord']
