"""The jail's filter measured: which system calls a jailed process makes, or which the filter refuses it.

`enter_jail(audit='all' | 'refusals')` installs the jail with a seccomp notification descriptor: every system call
('all'), or every call the allowlist refuses ('refusals'), waits for a supervisor's answer. SyscallAudit is that
supervisor, in the parent (a test): it takes the descriptor from the jailed process (pidfd_getfd; the parent may,
the jailed process cannot reach out), records each call (its name, and for the calls the filter checks by argument,
that argument: the ioctl or fcntl command, clone's flags, open's flags) and lets it proceed, so that the process
runs as without the filter and the record is complete.

    with SyscallAudit('refusals') as audit:
        engine = IsolatedEngine(build_engine, api, client, child_command=audit.child_command)
        ...                                     # the workload
    audit.calls                                 # Counter: {('ioctl', 'TCSETS'): 1, ...}; empty: nothing refused

A process started otherwise is audited with `audit.attach(pid)` (it must have entered the jail with the audit).
`python -m cap_lmp.testing.syscall_audit <mode> <socket> <data fd> <control fd>` (audit.child_command) is the
sandbox process (engine_process.py) entering its jail with `audit=mode`, having told the supervisor its pid on
the Unix socket `socket`. Only tests start it: with a supervisor that lets calls proceed, the filter refuses nothing.
"""
from __future__ import annotations

import collections
import ctypes
import fcntl
import functools
import os
import select
import shutil
import socket
import struct
import sys
import tempfile
import threading
import time

from cap_lmp.sandbox import jail

# <linux/seccomp.h>: struct seccomp_notif (80 bytes) and seccomp_notif_resp (24 bytes), and their ioctls.
_NOTIF_RECV, _NOTIF_SEND = 0xC0502100, 0xC0182101
_NOTIF_SIZE = 80
_FLAG_CONTINUE = 1
_PIDFD_GETFD = 438
_LISTENER_LINK = 'anon_inode:seccomp notify'
_ATTACH_TIMEOUT_S = 30.0
# Names of the commands the tests and the side doors use, for a readable record.
IOCTL_NAMES = {0x5401: 'TCGETS', 0x5402: 'TCSETS', 0x5403: 'TCSETSW', 0x5413: 'TIOCGWINSZ', 0x5414: 'TIOCSWINSZ',
               0x5412: 'TIOCSTI', 0x541C: 'TIOCLINUX', 0x541B: 'FIONREAD', 0x5421: 'FIONBIO', 0x5450: 'FIONCLEX',
               0x5451: 'FIOCLEX', 0x80086601: 'FS_IOC_GETFLAGS', 0x40086602: 'FS_IOC_SETFLAGS',
               0x801C581F: 'FS_IOC_FSGETXATTR', 0x401C5820: 'FS_IOC_FSSETXATTR'}
FCNTL_NAMES = {0: 'F_DUPFD', 1: 'F_GETFD', 2: 'F_SETFD', 3: 'F_GETFL', 4: 'F_SETFL', 5: 'F_GETLK', 6: 'F_SETLK',
               7: 'F_SETLKW', 8: 'F_SETOWN', 9: 'F_GETOWN', 1024: 'F_SETLEASE', 1025: 'F_GETLEASE',
               1026: 'F_NOTIFY', 1030: 'F_DUPFD_CLOEXEC', 1031: 'F_SETPIPE_SZ', 1032: 'F_GETPIPE_SZ',
               36: 'F_OFD_GETLK', 37: 'F_OFD_SETLK', 38: 'F_OFD_SETLKW'}

_libc = ctypes.CDLL(None, use_errno=True)
_libc.syscall.restype = ctypes.c_long


def describe(name: str, args: tuple[int, ...]) -> str:
    """The argument the filter checks for call `name`, in words ('' for the calls it does not check)."""
    if name == 'ioctl':
        command = args[1] & 0xFFFFFFFF
        return IOCTL_NAMES.get(command, hex(command))
    if name == 'fcntl':
        command = args[1] & 0xFFFFFFFF
        return FCNTL_NAMES.get(command, str(command))
    if name == 'clone':
        return 'thread' if args[0] & 0x00010000 else f'process (flags {args[0]:#x})'
    if name in ('open', 'openat'):
        flags = args[1 if name == 'open' else 2] & 0xFFFFFFFF
        return 'write' if flags & (os.O_WRONLY | os.O_RDWR | os.O_CREAT | os.O_TRUNC) else 'read-only'
    if name in ('kill', 'tgkill'):
        return f'pid {ctypes.c_int32(args[0] & 0xFFFFFFFF).value}'
    return ''


