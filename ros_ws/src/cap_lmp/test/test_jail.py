"""The jail (jail.py): code that escaped the in-process sandbox can do only what the sandbox process needs.

Every attack runs twice as raw Python in a sandbox-like process (testing/escaped_child.py): without the jail, where
it must succeed (so the test proves something), and after the same enter_jail() call the sandbox process makes,
where it must fail with an OSError and leave no trace: the file is unchanged, the server saw nothing, the binary's
side effect did not happen, the other process still runs, the segment, the flags, the terminal are as they were.
What the sandbox process needs keeps working: the allowlist's measurement is kept here as a test (the jail with its
filter audited, testing/syscall_audit.py, under the engine, NumPy and Shapely).
"""
from __future__ import annotations

import ctypes
import errno
import fcntl
import functools
import json
import os
import re
import shutil
import signal
import socket
import stat
import struct
import subprocess
import sys
import termios
import time
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Callable, Iterator

import pytest

from cap_lmp.isolated_engine import IsolatedEngine
from cap_lmp.llm import OpenAICompatibleClient
from cap_lmp.sandbox import SandboxLimits, jail
from cap_lmp.testing.openai_server import ScriptedOpenAIServer
from cap_lmp.testing.syscall_audit import SyscallAudit
from cap_lmp.testing.toy_domain import build_engine as toy_build_engine
from cap_lmp.testing.toy_world import ToyWorld

pytestmark = pytest.mark.skipif(sys.platform != 'linux', reason='the jail uses Linux system calls')

TOUCH = shutil.which('touch') or '/usr/bin/touch'
REPLY_TIMEOUT_S = 60.0  # generous: the machine may be busy; a hung child fails the test instead of hanging it


class Escaped:
    """One escaped_child process: `run(code)` executes raw code in it and returns its reply."""

    def __init__(self, mode: str, extra_fds: tuple[int, ...] = (), audit: SyscallAudit | None = None) -> None:
        ours, theirs = socket.socketpair()
        env = {**os.environ, 'PYTHONPATH': os.pathsep.join(p for p in sys.path if p), 'OPENBLAS_NUM_THREADS': '1',
               'OMP_NUM_THREADS': '1', 'PYTHONDONTWRITEBYTECODE': '1'}
        with theirs:
            self.process = subprocess.Popen(
                [sys.executable, '-m', 'cap_lmp.testing.escaped_child', mode, str(theirs.fileno())],
                pass_fds=(theirs.fileno(), *extra_fds), env=env, stdin=subprocess.DEVNULL, start_new_session=True)
        if audit is not None:  # mode audit_*: its calls wait for the supervisor
            audit.attach(self.process.pid)
        self.channel = Connection(ours.detach())
        self.outcome = self.receive()
        assert self.outcome is not None, 'the escaped child did not start'
        if (mode == 'jail' or mode.startswith('audit_')) and 'jail_error' in self.outcome:
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

    def _start(mode: str, extra_fds: tuple[int, ...] = (), audit: SyscallAudit | None = None) -> Escaped:
        children.append(Escaped(mode, extra_fds, audit))
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
    assert 50 < len(program) < 256  # every jump in range; a kernel takes up to 4096 instructions
    assert program[-1] == (0x06, 0, 0, jail.SECCOMP_RET_KILL_PROCESS)  # an unknown ABI ends the process
    verdict = functools.partial(run_filter, program, machine)
    for name in jail.ALLOWED_CALLS:
        if jail.syscall_number(name, machine) is not None:
            assert verdict(name) == jail.SECCOMP_RET_ALLOW, name
    for name in ('memfd_create', 'shmget', 'msgget', 'semget', 'mq_open', 'flock', 'inotify_init1', 'sync',
                 'pidfd_open', 'file_setattr', 'socket', 'execve', 'setrlimit', 'prlimit64', 'seccomp', 'pipe2'):
        assert verdict(name) == jail.REFUSED, name
    assert verdict('ioctl', (0, 0x5401)) == jail.SECCOMP_RET_ERRNO | errno.ENOTTY  # isatty(): no terminal
    assert verdict('ioctl', (0, 0x541B)) == jail.SECCOMP_RET_ALLOW  # FIONREAD
    assert verdict('ioctl', (0, 0x5402)) == verdict('ioctl', (0, 0x40086602)) == jail.REFUSED  # TCSETS, SETFLAGS
    assert verdict('fcntl', (0, 3)) == jail.SECCOMP_RET_ALLOW  # F_GETFL
    assert verdict('fcntl', (0, 1024)) == verdict('fcntl', (0, 6)) == jail.REFUSED  # F_SETLEASE, F_SETLK
    assert verdict('openat', (0, 0, os.O_RDONLY | os.O_CLOEXEC)) == jail.SECCOMP_RET_ALLOW
    assert verdict('openat', (0, 0, os.O_WRONLY)) == jail.REFUSED
    assert verdict('clone', (0x3D0F00,)) == jail.SECCOMP_RET_ALLOW  # the C library's thread flags
    assert verdict('clone', (0x11,)) == jail.REFUSED  # fork: SIGCHLD alone
    assert verdict('clone3') == jail.SECCOMP_RET_ERRNO | errno.ENOSYS
    assert verdict('kill', (12345,)) == jail.SECCOMP_RET_ALLOW and verdict('kill', (1,)) == jail.REFUSED


