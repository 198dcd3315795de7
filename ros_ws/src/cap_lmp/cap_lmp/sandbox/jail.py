"""The sandbox process' jail: the kernel, not Python, refuses file writes, sockets, exec and new processes.

The in-process sandbox (sandbox.py) refuses what it can see; a program that got past it (a bug there, a C
extension's side door, ctypes) runs with all the rights of the node's user. enter_jail() takes those rights away
for good, with two kernel mechanisms and a few lines of ctypes (no library): Landlock, which refuses access by
path, and a seccomp-BPF filter, which refuses system calls. It is entered once by the sandbox process
(engine_process.py) after its engine is built and its address-space limit set, while it runs one thread, before
the first program:

    from cap_lmp.sandbox.jail import enter_jail
    report = enter_jail()          # required: raises JailError if a layer cannot be applied

From then on, for that process and every thread it starts, whatever code runs (Python or C):

- **No file is written**: Landlock makes the whole tree read-only (reading files and listing directories are the
  only rights; writing, truncating, creating, removing, renaming, linking and device ioctls are refused, EACCES).
  The seccomp filter refuses the same independently of Landlock's version (EPERM), and what Landlock does not
  cover (mode, owner, times, extended attributes): open/openat with a write, create or truncate flag, creat,
  truncate/ftruncate/fallocate, mkdir, rmdir, unlink, rename, link, symlink, mknod, chmod, chown, utimes,
  set/remove xattr; openat2, whose flags a filter cannot read, fails with ENOSYS (callers fall back to openat).
- **No socket but its own**: socket, socketpair, connect, bind, listen, accept(4) fail (EPERM), and io_uring
  (which could open sockets and files without those calls) is refused. Landlock adds, where its ABI has them,
  refusal of every TCP bind/connect (ABI >= 4) and of connecting to abstract Unix sockets outside the jail
  (ABI >= 6); UDP and Unix sockets bound to a path rest on seccomp alone. The sockets the process inherited (its
  two socket pairs to the parent) and stderr keep working.
- **No exec**: execve and execveat are refused (seccomp, EPERM; Landlock too, EACCES: it handles EXECUTE and
  grants it nowhere). no_new_privs is set, so nothing can gain privileges.
- **No new process**: fork, vfork, clone without CLONE_THREAD and clone with a CLONE_NEW* (namespace) flag are
  refused (EPERM); clone3, whose flags a filter cannot read, fails with ENOSYS so that the C library starts
  threads with clone. Threads still start; a thread shares the process, so the parent's kill ends it too.
  unshare and setns are refused.
- **Other processes are out of reach**: ptrace, process_vm_readv/writev, pidfd_getfd, pidfd_send_signal, kcmp,
  process_madvise and tkill are refused; kill, tgkill and rt_(tg)sigqueueinfo only reach the process itself.
  Landlock (ABI >= 6) also scopes signals to the jail, and any Landlock domain refuses ptrace-mode access to
  processes outside it, so /proc/<pid>/mem, environ, fd/ of the parent or any other process cannot be read.
- **The limits stay**: setrlimit, and prlimit64 with a new limit, are refused (a root process could otherwise
  lift the address-space limit set before the jail); all capabilities are dropped (a process running as root
  keeps uid 0 and no capability); changes of uid/gid, scheduling priority, policy or CPU affinity are refused.
- **The terminal and the system**: ioctl TIOCSTI/TIOCLINUX (typing into the terminal the node was started
  from) and the administration calls (mount family, chroot, pivot_root, bpf, perf_event_open, userfaultfd,
  keyctl, modules, kexec, reboot, swap, clocks, hostname, syslog, acct, quotactl, open_by_handle_at,
  fanotify_init, personality, iopl/ioperm) are refused.

What it does not guarantee:

- **Reading**: every file the node's user may read stays readable (Python, NumPy and Shapely import
  submodules and shared libraries lazily from wherever they are installed): sources, configuration, other files
  of the same user (keys in ~/.ssh included), /proc/self, /sys and /proc entries not tied to another process.
  What the program reads can leave only through the parent, which checks every message (wire.py) but publishes
  the text of results and say() calls.
- **Another user**: the process keeps the node's uid (uid 0 without capabilities if the node runs as root);
  what that uid may read, it reads. For secrets on the machine, run the node as a user of its own.
- **CPU, memory and time** are bounded elsewhere: RLIMIT_AS (set before the jail) and the parent's deadline,
  stall and cancel checks, which kill the process group (isolated_engine.py).
- **Its own process**: it may spin, allocate up to its limit, run machine code of its own (ctypes, memfd), write
  to its inherited stderr (the parent's log), close or garble its own sockets (the parent then kills and
  restarts it). The jail holds for machine code too: the kernel checks every system call, whoever makes it.
- **The kernel**: a kernel bug in an allowed call is not contained. The seccomp filter knows the system call
  numbers of x86-64 and AArch64 only; any other architecture, or another ABI on these (x32, 32-bit compat), gets
  EPERM (x32) or a killed process (compat), and on an unknown architecture the filter is not installed (reported).
- **Threads started before enter_jail**: seccomp reaches them (TSYNC), but Landlock (ABI < 8) and the
  capability drop apply to the calling thread only; enter_jail therefore counts the threads and reports the jail
  as incomplete if there are others.

On a kernel without Landlock or seccomp the jail degrades honestly. Each guarantee above rests on seccomp (no
sockets, exec, processes, signals, limit changes; writes too), Landlock (writes again; other processes' /proc
entries) and the capability drop; Landlock's network rules (ABI 4) and scopes (ABI 6) are second layers, whose
absence is reported (JailReport.second_layers_missing) but leaves the jail complete. `enter_jail()` (required, the
default) raises JailError naming what could not be applied, after applying the rest; `enter_jail(required=False)`
returns the JailReport, whose `missing` says what does not hold. Both write one line to stderr (the parent's
log). Entering costs about 0.6 ms here (JailReport.seconds); the filter adds about 50 ns to a system call
(getppid: 0.22 -> 0.27 us), nothing measurable to a command.
"""
from __future__ import annotations

