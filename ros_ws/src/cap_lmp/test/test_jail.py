"""The jail (jail.py): code that escaped the in-process sandbox can write no file, open no connection, exec nothing.

Every attack runs twice as raw Python in a sandbox-like process (testing/escaped_child.py): without the jail, where
it must succeed (so the test proves something), and after the same enter_jail() call the sandbox process makes,
where it must fail with an OSError and leave no trace: the file is unchanged, the server saw nothing, the binary's
side effect did not happen, the other process still runs. What the sandbox process needs keeps working.
"""
from __future__ import annotations

import json
import os
import re
import shutil
import signal
import socket
import stat
import subprocess
import sys
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Callable, Iterator

import pytest

from cap_lmp.sandbox import jail

pytestmark = pytest.mark.skipif(sys.platform != 'linux', reason='the jail uses Linux system calls')

TOUCH = shutil.which('touch') or '/usr/bin/touch'
REPLY_TIMEOUT_S = 60.0  # generous: the machine may be busy; a hung child fails the test instead of hanging it


class Escaped:
    """One escaped_child process: `run(code)` executes raw code in it and returns its reply."""

    def __init__(self, mode: str, extra_fds: tuple[int, ...] = ()) -> None:
        ours, theirs = socket.socketpair()
        env = {**os.environ, 'PYTHONPATH': os.pathsep.join(p for p in sys.path if p), 'OPENBLAS_NUM_THREADS': '1',
               'OMP_NUM_THREADS': '1', 'PYTHONDONTWRITEBYTECODE': '1'}
        with theirs:
            self.process = subprocess.Popen(
                [sys.executable, '-m', 'cap_lmp.testing.escaped_child', mode, str(theirs.fileno())],
                pass_fds=(theirs.fileno(), *extra_fds), env=env, stdin=subprocess.DEVNULL, start_new_session=True)
        self.channel = Connection(ours.detach())
        self.outcome = self.receive()
        assert self.outcome is not None, 'the escaped child did not start'
        if mode == 'jail' and 'jail_error' in self.outcome:
            self.close()
            pytest.skip(f"this kernel cannot hold the jail: {self.outcome['jail_error']}")

    def receive(self) -> dict | None:
        """The next message, or None if the process ended (an exec replaced it, or it died)."""
        if not self.channel.poll(REPLY_TIMEOUT_S):
            raise AssertionError('no answer from the escaped child')
        try:
            return json.loads(self.channel.recv_bytes())
        except EOFError:
            return None

    def run(self, code: str) -> dict | None:
        self.channel.send_bytes(code.encode())
        return self.receive()

    def close(self) -> None:
        try:
            os.killpg(self.process.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        self.process.wait()
        self.channel.close()


@pytest.fixture
def start() -> Iterator[Callable[..., Escaped]]:
    """A new escaped child of the given mode (for attacks that end or change the process, or need an fd)."""
    children: list[Escaped] = []

    def _start(mode: str, extra_fds: tuple[int, ...] = ()) -> Escaped:
        children.append(Escaped(mode, extra_fds))
        return children[-1]

    yield _start
    for child in children:
        child.close()


@pytest.fixture(scope='module')
def shared() -> Iterator[Callable[[str], Escaped]]:
    """One escaped child per mode for the whole module (each starts in about 0.3 s); replaced if it ended."""
    children: dict[str, Escaped] = {}

    def _shared(mode: str) -> Escaped:
        if mode not in children or children[mode].process.poll() is not None:
            children[mode] = Escaped(mode)
        return children[mode]

    yield _shared
    for child in children.values():
        child.close()


def refused(reply: dict | None) -> bool:
    """The attack failed inside the process with a permission error (not a kill, not success)."""
    return reply is not None and not reply['ok'] and reply['error'] in ('PermissionError', 'ValueError') \
        and reply['errno'] in (1, 13, None)


# ------------------------------------------------------------------------------------------------ the jail itself
def test_the_jail_is_complete_on_this_kernel_and_cheap(start):
    report = start('jail').outcome['jail']
    assert report['missing'] == [], report
    assert report['landlock_abi'] >= 1
    assert any('Landlock' in layer for layer in report['applied'])
    assert any('seccomp' in layer for layer in report['applied'])
    assert report['seconds'] < 0.5, report  # measured 0.5-1 ms; generous for a loaded machine
    print(f"entering the jail took {report['seconds'] * 1e3:.2f} ms")


@pytest.mark.parametrize('machine', ['x86_64', 'aarch64'])
def test_the_filter_assembles_for_both_architectures(machine):
    program = jail.seccomp_program(machine, 12345)
    assert 100 < len(program) < 256  # every jump in range; a kernel takes up to 4096 instructions
    assert program[-1] == (0x06, 0, 0, jail.SECCOMP_RET_KILL_PROCESS)  # an unknown ABI ends the process


HEADERS = {0: Path('/usr/include/x86_64-linux-gnu/asm/unistd_64.h'), 1: Path('/usr/include/asm-generic/unistd.h')}


@pytest.mark.parametrize('column', [0, 1], ids=['x86_64', 'aarch64'])
def test_the_system_call_numbers_match_the_kernel_headers(column):
    header = HEADERS[column]
    if not header.exists():
        pytest.skip(f'{header} is not installed')
    defined = dict(re.findall(r'#define __NR(?:3264)?_(\w+)\s+(\d+)', header.read_text()))
    checked = 0
    for name, numbers in jail._SYSCALLS.items():
        if name in defined:  # an older header lacks the newest calls
            assert numbers[column] == int(defined[name]), name
            checked += 1
        elif numbers[column] is not None:
            assert numbers[column] >= 440, f'{name} is not in {header}'
    assert checked > 100


# ------------------------------------------------------------------------------------------------ the file system
# name: (prepare the directory, the escaped code, what a user would look at afterwards)
FILE_ATTACKS: dict[str, tuple[Callable[[Path], None], str, Callable[[Path], object]]] = {
    'write a new file': (lambda d: None, "open(D + '/escaped.txt', 'w').write('escaped')",
                         lambda d: (d / 'escaped.txt').exists()),
    'append to a file': (lambda d: (d / 'log.txt').write_text('original'), "open(D + '/log.txt', 'a').write('!')",
                         lambda d: (d / 'log.txt').read_text()),
    'truncate a file': (lambda d: (d / 'data.txt').write_text('original'), "os.truncate(D + '/data.txt', 0)",
                        lambda d: (d / 'data.txt').read_text()),
    'open read-only with O_TRUNC': (lambda d: (d / 'data.txt').write_text('original'),
                                    "os.close(os.open(D + '/data.txt', os.O_RDONLY | os.O_TRUNC))",
                                    lambda d: (d / 'data.txt').read_text()),
    'create a directory': (lambda d: None, "os.mkdir(D + '/made')", lambda d: (d / 'made').exists()),
    'remove a file': (lambda d: (d / 'keep.txt').write_text('x'), "os.remove(D + '/keep.txt')",
                      lambda d: (d / 'keep.txt').exists()),
    'remove a directory': (lambda d: (d / 'sub').mkdir(), "os.rmdir(D + '/sub')", lambda d: (d / 'sub').exists()),
    'rename a file': (lambda d: (d / 'a.txt').write_text('x'), "os.rename(D + '/a.txt', D + '/b.txt')",
                      lambda d: sorted(p.name for p in d.iterdir())),
    'make a symbolic link': (lambda d: None, "os.symlink('/etc/passwd', D + '/link')",
                             lambda d: (d / 'link').is_symlink()),
    'make a hard link': (lambda d: (d / 'a.txt').write_text('x'), "os.link(D + '/a.txt', D + '/hard')",
                         lambda d: (d / 'hard').exists()),
    'change a mode': (lambda d: (d / 'a.txt').write_text('x'), "os.chmod(D + '/a.txt', 0o777)",
                      lambda d: stat.S_IMODE((d / 'a.txt').stat().st_mode)),
    'make a fifo': (lambda d: None, "os.mkfifo(D + '/fifo')", lambda d: (d / 'fifo').exists()),
    'write through ctypes': (lambda d: None,
                             "import ctypes\nlibc = ctypes.CDLL(None, use_errno=True)\n"
                             "fd = libc.open((D + '/c.txt').encode(), os.O_WRONLY | os.O_CREAT, 0o644)\n"
                             "if fd < 0: raise OSError(ctypes.get_errno(), 'open')",
                             lambda d: (d / 'c.txt').exists()),
}


@pytest.mark.parametrize('attack', FILE_ATTACKS)
def test_an_escaped_program_changes_no_file(shared, tmp_path, attack):
    prepare, code, look = FILE_ATTACKS[attack]
    outcomes = {}
    for mode in ('free', 'jail'):
        directory = tmp_path / mode
        directory.mkdir()
        prepare(directory)
        before = look(directory)
        reply = shared(mode).run(f'import os\nD = {str(directory)!r}\n{code}')
        outcomes[mode] = (before, reply, look(directory))
    before, reply, after = outcomes['free']
    assert reply['ok'] and after != before, (reply, before, after)  # the attack works without the jail
    before, reply, after = outcomes['jail']
    assert refused(reply), reply
    assert after == before


# ------------------------------------------------------------------------------------------------ the network
def _tcp_server() -> socket.socket:
    server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    server.bind(('127.0.0.1', 0))
    server.listen(8)
    server.setblocking(False)
    return server


def _connections(server: socket.socket) -> list[bytes]:
    """What arrived on the listening socket by now (a connect completes before the escaped code answers)."""
    received = []
    while True:
        try:
            connection, _ = server.accept()
        except BlockingIOError:
            return received
        with connection:
            connection.settimeout(5.0)
            received.append(connection.recv(100))


def test_an_escaped_program_opens_no_tcp_connection(shared):
    with _tcp_server() as server:
        port = server.getsockname()[1]
        code = f"import socket\ns = socket.create_connection(('127.0.0.1', {port}), timeout=5)\ns.sendall(b'escaped')"
        assert shared('free').run(code)['ok']
        assert _connections(server) == [b'escaped']
        reply = shared('jail').run(code)
        assert refused(reply), reply
        assert _connections(server) == []


def test_an_escaped_program_cannot_listen(shared):
    code = "import socket\ns = socket.socket()\ns.bind(('127.0.0.1', 0))\ns.listen()\nresult = s.getsockname()[1]"
    assert shared('free').run(code)['ok']
    assert refused(shared('jail').run(code))


def test_an_escaped_program_sends_no_udp_datagram(shared):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as server:
        server.bind(('127.0.0.1', 0))
        server.setblocking(False)
        code = (f"import socket\nsocket.socket(socket.AF_INET, socket.SOCK_DGRAM)"
                f".sendto(b'escaped', ('127.0.0.1', {server.getsockname()[1]}))")
        assert shared('free').run(code)['ok']
        assert server.recv(100) == b'escaped'  # loopback delivers before sendto returns
        assert refused(shared('jail').run(code))
        with pytest.raises(BlockingIOError):
            server.recv(100)


@pytest.mark.parametrize('namespace', ['path', 'abstract'])
def test_an_escaped_program_connects_to_no_unix_socket(shared, tmp_path, namespace):
    address = str(tmp_path / 'node.sock') if namespace == 'path' else f'\0cap-jail-test-{os.getpid()}'
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as server:
        server.bind(address)
        server.listen(8)
        server.setblocking(False)
        code = f"import socket\ns = socket.socket(socket.AF_UNIX)\ns.connect({address!r})\ns.sendall(b'escaped')"
        assert shared('free').run(code)['ok']
        assert _connections(server) == [b'escaped']
        assert refused(shared('jail').run(code))
        assert _connections(server) == []


def test_an_escaped_program_makes_no_socket_pair(shared):
    code = 'import socket\na, b = socket.socketpair()'
    assert shared('free').run(code)['ok']
    assert refused(shared('jail').run(code))


# ------------------------------------------------------------------------------------------------ programs
def test_an_escaped_program_execs_nothing(start, tmp_path):
    for mode in ('free', 'jail'):
        mark = tmp_path / f'{mode}-touched'
        child = start(mode)
        reply = child.run(f'import os\nos.execv({TOUCH!r}, ["touch", {str(mark)!r}])')
        if mode == 'free':  # the process became `touch`, which did its work and exited
            assert reply is None and child.process.wait(timeout=30) == 0
            assert mark.exists()
        else:
            assert refused(reply), reply
            assert not mark.exists()
            assert child.run('result = 6 * 7') == {'ok': True, 'result': 42}  # still the same process


def test_an_escaped_program_cannot_become_bin_true(start):
    code = "import os\nos.execv('/bin/true', ['true'])"
    free = start('free')
    assert free.run(code) is None and free.process.wait(timeout=30) == 0
    jailed = start('jail')
    assert refused(jailed.run(code))
    assert jailed.process.poll() is None


def test_an_escaped_program_starts_no_subprocess(shared, tmp_path):
    for mode in ('free', 'jail'):
        mark = tmp_path / f'{mode}-touched'
        reply = shared(mode).run(f'import subprocess\nresult = subprocess.run([{TOUCH!r}, {str(mark)!r}]).returncode\n'
                                f"result += subprocess.run(['/bin/true']).returncode")
        if mode == 'free':
            assert reply == {'ok': True, 'result': 0} and mark.exists()
        else:
            assert refused(reply), reply
            assert not mark.exists()


def test_an_escaped_program_cannot_fork_but_can_start_threads(start):
    fork = 'import os\npid = os.fork()\nif pid == 0:\n    os._exit(0)\nos.waitpid(pid, 0)\nresult = pid > 0'
    assert start('free').run(fork) == {'ok': True, 'result': True}
    jailed = start('jail')
    assert refused(jailed.run(fork))
    # A thread starts, and the jail holds in it too.
    threads = ('import socket, threading\nseen = []\n'
               'def work():\n    try:\n        socket.socket()\n'
               '    except OSError as error:\n        seen.append(error.errno)\n'
               't = threading.Thread(target=work)\nt.start()\nt.join()\nresult = seen')
    assert jailed.run(threads) == {'ok': True, 'result': [1]}


def test_an_escaped_program_types_nothing_into_a_terminal(start):
    """TIOCSTI on an inherited terminal would type commands into the shell that started the node."""
    import tty

    controller, terminal = os.openpty()
    tty.setraw(terminal)
    os.set_blocking(terminal, False)
    code = f'import fcntl, termios\nfcntl.ioctl({terminal}, termios.TIOCSTI, b"x")'
    try:
        for mode in ('free', 'jail'):
            reply = start(mode, (terminal,)).run(code)
            if mode == 'free':
                if not reply['ok']:  # a kernel with dev.tty.legacy_tiocsti = 0 refuses it to everyone
                    pytest.skip(f"TIOCSTI is refused here even without the jail: {reply['message']}")
                assert os.read(terminal, 10) == b'x'
            else:
                assert refused(reply), reply
                with pytest.raises(BlockingIOError):
                    os.read(terminal, 10)
    finally:
        os.close(controller)
        os.close(terminal)


# ------------------------------------------------------------------------------------------------ other processes
@pytest.fixture
def bystander() -> Iterator[subprocess.Popen]:
    """Another process of the same user, with a secret in its environment."""
    process = subprocess.Popen([sys.executable, '-c', 'import time; print("ready", flush=True); time.sleep(120)'],
                               env={**os.environ, 'BYSTANDER_SECRET': 'hunter2'}, stdout=subprocess.PIPE,
                               start_new_session=True)
    assert process.stdout.readline() == b'ready\n'  # exec'd: its environment is its own
    yield process
    process.kill()
    process.wait()
    process.stdout.close()


def test_an_escaped_program_cannot_signal_another_process(shared, bystander):
    jailed = shared('jail')
    assert refused(jailed.run(f'import os\nos.kill({bystander.pid}, 15)'))
    assert bystander.poll() is None
    assert shared('free').run(f'import os\nos.kill({bystander.pid}, 15)')['ok']
    assert bystander.wait(timeout=30) == -15


def test_an_escaped_program_cannot_read_another_process(shared, bystander):
    code = f"result = 'hunter2' in open('/proc/{bystander.pid}/environ', 'rb').read().decode(errors='replace')"
    assert shared('free').run(code) == {'ok': True, 'result': True}
    assert refused(shared('jail').run(code))


def test_an_escaped_program_cannot_change_its_limits(shared):
    code = ('import resource\nsoft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)\n'
            'try:\n    resource.setrlimit(resource.RLIMIT_NOFILE, (soft - 1, hard))\n'
            'finally:\n    result = resource.getrlimit(resource.RLIMIT_NOFILE)[0] - soft')
    assert shared('free').run(code) == {'ok': True, 'result': -1}
    assert refused(shared('jail').run(code))


# ------------------------------------------------------------------------------------------------ what must still work
def test_the_jailed_process_still_imports_and_reads_modules(start, tmp_path):
    (tmp_path / 'jail_probe.py').write_text('VALUE = 7\n')
    jailed = start('jail')  # a new one: none of these modules may have been imported before the jail
    lazy = ('numpy.polynomial', 'numpy.fft', 'shapely.ops', 'shapely.validation', 'decimal')
    code = (f'import sys\nnot_loaded = [m for m in {lazy!r} if m not in sys.modules]\n'
            'import numpy, numpy.polynomial, numpy.fft, shapely, shapely.ops, shapely.validation, decimal\n'
            f'sys.path.insert(0, {str(tmp_path)!r})\nimport jail_probe\n'
            'line = shapely.geometry.LineString([(0, 0), (1, 0)])\n'
            'result = {"not_loaded": not_loaded, "poly": float(numpy.polynomial.Polynomial([1, 2])(3)),\n'
            '          "fft": float(abs(numpy.fft.fft(numpy.ones(8))[0])),\n'
            '          "area": round(shapely.ops.unary_union([line.buffer(0.5)]).area, 2),\n'
            '          "valid": shapely.validation.explain_validity(line), "third": str(decimal.Decimal(1) / 3)[:4],\n'
            '          "probe": jail_probe.VALUE, "source": open(numpy.__file__).read(200) != "",\n'
            '          "status": "VmSize" in open("/proc/self/status").read()}')
    reply = jailed.run(code)
    assert reply['ok'], reply
    result = reply['result']
    assert result['not_loaded'] == list(lazy)  # these really were imported inside the jail
    assert result['poly'] == 7.0 and result['fft'] == 8.0 and result['area'] == 1.78
    assert result['valid'] == 'Valid Geometry' and result['third'] == '0.33'
    assert result['probe'] == 7 and result['source'] and result['status']


def test_the_inherited_socket_still_carries_messages(shared):
    jailed = shared('jail')
    jailed.channel.send_bytes(b"channel.send_bytes(b'ping' * 100_000)\nresult = channel.recv_bytes().decode()")
    assert jailed.channel.poll(REPLY_TIMEOUT_S)
    assert jailed.channel.recv_bytes() == b'ping' * 100_000  # 400 kB out, over the socket it inherited
    jailed.channel.send_bytes(b'pong')
    assert jailed.receive() == {'ok': True, 'result': 'pong'}


def test_the_jailed_process_signals_itself(shared):
    code = ('import os, signal\ngot = []\nsignal.signal(signal.SIGUSR1, lambda *a: got.append(1))\n'
            'os.kill(os.getpid(), signal.SIGUSR1)\nsignal.raise_signal(signal.SIGUSR1)\nresult = len(got)')
    assert shared('jail').run(code) == {'ok': True, 'result': 2}


# ------------------------------------------------------------------------------------------------ degraded kernels
def test_without_landlock_the_jail_says_so_and_seccomp_still_refuses(start, tmp_path):
    child = start('jail_without_landlock')
    report = child.outcome['jail']
    assert report['landlock_abi'] == 0
    assert any('Landlock' in missing for missing in report['missing'])
    assert any('seccomp' in layer for layer in report['applied'])
    reply = child.run(f"open({str(tmp_path / 'x')!r}, 'w')")
    assert refused(reply) and reply['errno'] == 1 and not (tmp_path / 'x').exists()
    assert refused(child.run('import socket\nsocket.socket()'))
    assert refused(child.run(f'import os\nos.execv({TOUCH!r}, ["touch", {str(tmp_path / "y")!r}])'))


def test_without_seccomp_the_jail_says_so_and_landlock_still_refuses(start, tmp_path):
    child = start('jail_without_seccomp')
    report = child.outcome['jail']
    if report['landlock_abi'] < 4:
        pytest.skip(f"Landlock ABI {report['landlock_abi']}: too old to hold this alone")
    assert any('seccomp' in missing for missing in report['missing'])
    assert any('Landlock' in layer for layer in report['applied'])
    reply = child.run(f"open({str(tmp_path / 'x')!r}, 'w')")
    assert refused(reply) and reply['errno'] == 13 and not (tmp_path / 'x').exists()  # EACCES: Landlock's answer
    reply = child.run(f'import os\nos.execv({TOUCH!r}, ["touch", {str(tmp_path / "y")!r}])')
    assert refused(reply) and not (tmp_path / 'y').exists()
    with _tcp_server() as server:
        code = f"import socket\nsocket.create_connection(('127.0.0.1', {server.getsockname()[1]}), timeout=5)"
        assert refused(child.run(code))
        assert _connections(server) == []


def test_a_jail_entered_with_other_threads_running_is_incomplete(start):
    report = start('jail_with_a_thread').outcome['jail']
    if report['landlock_abi'] >= 8:
        pytest.skip('Landlock ABI 8 restricts every thread')
    assert any('other thread' in missing for missing in report['missing']), report


def test_a_required_jail_refuses_to_start_without_landlock(start):
    outcome = start('required_without_landlock').outcome
    assert 'jail_error' in outcome and 'Landlock' in outcome['jail_error'], outcome