def run_filter(program, machine: str, name: str, args: tuple[int, ...] = ()) -> int:
    """What the classic BPF `program` returns for system call `name` with `args` on `machine`."""
    arch = {'x86_64': 0xC000003E, 'aarch64': 0xC00000B7}[machine]
    padded = [*args, *[0] * (6 - len(args))]
    data = struct.pack('<iIQ6Q', jail.syscall_number(name, machine), arch, 0, *padded)
    accumulator, pc = 0, 0
    while True:
        code, jump_true, jump_false, k = program[pc]
        if code == 0x20:
            accumulator = struct.unpack_from('<I', data, k)[0]
        elif code == 0x06:
            return k
        else:
            taken = {0x15: accumulator == k, 0x35: accumulator >= k, 0x45: bool(accumulator & k)}[code]
            pc += jump_true if taken else jump_false
        pc += 1


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


# ------------------------------------------------------------------------------------------------ objects and memory
LIBC = ('import ctypes, os\nlibc = ctypes.CDLL(None, use_errno=True)\n'
        'def check(value):\n    if value == -1:\n        raise OSError(ctypes.get_errno(), "refused")\n'
        '    return value\n')
# System V objects (IPC_PRIVATE, IPC_CREAT | 0600) and a POSIX queue outlive the process; without the jail the
# attack removes what it made (IPC_RMID, mq_unlink).
IPC_ATTACKS = {
    'shared memory': 'made = check(libc.shmget(0, 1 << 20, 0o1600))\nlibc.shmctl(made, 0, None)',
    'message queue': 'made = check(libc.msgget(0, 0o1600))\nlibc.msgctl(made, 0, None)',
    'semaphore': 'made = check(libc.semget(0, 1, 0o1600))\nlibc.semctl(made, 0, 0)',
    'POSIX message queue': ("libc.mq_open.restype = ctypes.c_int\nname = b'/cap-jail-test-%d' % os.getpid()\n"
                            'made = check(libc.mq_open(name, os.O_CREAT | os.O_RDWR, 0o600, None))\n'
                            'os.close(made)\nlibc.mq_unlink(name)'),
}


@pytest.mark.parametrize('kind', IPC_ATTACKS)
def test_an_escaped_program_makes_no_ipc_object(shared, kind):
    code = f'{LIBC}{IPC_ATTACKS[kind]}\nresult = made >= 0'
    assert shared('free').run(code) == {'ok': True, 'result': True}
    assert refused(shared('jail').run(code))


@pytest.fixture
def segment() -> Iterator[tuple[int, ctypes.c_void_p]]:
    """A System V shared-memory segment of this process (its id and where it is attached), holding 'original'."""
    libc = ctypes.CDLL(None, use_errno=True)
    libc.shmat.restype = ctypes.c_void_p
    made = libc.shmget(0, 4096, 0o1600)
    if made < 0:
        pytest.skip(f'no System V shared memory here: {os.strerror(ctypes.get_errno())}')
    address = libc.shmat(made, None, 0)
    ctypes.memmove(address, b'original', 8)
    yield made, address
    libc.shmdt(ctypes.c_void_p(address))
    libc.shmctl(made, 0, None)