import ctypes
import errno as errno_codes
import os
import platform
import struct
import sys
import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

# ------------------------------------------------------------------------------------------------ kernel constants
PR_SET_NO_NEW_PRIVS = 38
PR_SET_SECCOMP = 22
SECCOMP_MODE_FILTER = 2
SECCOMP_SET_MODE_FILTER = 1
SECCOMP_FILTER_FLAG_TSYNC = 1
SECCOMP_RET_KILL_PROCESS = 0x80000000
SECCOMP_RET_ERRNO = 0x00050000
SECCOMP_RET_ALLOW = 0x7FFF0000

# Landlock system calls have the same numbers on every architecture.
_LANDLOCK_CREATE_RULESET, _LANDLOCK_ADD_RULE, _LANDLOCK_RESTRICT_SELF = 444, 445, 446
_LANDLOCK_CREATE_RULESET_VERSION = 1
_LANDLOCK_RULE_PATH_BENEATH = 1
_LANDLOCK_RESTRICT_SELF_TSYNC = 1 << 3  # ABI 8: the domain reaches every thread
_FS_READ_FILE, _FS_READ_DIR = 1 << 2, 1 << 3
_FS_ABI_1 = (1 << 13) - 1  # EXECUTE, WRITE_FILE, READ_FILE, READ_DIR, REMOVE_*, MAKE_* (13 rights)
_FS_REFER, _FS_TRUNCATE, _FS_IOCTL_DEV = 1 << 13, 1 << 14, 1 << 15  # ABI 2, 3, 5
_NET_BIND_TCP, _NET_CONNECT_TCP = 1 << 0, 1 << 1  # ABI 4
_SCOPE_ABSTRACT_UNIX_SOCKET, _SCOPE_SIGNAL = 1 << 0, 1 << 1  # ABI 6
_READ_ONLY = _FS_READ_FILE | _FS_READ_DIR

_CAPABILITY_VERSION_3 = 0x20080522
_CLONE_THREAD = 0x00010000
_CLONE_NEW_NAMESPACES = 0x7E020080  # NEWNS, NEWCGROUP, NEWUTS, NEWIPC, NEWUSER, NEWPID, NEWNET, NEWTIME
_OPEN_WRITE_FLAGS = os.O_WRONLY | os.O_RDWR | os.O_CREAT | os.O_TRUNC  # O_TMPFILE needs a write flag too
_TIOCSTI, _TIOCLINUX = 0x5412, 0x541C
_X32_SYSCALL_BIT = 0x40000000