class SyscallAudit:
    """The supervisor of jailed processes entered with `audit=mode`: records their calls, lets them proceed."""

    def __init__(self, mode: str = 'refusals') -> None:
        if mode not in jail.AUDIT_MODES or not mode:
            raise ValueError(f'mode must be "refusals" or "all", not {mode!r}')
        self.mode = mode
        self.calls: collections.Counter[tuple[str, str]] = collections.Counter()
        self.errors: list[str] = []  # processes it could not attach to
        self._lock = threading.Lock()
        self._stopped = threading.Event()
        self._threads: list[threading.Thread] = []
        self._folder = tempfile.mkdtemp(prefix='cap-syscall-audit-')
        self.address = os.path.join(self._folder, 'supervisor.sock')
        self._server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self._server.bind(self.address)
        self._server.listen(16)
        self._server.settimeout(0.2)
        self._start(self._accept)

    @property
    def child_command(self) -> list[str]:
        """IsolatedEngine's child_command for a sandbox process under this audit."""
        return [sys.executable, '-m', 'cap_lmp.testing.syscall_audit', self.mode, self.address]

    def attach(self, pid: int) -> None:
        """Supervise process `pid` (from the moment it has entered its jail; its calls wait until then)."""
        self._start(functools.partial(self._supervise, pid))

    def take(self) -> collections.Counter[tuple[str, str]]:
        """The calls recorded so far, and a fresh count."""
        with self._lock:
            calls, self.calls = self.calls, collections.Counter()
        return calls

    def close(self) -> None:
        self._stopped.set()
        for thread in self._threads:
            thread.join(timeout=5.0)
        self._server.close()
        shutil.rmtree(self._folder, ignore_errors=True)

    def __enter__(self) -> 'SyscallAudit':
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # -------------------------------------------------------------------------------------------- supervision
    def _start(self, target) -> None:
        thread = threading.Thread(target=target, name='syscall_audit', daemon=True)
        self._threads.append(thread)
        thread.start()

    def _accept(self) -> None:
        while not self._stopped.is_set():
            try:
                connection, _ = self._server.accept()
            except socket.timeout:
                continue
            except OSError:
                return
            with connection:
                connection.settimeout(5.0)
                try:
                    pid = int(connection.recv(32).decode().strip())
                except (OSError, ValueError):
                    continue
            self.attach(pid)

    def _listener(self, pid: int) -> int:
        """The notification descriptor of jailed process `pid`, copied into this process."""
        deadline = time.monotonic() + _ATTACH_TIMEOUT_S
        while time.monotonic() < deadline and not self._stopped.is_set():
            try:
                for name in os.listdir(f'/proc/{pid}/fd'):
                    try:
                        if os.readlink(f'/proc/{pid}/fd/{name}') != _LISTENER_LINK:
                            continue
                    except OSError:
                        continue
                    pidfd = os.pidfd_open(pid)
                    try:
                        fd = _libc.syscall(ctypes.c_long(_PIDFD_GETFD), ctypes.c_long(pidfd), ctypes.c_long(int(name)),
                                           ctypes.c_long(0))
                    finally:
                        os.close(pidfd)
                    if fd < 0:
                        raise OSError(ctypes.get_errno(), f'pidfd_getfd of process {pid}')
                    return fd
            except FileNotFoundError:
                raise OSError(f'process {pid} ended before it entered its jail') from None
            time.sleep(0.002)
        raise OSError(f'process {pid} did not enter a jail with an audit within {_ATTACH_TIMEOUT_S:.0f} s')

    def _supervise(self, pid: int) -> None:
        try:
            listener = self._listener(pid)
        except OSError as error:
            with self._lock:
                self.errors.append(str(error))
            return
        poller = select.poll()
        poller.register(listener, select.POLLIN)
        notification = bytearray(_NOTIF_SIZE)
        try:
            while not self._stopped.is_set():
                events = poller.poll(100)
                if any(event & (select.POLLHUP | select.POLLERR) for _, event in events):
                    return  # the process (every user of the filter) is gone
                if not events:
                    continue
                notification[:] = bytes(_NOTIF_SIZE)  # the kernel wants it zeroed
                try:
                    fcntl.ioctl(listener, _NOTIF_RECV, notification, True)
                except OSError:  # the caller was killed meanwhile
                    continue
                identifier, _, _, number, _, _ = struct.unpack_from('<QIIiIQ', notification)
                args = struct.unpack_from('<6Q', notification, 32)
                name = jail.syscall_name(number)
                with self._lock:
                    self.calls[(name, describe(name, args))] += 1
                try:
                    fcntl.ioctl(listener, _NOTIF_SEND, struct.pack('<QqiI', identifier, 0, 0, _FLAG_CONTINUE))
                except OSError:
                    continue
        finally:
            os.close(listener)


def main() -> None:
    """The sandbox process under audit: tell the supervisor this pid, then run engine_process with the audit."""
    mode, address = sys.argv[1], sys.argv[2]
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as connection:
        connection.connect(address)
        connection.sendall(f'{os.getpid()}\n'.encode())
    from cap_lmp import engine_process

    engine_process.enter_jail = functools.partial(jail.enter_jail, audit=mode)
    sys.argv = [sys.argv[0], *sys.argv[3:]]
    engine_process.main()


if __name__ == '__main__':
    main()