def test_an_escaped_program_cannot_write_another_process_shared_memory(shared, segment):
    made, address = segment
    code = (f'{LIBC}libc.shmat.restype = ctypes.c_void_p\nat = libc.shmat({made}, None, 0)\n'
            'if at in (None, 2 ** 64 - 1):\n    raise OSError(ctypes.get_errno(), "shmat")\n'
            "ctypes.memmove(at, b'escaped!', 8)\nlibc.shmdt(ctypes.c_void_p(at))")
    assert refused(shared('jail').run(code))
    assert ctypes.string_at(address, 8) == b'original'
    assert shared('free').run(code)['ok']
    assert ctypes.string_at(address, 8) == b'escaped!'


def test_an_escaped_program_holds_no_memory_outside_its_address_space(shared):
    """memfd_create: file pages that count against no RLIMIT_AS and no resident size; pipes buffer likewise."""
    code = ("import os\nfd = os.memfd_create('held')\nfor i in range(8):\n    os.write(fd, bytes(1 << 20))\n"
            'result = os.fstat(fd).st_size')
    assert shared('free').run(code) == {'ok': True, 'result': 8 << 20}
    assert refused(shared('jail').run(code))
    assert refused(shared('jail').run('import os\nr, w = os.pipe()'))


# ------------------------------------------------------------------------------------------------ inode flags
FS_IOC_GETFLAGS, FS_IOC_SETFLAGS, FS_NODUMP_FL = 0x80086601, 0x40086602, 0x40
FS_IOC_FSGETXATTR, FS_IOC_FSSETXATTR, FS_XFLAG_NODUMP = 0x801C581F, 0x401C5820, 0x80
FILE_GETATTR, FILE_SETATTR, AT_FDCWD = 468, 469, -100


def _nodump(path: Path) -> bool:
    """Whether the file has the no-dump flag (a flag its owner may set; chattr +d), as lsattr would show."""
    fd = os.open(path, os.O_RDONLY)
    try:
        return bool(struct.unpack('q', fcntl.ioctl(fd, FS_IOC_GETFLAGS, bytes(8)))[0] & FS_NODUMP_FL)
    finally:
        os.close(fd)