# name: (x86-64, AArch64) system call numbers; None where the architecture has no such call.
_SYSCALLS: dict[str, tuple[int | None, int | None]] = {
    # the file system
    'open': (2, None), 'openat': (257, 56), 'openat2': (437, 437), 'creat': (85, None),
    'truncate': (76, 45), 'ftruncate': (77, 46), 'fallocate': (285, 47),
    'rename': (82, None), 'renameat': (264, 38), 'renameat2': (316, 276),
    'mkdir': (83, None), 'mkdirat': (258, 34), 'rmdir': (84, None),
    'link': (86, None), 'linkat': (265, 37), 'unlink': (87, None), 'unlinkat': (263, 35),
    'symlink': (88, None), 'symlinkat': (266, 36), 'mknod': (133, None), 'mknodat': (259, 33),
    'chmod': (90, None), 'fchmod': (91, 52), 'fchmodat': (268, 53), 'fchmodat2': (452, 452),
    'chown': (92, None), 'fchown': (93, 55), 'lchown': (94, None), 'fchownat': (260, 54),
    'utime': (132, None), 'utimes': (235, None), 'utimensat': (280, 88), 'futimesat': (261, None),
    'setxattr': (188, 5), 'lsetxattr': (189, 6), 'fsetxattr': (190, 7), 'setxattrat': (463, 463),
    'removexattr': (197, 14), 'lremovexattr': (198, 15), 'fremovexattr': (199, 16), 'removexattrat': (466, 466),
    # sockets, and io_uring which can do without the socket and file calls
    'socket': (41, 198), 'socketpair': (53, 199), 'connect': (42, 203), 'bind': (49, 200),
    'listen': (50, 201), 'accept': (43, 202), 'accept4': (288, 242),
    'io_uring_setup': (425, 425), 'io_uring_enter': (426, 426), 'io_uring_register': (427, 427),
    # programs and processes
    'execve': (59, 221), 'execveat': (322, 281), 'uselib': (134, None),
    'fork': (57, None), 'vfork': (58, None), 'clone': (56, 220), 'clone3': (435, 435),
    'unshare': (272, 97), 'setns': (308, 268),
    # other processes
    'ptrace': (101, 117), 'process_vm_readv': (310, 270), 'process_vm_writev': (311, 271),
    'pidfd_getfd': (438, 438), 'pidfd_send_signal': (424, 424), 'kcmp': (312, 272),
    'process_madvise': (440, 440), 'process_mrelease': (448, 448), 'tkill': (200, 130),
    'kill': (62, 129), 'tgkill': (234, 131), 'rt_sigqueueinfo': (129, 138), 'rt_tgsigqueueinfo': (297, 240),
    'migrate_pages': (256, 238), 'move_pages': (279, 239),
    # limits, identity, scheduling
    'setrlimit': (160, 164), 'prlimit64': (302, 261),
    'setuid': (105, 146), 'setgid': (106, 144), 'setreuid': (113, 145), 'setregid': (114, 143),
    'setresuid': (117, 147), 'setresgid': (119, 149), 'setgroups': (116, 159),
    'setfsuid': (122, 151), 'setfsgid': (123, 152),
    'setpriority': (141, 140), 'ioprio_set': (251, 30), 'sched_setaffinity': (203, 122),
    'sched_setscheduler': (144, 119), 'sched_setparam': (142, 118), 'sched_setattr': (314, 274),
    # the terminal and the system
    'ioctl': (16, 29),
    'mount': (165, 40), 'umount2': (166, 39), 'pivot_root': (155, 41), 'chroot': (161, 51),
    'move_mount': (429, 429), 'open_tree': (428, 428), 'fsopen': (430, 430), 'fsmount': (432, 432),
    'fsconfig': (431, 431), 'fspick': (433, 433), 'mount_setattr': (442, 442), 'open_tree_attr': (467, 467),
    'bpf': (321, 280), 'perf_event_open': (298, 241), 'userfaultfd': (323, 282),
    'keyctl': (250, 219), 'add_key': (248, 217), 'request_key': (249, 218),
    'init_module': (175, 105), 'finit_module': (313, 273), 'delete_module': (176, 106),
    'kexec_load': (246, 104), 'kexec_file_load': (320, 294), 'reboot': (169, 142),
    'swapon': (167, 224), 'swapoff': (168, 225), 'iopl': (172, None), 'ioperm': (173, None),
    'name_to_handle_at': (303, 264), 'open_by_handle_at': (304, 265), 'acct': (163, 89), 'quotactl': (179, 60),
    'settimeofday': (164, 170), 'clock_settime': (227, 112), 'clock_adjtime': (305, 266), 'adjtimex': (159, 171),
    'sethostname': (170, 161), 'setdomainname': (171, 162), 'syslog': (103, 116), 'vhangup': (153, 58),
    'fanotify_init': (300, 262), 'personality': (135, 92),
    # allowed, named for the tests that make a kernel without them
    'seccomp': (317, 277), 'prctl': (157, 167), 'landlock_create_ruleset': (444, 444),
}
# Refused outright (EPERM). The calls below with an argument check are handled apart.
_REFUSED = (
    'creat', 'truncate', 'ftruncate', 'fallocate', 'rename', 'renameat', 'renameat2', 'mkdir', 'mkdirat', 'rmdir',
    'link', 'linkat', 'unlink', 'unlinkat', 'symlink', 'symlinkat', 'mknod', 'mknodat', 'chmod', 'fchmod',
    'fchmodat', 'fchmodat2', 'chown', 'fchown', 'lchown', 'fchownat', 'utime', 'utimes', 'utimensat', 'futimesat',
    'setxattr', 'lsetxattr', 'fsetxattr', 'setxattrat', 'removexattr', 'lremovexattr', 'fremovexattr',
    'removexattrat',
    'socket', 'socketpair', 'connect', 'bind', 'listen', 'accept', 'accept4',
    'io_uring_setup', 'io_uring_enter', 'io_uring_register',
    'execve', 'execveat', 'uselib', 'fork', 'vfork', 'unshare', 'setns',
    'ptrace', 'process_vm_readv', 'process_vm_writev', 'pidfd_getfd', 'pidfd_send_signal', 'kcmp',
    'process_madvise', 'process_mrelease', 'tkill', 'migrate_pages', 'move_pages',
    'setrlimit', 'setuid', 'setgid', 'setreuid', 'setregid', 'setresuid', 'setresgid', 'setgroups', 'setfsuid',
    'setfsgid', 'setpriority', 'ioprio_set', 'sched_setaffinity', 'sched_setscheduler', 'sched_setparam',
    'sched_setattr',
    'mount', 'umount2', 'pivot_root', 'chroot', 'move_mount', 'open_tree', 'fsopen', 'fsmount', 'fsconfig',
    'fspick', 'mount_setattr', 'open_tree_attr', 'bpf', 'perf_event_open', 'userfaultfd', 'keyctl', 'add_key',
    'request_key', 'init_module', 'finit_module', 'delete_module', 'kexec_load', 'kexec_file_load', 'reboot',
    'swapon', 'swapoff', 'iopl', 'ioperm', 'name_to_handle_at', 'open_by_handle_at', 'acct', 'quotactl',
    'settimeofday', 'clock_settime', 'clock_adjtime', 'adjtimex', 'sethostname', 'setdomainname', 'syslog',
    'vhangup', 'fanotify_init', 'personality',
)
# Fail with ENOSYS: the C library then uses a call the filter can check (clone, openat).
_UNSUPPORTED = ('clone3', 'openat2')
_SIGNALS_TO_SELF_ONLY = ('kill', 'tgkill', 'rt_sigqueueinfo', 'rt_tgsigqueueinfo')
# AUDIT_ARCH_* (EM_* | 64-bit | little-endian) and which column of _SYSCALLS it reads.
_ARCHITECTURES = {'x86_64': (0xC000003E, 0), 'aarch64': (0xC00000B7, 1)}