def _flag_attack(way: str, path: Path) -> str:
    """Escaped code setting the no-dump flag of `path` through a read-only descriptor, or by path (file_setattr)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        flags = struct.unpack('q', fcntl.ioctl(fd, FS_IOC_GETFLAGS, bytes(8)))[0]
        xattr = bytearray(fcntl.ioctl(fd, FS_IOC_FSGETXATTR, bytes(28)))
    finally:
        os.close(fd)
    struct.pack_into('I', xattr, 0, struct.unpack_from('I', xattr)[0] | FS_XFLAG_NODUMP)
    open_it = f'import fcntl, os\nfd = os.open({str(path)!r}, os.O_RDONLY)\n'
    if way == 'FS_IOC_SETFLAGS':
        return f'{open_it}fcntl.ioctl(fd, {FS_IOC_SETFLAGS}, {struct.pack("q", flags | FS_NODUMP_FL)!r})'
    if way == 'FS_IOC_FSSETXATTR':
        return f'{open_it}fcntl.ioctl(fd, {FS_IOC_FSSETXATTR}, {bytes(xattr)!r})'
    attr = struct.pack('QIIII', FS_XFLAG_NODUMP, 0, 0, 0, 0)  # struct file_attr, version 0 (24 bytes)
    return (f'{LIBC}attr = ctypes.create_string_buffer({attr!r}, 24)\n'
            f'check(libc.syscall({FILE_SETATTR}, {AT_FDCWD}, {str(path).encode()!r}, attr, 24, 0))')


@pytest.mark.parametrize('way', ['FS_IOC_SETFLAGS', 'FS_IOC_FSSETXATTR', 'file_setattr'])
def test_an_escaped_program_changes_no_inode_flag(shared, tmp_path, way):
    outcomes = {}
    for mode in ('free', 'jail'):
        path = tmp_path / f'{mode}.txt'
        path.write_text('x')
        try:
            code = _flag_attack(way, path)
        except OSError as error:
            pytest.skip(f'{tmp_path} has no inode flags: {error}')
        outcomes[mode] = (shared(mode).run(code), _nodump(path))
    reply, flagged = outcomes['free']
    if not reply['ok'] and reply['errno'] in (errno.ENOSYS, errno.EOPNOTSUPP, errno.ENOTTY):
        pytest.skip(f'{way} is not available here: {reply["message"]}')
    assert reply['ok'] and flagged, reply
    reply, flagged = outcomes['jail']
    assert refused(reply) and not flagged, reply


# ------------------------------------------------------------------------------------------------ others' files
# Escaped code taking a lease or a lock on a file it may only read, and what the other process then finds.
LEASE_AND_LOCKS = {
    'read lease': ('import fcntl, os\nfd = os.open(P, os.O_RDONLY)\nfcntl.fcntl(fd, fcntl.F_SETLEASE, fcntl.F_RDLCK)',
                   lambda path: os.close(os.open(path, os.O_WRONLY | os.O_NONBLOCK))),
    'flock': ('import fcntl, os\nfd = os.open(P, os.O_RDONLY)\nfcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)',
              lambda path: _locked_with(path, lambda fd: fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB))),
    'fcntl lock': ('import fcntl, os\nfd = os.open(P, os.O_RDONLY)\nfcntl.lockf(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)',
                   lambda path: _locked_with(path, lambda fd: fcntl.lockf(fd, fcntl.LOCK_EX | fcntl.LOCK_NB))),
}


def _locked_with(path: Path, lock: Callable[[int], None]) -> None:
    fd = os.open(path, os.O_RDWR)
    try:
        lock(fd)
    finally:
        os.close(fd)


@pytest.mark.parametrize('kind', LEASE_AND_LOCKS)
def test_an_escaped_program_blocks_no_writer_of_a_file_it_reads(start, tmp_path, kind):
    """A lease makes every writer wait up to lease-break-time (45 s), a lock blocks every locker."""
    attack, writer = LEASE_AND_LOCKS[kind]
    for mode in ('free', 'jail'):
        path = tmp_path / f'{mode}.txt'
        path.write_text('shared')
        child = start(mode)  # a child of its own: a broken lease signals its holder, a lock lives with it
        reply = child.run(f'P = {str(path)!r}\n{attack}')
        if mode == 'free':
            assert reply['ok'], reply
            with pytest.raises(BlockingIOError):
                writer(path)
        else:
            assert refused(reply), reply
            writer(path)  # nothing in the way


# ------------------------------------------------------------------------------------------------ the terminal
@pytest.fixture
def terminal() -> Iterator[int]:
    """The follower side of a new pseudo-terminal, as the node's terminal would be inherited."""
    controller, follower = os.openpty()
    yield follower
    os.close(controller)
    os.close(follower)


def test_an_escaped_program_changes_no_mode_or_size_of_an_inherited_terminal(start, terminal):
    settings = bytearray(fcntl.ioctl(terminal, termios.TCGETS, bytes(64)))
    struct.pack_into('I', settings, 12, struct.unpack_from('I', settings, 12)[0] & ~termios.ECHO)  # c_lflag
    code = (f'import fcntl, struct\nfcntl.ioctl({terminal}, {termios.TCSETS}, {bytes(settings)!r})\n'
            f"fcntl.ioctl({terminal}, {termios.TIOCSWINSZ}, struct.pack('HHHH', 11, 22, 0, 0))")

    def state() -> tuple[bool, tuple[int, ...]]:
        size = struct.unpack('HHHH', fcntl.ioctl(terminal, termios.TIOCGWINSZ, bytes(8)))
        return bool(termios.tcgetattr(terminal)[3] & termios.ECHO), size[:2]

    before = state()
    assert refused(start('jail', (terminal,)).run(code))
    assert state() == before
    assert start('free', (terminal,)).run(code)['ok']
    assert state() == (False, (11, 22))


def test_the_jailed_process_sees_no_terminal(start, terminal):
    code = f'import os\nresult = [os.isatty({terminal}), os.isatty(0)]'
    assert start('free', (terminal,)).run(code) == {'ok': True, 'result': [True, False]}
    assert start('jail', (terminal,)).run(code) == {'ok': True, 'result': [False, False]}  # TCGETS: ENOTTY