class JailError(RuntimeError):
    """The jail could not be entered completely, and the caller required it."""


@dataclass(frozen=True)
class JailReport:
    """What enter_jail applied, and what it could not (each with the reason)."""

    applied: tuple[str, ...]
    # Layers a guarantee of the module docstring rests on, not applied: the jail is incomplete.
    missing: tuple[str, ...]
    # Second layers this kernel lacks (older Landlock ABIs); seccomp holds those guarantees without them.
    second_layers_missing: tuple[str, ...]
    landlock_abi: int  # 0: no Landlock
    seconds: float

    @property
    def complete(self) -> bool:
        return not self.missing

    def summary(self) -> str:
        applied = '; '.join(self.applied) or 'nothing'
        timing = f'{self.seconds * 1e3:.1f} ms'
        if self.complete:
            lacking = f' (the kernel lacks {"; ".join(self.second_layers_missing)})' \
                if self.second_layers_missing else ''
            return f'sandbox jail entered in {timing}: {applied}{lacking}'
        return f'sandbox jail INCOMPLETE (entered in {timing}): missing {"; ".join(self.missing)}; applied {applied}'


@dataclass
class _Outcome:
    applied: list[str] = field(default_factory=list)
    missing: list[str] = field(default_factory=list)
    second_layers_missing: list[str] = field(default_factory=list)


# ------------------------------------------------------------------------------------------------ system calls
_libc = ctypes.CDLL(None, use_errno=True)
_libc.syscall.restype = ctypes.c_long
_libc.prctl.argtypes = [ctypes.c_int, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong]


def _call(result: int, what: str) -> int:
    if result < 0:
        code = ctypes.get_errno()
        raise OSError(code, f'{what}: {os.strerror(code)}')
    return result


def _syscall(number: int, *args: object) -> int:
    # syscall() is variadic and reads every argument as a long: widen plain integers.
    return _libc.syscall(ctypes.c_long(number), *(ctypes.c_long(a) if isinstance(a, int) else a for a in args))


class _RulesetAttr(ctypes.Structure):
    _fields_ = [('handled_access_fs', ctypes.c_uint64), ('handled_access_net', ctypes.c_uint64),
                ('scoped', ctypes.c_uint64)]


class _PathBeneathAttr(ctypes.Structure):
    _pack_ = 1  # the kernel's struct is packed: 12 bytes
    _fields_ = [('allowed_access', ctypes.c_uint64), ('parent_fd', ctypes.c_int32)]


class _SockFilter(ctypes.Structure):
    _fields_ = [('code', ctypes.c_uint16), ('jt', ctypes.c_uint8), ('jf', ctypes.c_uint8), ('k', ctypes.c_uint32)]


class _SockFprog(ctypes.Structure):
    _fields_ = [('len', ctypes.c_ushort), ('filter', ctypes.POINTER(_SockFilter))]


def landlock_abi() -> int:
    """The kernel's Landlock ABI version, 0 if Landlock is absent, disabled or refused (e.g. by a container)."""
    version = _syscall(_LANDLOCK_CREATE_RULESET, None, ctypes.c_size_t(0),
                       ctypes.c_uint32(_LANDLOCK_CREATE_RULESET_VERSION))
    return max(int(version), 0)


def _thread_count() -> int:
    try:
        return len(os.listdir('/proc/self/task'))
    except OSError:
        import threading
        return threading.active_count()


# ------------------------------------------------------------------------------------------------ Landlock
def _apply_landlock(abi: int, threads: int, outcome: _Outcome) -> None:
    """The whole tree read-only; TCP and (by scope) abstract Unix sockets and signals confined to the jail."""
    if abi < 1:
        outcome.missing.append('Landlock (not available on this kernel; seccomp still keeps files read-only, '
                               'but other processes\' /proc entries stay readable)')
        return
    handled_fs = _FS_ABI_1 | (_FS_REFER if abi >= 2 else 0) | (_FS_TRUNCATE if abi >= 3 else 0) \
        | (_FS_IOCTL_DEV if abi >= 5 else 0)
    attr = _RulesetAttr(handled_fs, (_NET_BIND_TCP | _NET_CONNECT_TCP) if abi >= 4 else 0,
                        (_SCOPE_ABSTRACT_UNIX_SOCKET | _SCOPE_SIGNAL) if abi >= 6 else 0)
    ruleset = root = -1
    try:
        ruleset = _call(_syscall(_LANDLOCK_CREATE_RULESET, ctypes.byref(attr), ctypes.c_size_t(ctypes.sizeof(attr)),
                                 ctypes.c_uint32(0)), 'landlock_create_ruleset')
        root = os.open('/', os.O_PATH | os.O_CLOEXEC)
        rule = _PathBeneathAttr(_READ_ONLY, root)
        _call(_syscall(_LANDLOCK_ADD_RULE, ruleset, _LANDLOCK_RULE_PATH_BENEATH, ctypes.byref(rule),
                       ctypes.c_uint32(0)), 'landlock_add_rule')
        flags = _LANDLOCK_RESTRICT_SELF_TSYNC if abi >= 8 else 0
        _call(_syscall(_LANDLOCK_RESTRICT_SELF, ruleset, ctypes.c_uint32(flags)), 'landlock_restrict_self')
    except OSError as error:
        outcome.missing.append(f'Landlock ({error})')
        return
    finally:
        for fd in (ruleset, root):
            if fd >= 0:
                os.close(fd)
    outcome.applied.append(f'file system read-only (Landlock ABI {abi})')
    if threads > 1 and abi < 8:
        outcome.missing.append(f'Landlock for the {threads - 1} other thread(s) already running (ABI {abi} '
                               f'restricts the calling thread only)')
    if abi >= 4:
        outcome.applied.append('TCP bind/connect refused (Landlock)')
    else:
        outcome.second_layers_missing.append(f'Landlock network rules (ABI {abi} < 4)')
    if abi >= 6:
        outcome.applied.append('signals and abstract Unix sockets scoped to the jail (Landlock)')
    else:
        outcome.second_layers_missing.append(f'Landlock scopes (ABI {abi} < 6)')