def test_the_sandbox_process_gets_no_terminal_of_the_node(tmp_path):
    """lmp_node started from a terminal: the sandbox process' stdin, stdout and stderr are not that terminal, and its
    log line still reaches it (through the pipe the node copies)."""
    node = ('import os, sys\nfrom cap_lmp.isolated_engine import IsolatedEngine\n'
            'from cap_lmp.testing.toy_domain import build_engine\n'
            'engine = IsolatedEngine(build_engine, {}, None)\n'
            "links = [os.readlink(f'/proc/{engine.pid}/fd/{fd}') for fd in range(3)]\n"
            "print('LINKS', *links, flush=True)\nengine.close()\n")
    controller, follower = os.openpty()
    env = {**os.environ, 'PYTHONPATH': os.pathsep.join(p for p in sys.path if p)}
    process = subprocess.Popen([sys.executable, '-c', node], stdin=follower, stdout=follower, stderr=follower,
                               env=env, start_new_session=True)
    os.close(follower)
    output = b''
    try:
        while True:
            try:
                chunk = os.read(controller, 4096)
            except OSError:  # EIO: the node and everything it started closed the terminal
                break
            if not chunk:
                break
            output += chunk
    finally:
        os.close(controller)
        assert process.wait(timeout=REPLY_TIMEOUT_S) == 0, output
    text = output.decode(errors='replace')
    links = next(line for line in text.splitlines() if line.startswith('LINKS')).split()[1:]
    assert links[:2] == ['/dev/null', '/dev/null'] and links[2].startswith('pipe:'), links
    assert 'sandbox jail entered' in text  # the log, copied by the node to its terminal


# ------------------------------------------------------------------------------------------------ watches, sync, pidfds
def test_an_escaped_program_watches_no_file(shared, tmp_path):
    code = (f'{LIBC}fd = check(libc.inotify_init1(0))\n'
            f'result = check(libc.inotify_add_watch(fd, {str(tmp_path).encode()!r}, 0xFFF)) > 0')
    assert shared('free').run(code) == {'ok': True, 'result': True}
    assert refused(shared('jail').run(code))


def test_an_escaped_program_cannot_sync_the_file_systems(shared):
    code = f'{LIBC}result = check(libc.syscall({jail.syscall_number("sync")}))'
    assert shared('free').run(code) == {'ok': True, 'result': 0}
    assert refused(shared('jail').run(code))


def test_an_escaped_program_opens_no_pidfd(shared, bystander):
    code = f'import os\nresult = os.pidfd_open({bystander.pid}) > 0'
    assert shared('free').run(code) == {'ok': True, 'result': True}
    assert refused(shared('jail').run(code))
    assert bystander.poll() is None


# ------------------------------------------------------------------------------------------------ reads
def _readable_by_the_node(path: str) -> str:
    try:
        open(path, 'rb').close()
    except OSError as error:
        pytest.skip(f'{path} is not readable here either: {error}')
    return path


READS = {
    'a file of the user in another folder': lambda tmp_path: str(tmp_path / 'secret.txt'),
    '/etc/shadow': lambda tmp_path: _readable_by_the_node('/etc/shadow'),
    "the node's /proc status": lambda tmp_path: f'/proc/{os.getpid()}/status',
}


@pytest.mark.parametrize('what', READS)
def test_an_escaped_program_reads_only_what_the_sandbox_needs(shared, tmp_path, what):
    (tmp_path / 'secret.txt').write_text('hunter2')
    code = f'result = len(open({READS[what](tmp_path)!r}, "rb").read()) > 0'
    assert shared('free').run(code) == {'ok': True, 'result': True}
    assert refused(shared('jail').run(code))


def test_an_escaped_program_lists_no_home_directory(shared):
    home = os.path.expanduser('~')
    code = f'import os\nresult = len(os.listdir({home!r})) >= 0'
    assert shared('free').run(code) == {'ok': True, 'result': True}
    assert refused(shared('jail').run(code))
    readable = shared('jail').outcome['jail']['readable']
    assert readable and not any(path == home or home.startswith(path + os.sep) for path in readable)