# ------------------------------------------------------------------------------------------------ seccomp
def _ld(offset: int) -> tuple:
    return ('ld', offset)


def assemble(program: Sequence[tuple]) -> list[tuple[int, int, int, int]]:
    """Classic BPF from ('label', name), ('ld', offset), ('jeq'|'jset'|'jge', k, true, false), ('ret', k).

    Jump targets are label names or None for the next instruction.
    """
    labels: dict[str, int] = {}
    position = 0
    for item in program:
        if item[0] == 'label':
            labels[item[1]] = position
        else:
            position += 1
    codes = {'ld': 0x20, 'jeq': 0x15, 'jge': 0x35, 'jset': 0x45, 'ret': 0x06}  # BPF_LD|W|ABS, JMP|..|K, RET|K
    out: list[tuple[int, int, int, int]] = []
    for item in program:
        if item[0] == 'label':
            continue
        here = len(out)

        def offset(target: str | None) -> int:
            if target is None:
                return 0
            distance = labels[target] - here - 1
            if not 0 <= distance <= 255:
                raise ValueError(f'BPF jump to {target} out of range')
            return distance

        if item[0] in ('ld', 'ret'):
            out.append((codes[item[0]], 0, 0, item[1]))
        else:
            out.append((codes[item[0]], offset(item[2]), offset(item[3]), item[1]))
    return out


def syscall_number(name: str, machine: str | None = None) -> int | None:
    """The number of system call `name` on `machine` (this one by default); None where it has no such call."""
    machine = machine or platform.machine()
    return _SYSCALLS[name][_ARCHITECTURES[machine][1]] if machine in _ARCHITECTURES else None


def seccomp_program(machine: str, own_pid: int) -> list[tuple[int, int, int, int]]:
    """The jail's filter for `machine` (platform.machine()); ValueError for an architecture it does not know."""
    if machine not in _ARCHITECTURES:
        raise ValueError(f'no system call table for {machine}')
    audit_arch, column = _ARCHITECTURES[machine]

    def numbers(names: Sequence[str]) -> list[int]:
        return [n for n in (_SYSCALLS[name][column] for name in names) if n is not None]

    def arg(index: int, high: bool = False) -> tuple:
        return _ld(16 + 8 * index + (4 if high else 0))  # seccomp_data.args, little-endian halves

    program: list[tuple] = [_ld(4), ('jeq', audit_arch, None, 'kill'), _ld(0)]
    if machine == 'x86_64':  # the x32 ABI shares AUDIT_ARCH_X86_64 with its own numbers
        program.append(('jge', _X32_SYSCALL_BIT, 'deny', None))
    program += [('jeq', n, 'deny', None) for n in numbers(_REFUSED)]
    program += [('jeq', n, 'enosys', None) for n in numbers(_UNSUPPORTED)]
    program += [('jeq', n, 'clone', None) for n in numbers(['clone'])]
    program += [('jeq', n, 'signal', None) for n in numbers(_SIGNALS_TO_SELF_ONLY)]
    program += [('jeq', n, 'prlimit', None) for n in numbers(['prlimit64'])]
    program += [('jeq', n, 'ioctl', None) for n in numbers(['ioctl'])]
    program += [('jeq', n, 'open_flags_1', None) for n in numbers(['open'])]
    program += [('jeq', n, 'open_flags_2', None) for n in numbers(['openat'])]
    program += [
        ('ret', SECCOMP_RET_ALLOW),
        ('label', 'clone'), arg(0), ('jset', _CLONE_NEW_NAMESPACES, 'deny', None),
        ('jset', _CLONE_THREAD, 'allow', 'deny'),
        ('label', 'signal'), arg(0), ('jeq', own_pid, 'allow', 'deny'),  # the kernel reads pid_t: the low half
        ('label', 'prlimit'), arg(2), ('jeq', 0, None, 'deny'), arg(2, high=True), ('jeq', 0, 'allow', 'deny'),
        ('label', 'ioctl'), arg(1), ('jeq', _TIOCSTI, 'deny', None), ('jeq', _TIOCLINUX, 'deny', 'allow'),
        ('label', 'open_flags_1'), arg(1), ('jset', _OPEN_WRITE_FLAGS, 'deny', 'allow'),
        ('label', 'open_flags_2'), arg(2), ('jset', _OPEN_WRITE_FLAGS, 'deny', 'allow'),
        ('label', 'allow'), ('ret', SECCOMP_RET_ALLOW),
        ('label', 'deny'), ('ret', SECCOMP_RET_ERRNO | errno_codes.EPERM),
        ('label', 'enosys'), ('ret', SECCOMP_RET_ERRNO | errno_codes.ENOSYS),
        ('label', 'kill'), ('ret', SECCOMP_RET_KILL_PROCESS),
    ]
    return assemble(program)


def install_seccomp(program: Sequence[tuple[int, int, int, int]]) -> None:
    """Install a BPF program on every thread of the process (no_new_privs must be set). OSError on failure."""
    filters = (_SockFilter * len(program))(*(_SockFilter(*instruction) for instruction in program))
    prog = _SockFprog(len(program), filters)
    number = syscall_number('seccomp')
    result = -1
    if number is not None:
        result = _syscall(number, ctypes.c_uint(SECCOMP_SET_MODE_FILTER), ctypes.c_uint(SECCOMP_FILTER_FLAG_TSYNC),
                          ctypes.byref(prog))
        if result > 0:
            raise OSError(errno_codes.EBUSY, f'seccomp: thread {result} could not be synchronised')
    if result < 0:  # a kernel before seccomp(2): prctl reaches the calling thread only
        _call(_libc.prctl(PR_SET_SECCOMP, SECCOMP_MODE_FILTER, ctypes.addressof(prog), 0, 0), 'seccomp')


def _apply_seccomp(outcome: _Outcome) -> None:
    machine = platform.machine()
    try:
        program = seccomp_program(machine, os.getpid())
        install_seccomp(program)
    except (ValueError, OSError) as error:
        outcome.missing.append(f'seccomp ({error}): sockets, new processes, signals and mode changes are not '
                               f'refused')
        return
    outcome.applied.append(f'no sockets, exec, new processes, writes or signals to others (seccomp, '
                           f'{len(program)} instructions)')


def _drop_capabilities(threads: int, outcome: _Outcome) -> None:
    header = struct.pack('=Ii', _CAPABILITY_VERSION_3, 0)
    data = bytes(24)  # two {effective, permitted, inheritable} words, all empty
    if _libc.capset(header, data) != 0:
        outcome.missing.append(f'capability drop ({os.strerror(ctypes.get_errno())})')
        return
    outcome.applied.append('no capabilities')
    if threads > 1:
        outcome.missing.append(f'capability drop for the {threads - 1} other thread(s) already running')


# ------------------------------------------------------------------------------------------------ entry
def _stderr_line(line: str) -> None:
    sys.stderr.write(line + '\n')
    sys.stderr.flush()


def enter_jail(required: bool = True, log: Callable[[str], None] | None = _stderr_line) -> JailReport:
    """Jail this process for good (see the module docstring); call it once, from the only thread.

    required=True raises JailError unless the jail is complete (JailReport.missing is empty; what could be applied
    stays applied); required=False returns the report. Either way its summary, one line, goes to `log`.
    """
    started = time.perf_counter()
    outcome = _Outcome()
    threads = _thread_count()
    abi = landlock_abi()
    if _libc.prctl(PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0) != 0:
        outcome.missing.append(f'no_new_privs ({os.strerror(ctypes.get_errno())})')
    _apply_landlock(abi, threads, outcome)
    _drop_capabilities(threads, outcome)
    _apply_seccomp(outcome)  # last: the steps above make calls (open, prctl, capset) a filter could refuse
    report = JailReport(tuple(outcome.applied), tuple(outcome.missing), tuple(outcome.second_layers_missing), abi,
                        time.perf_counter() - started)
    if log is not None:
        log(report.summary())
    if required and not report.complete:
        raise JailError(report.summary())
    return report