# ------------------------------------------------------------------------------------------------ what must still work
def test_the_jailed_process_still_imports_and_reads_modules(start, tmp_path):
    (tmp_path / 'jail_probe.py').write_text('VALUE = 7\n')
    jailed = start('jail')  # a new one: none of these modules may have been imported before the jail
    lazy = ('numpy.polynomial', 'numpy.fft', 'shapely.ops', 'shapely.validation', 'decimal')
    code = (f'import sys\nnot_loaded = [m for m in {lazy!r} if m not in sys.modules]\n'
            'import numpy, numpy.polynomial, numpy.fft, shapely, shapely.ops, shapely.validation, decimal\n'
            f'sys.path.insert(0, {str(tmp_path)!r})\n'
            'try:\n    import jail_probe\n    probe = jail_probe.VALUE\nexcept ImportError:\n    probe = None\n'
            'line = shapely.geometry.LineString([(0, 0), (1, 0)])\n'
            'result = {"not_loaded": not_loaded, "poly": float(numpy.polynomial.Polynomial([1, 2])(3)),\n'
            '          "fft": float(abs(numpy.fft.fft(numpy.ones(8))[0])),\n'
            '          "area": round(shapely.ops.unary_union([line.buffer(0.5)]).area, 2),\n'
            '          "valid": shapely.validation.explain_validity(line), "third": str(decimal.Decimal(1) / 3)[:4],\n'
            '          "probe": probe, "source": open(numpy.__file__).read(200) != "",\n'
            '          "status": "VmSize" in open("/proc/self/status").read()}')
    reply = jailed.run(code)
    assert reply['ok'], reply
    result = reply['result']
    assert result['not_loaded'] == list(lazy)  # these really were imported inside the jail
    assert result['poly'] == 7.0 and result['fft'] == 8.0 and result['area'] == 1.78
    assert result['valid'] == 'Valid Geometry' and result['third'] == '0.33'
    assert result['source'] and result['status']
    assert result['probe'] is None  # a folder the jail does not grant: its modules cannot be read


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


# ------------------------------------------------------------------------------------------------ the allowlist
SCENE = {'red block': (-0.1, -0.4), 'blue block': (0.1, -0.45), 'red bowl': (-0.15, -0.65)}
# Commands and the model's answers: the toy domain's robot calls and nested LMP, NumPy's linear algebra and
# sampling, Shapely, growing memory, an error inside NumPy (its traceback), print() to the log.
WORKLOAD = {
    'put the red block in the red bowl': ("put_first_on_second('red block', 'red bowl')\n"
                                          "where = get_obj_pos('red block')\nsay(where)"),
    'ask the blocks': "blocks = parse_obj_name('the blocks', f'objects = {get_obj_names()}')\nsay(blocks)",
    '# the blocks.': "ret_val = [name for name in objects if 'block' in name]",
    'do linear algebra': ('a = np.random.normal(size=(40, 40)) + 10 * np.eye(40)\nvalues, vectors = np.linalg.eig(a)\n'
                          'u, s, vt = np.linalg.svd(a)\nx = np.linalg.solve(a, np.ones(40))\n'
                          'p = np.linalg.pinv(a)\npicked = np.random.choice(10, 3, replace=False)\n'
                          'say(round(float(np.linalg.det(a @ np.linalg.inv(a))), 6))\n'
                          'say(len(picked) + np.random.randint(1, 2) + int(np.random.rand() < 1))'),
    'draw with shapely': ('shape = Polygon([(0, 0), (1, 0), (1, 1)]).buffer(0.1)\n'
                          'merged = unary_union([shape, box(0.5, 0.5, 2, 2)])\n'
                          'turned = rotate(scale(translate(merged, 1, 1), 2, 2), 30)\n'
                          'near = nearest_points(turned, Point(9, 9))\nsay(round(merged.area, 3))'),
    'grow and shrink': 'rows = [[i] * 100000 for i in range(40)]\nsay(sum(len(row) for row in rows))\nrows = None',
    'fail inside numpy': 'x = np.linalg.inv(np.zeros((3, 3)))',
    'print a line': "print('from the program')",
}
WORKLOAD_SAID = ['[-0.15 -0.65]', "['red block', 'blue block']", '1.0', '5', '2.87', '4000000']


def run_workload(child_command: list[str]) -> None:
    """The workload through an IsolatedEngine whose sandbox process is `child_command`, checked as it ran."""
    world = ToyWorld.with_objects(SCENE)
    with ScriptedOpenAIServer(WORKLOAD) as server:
        engine = IsolatedEngine(toy_build_engine, world.api(),
                                OpenAICompatibleClient(server.base_url, 'scripted-model', timeout_s=10.0),
                                SandboxLimits(time_limit_s=60.0), child_command=child_command)
        try:
            results = {command: engine.run(command) for command in WORKLOAD if not command.startswith('#')}
        finally:
            engine.close()
    failed = {command: result.message for command, result in results.items()
              if result.success == command.startswith('fail')}
    assert failed == {}
    assert 'LinAlgError' in results['fail inside numpy'].message
    assert world.said == WORKLOAD_SAID


def test_the_allowlist_refuses_nothing_the_engine_numpy_and_shapely_need():
    with SyscallAudit('refusals') as audit:
        run_workload(audit.child_command)
        time.sleep(0.2)  # the supervisor's last answers
    assert audit.errors == []
    assert dict(audit.calls) == {}  # what the filter would have refused (each let through and counted here)


# Escaped code doing what a sandbox process may do: import lazily, NumPy (linear algebra, sampling, FFT), Shapely,
# a thread, a traceback, memory that grows and is given back, a clock, a sleep, randomness.
RAW_WORKLOAD = '''
import decimal, statistics, threading, time, traceback
import numpy, numpy.fft, numpy.polynomial, shapely, shapely.ops, shapely.validation
rng = numpy.random.default_rng()
a = rng.normal(size=(50, 50)) + 10 * numpy.eye(50)
numpy.linalg.eig(a), numpy.linalg.svd(a), numpy.linalg.inv(a), numpy.linalg.solve(a, numpy.ones(50))
numpy.random.seed()
numpy.random.choice(10, 3), numpy.random.rand(3), numpy.fft.fft(numpy.ones(64)), numpy.fft.rfft(numpy.ones(64))
line = shapely.geometry.LineString([(0, 0), (1, 0)])
shapely.ops.unary_union([line.buffer(0.5), shapely.geometry.box(0, 0, 2, 2)]), shapely.validation.explain_validity(line)
str(decimal.Decimal(1) / 3), statistics.mean([1, 2, 3]), time.sleep(0.001), time.thread_time(), time.time()
big = numpy.zeros((3000, 3000))
big = [str(i) for i in range(200000)]
grown = []
for i in range(300000):
    grown.append(i)
big = grown = None
thread = threading.Thread(target=sum, args=(range(1000),))
thread.start()
thread.join()
try:
    numpy.linalg.inv(numpy.zeros((3, 3)))
except Exception:
    result = len(traceback.format_exc())
'''


def permitted(name: str, detail: str) -> bool:
    """Whether the jail's filter lets call `name` with `detail` (syscall_audit.describe) through."""
    details = {'openat': ('read-only',), 'clone': ('thread',), 'clone3': ('',),
               'ioctl': ('TCGETS', *jail.IOCTLS_ALLOWED), 'fcntl': tuple(jail.FCNTLS_ALLOWED)}
    return name in jail.ALLOWED_CALLS or detail in details.get(name, ())


def test_the_measured_system_calls_are_those_the_allowlist_allows(start):
    """The measurement, kept: every system call the sandbox process makes once jailed (the workloads above, each
    call handed to the supervisor and let through), by name and checked argument, with the allowlist's verdict."""
    with SyscallAudit('all') as audit:
        child = start('audit_all', audit=audit)
        audit.take()  # the measurement starts after the jail
        reply = child.run(RAW_WORKLOAD)
        assert reply['ok'] and reply['result'] > 0, reply
        run_workload(audit.child_command)
        time.sleep(0.2)
        measured = audit.take()
    assert audit.errors == []
    print('\nsystem calls made in the jail (count, name, checked argument, allowed):')
    for (name, detail), count in sorted(measured.items()):
        print(f'{count:8d}  {name:18s} {detail:12s} {permitted(name, detail)}')
    unseen = sorted(set(jail.ALLOWED_CALLS) - {name for name, _ in measured})
    print(f'allowed, not seen here (kept for correctness, see jail._ALLOWED): {", ".join(unseen)}')
    assert {'read', 'write', 'openat', 'mmap', 'futex', 'getdents64'} <= {name for name, _ in measured}
    assert [call for call in measured if not permitted(*call)] == []


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
