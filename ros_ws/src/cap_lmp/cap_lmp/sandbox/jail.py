"""The sandbox process' jail: the kernel, not Python, lets it do only what it needs.

The in-process sandbox (sandbox.py) refuses what it can see; a program that got past it (a bug there, a C
extension's side door, ctypes) runs with all the rights of the node's user. enter_jail() takes those rights away
for good, with two kernel mechanisms and a few lines of ctypes (no library): Landlock, which grants access by
path, and a seccomp-BPF filter, which allows system calls by name. Both are lists of what is ALLOWED: a call or a
path nobody thought of is refused. It is entered once by the sandbox process (engine_process.py) after its engine
is built and its address-space limit set, while it runs one thread, before the first program:

    from cap_lmp.sandbox.jail import enter_jail
    report = enter_jail()          # required: raises JailError if a layer cannot be applied

From then on, for that process and every thread it starts, whatever code runs (Python or C):

- **Only the system calls it needs** (seccomp, _ALLOWED below, measured): reading files, its sockets and its log,
  memory, threads, its own signals, clocks and randomness. Every other call fails with EPERM. Some are allowed
  with their arguments checked: openat without a write, create or truncate flag; ioctl only FIONREAD,
  FIONBIO, FIOCLEX and FIONCLEX (TCGETS, the probe behind isatty(), answers ENOTTY: the process has no terminal);
  fcntl only F_GETFD, F_SETFD, F_GETFL, F_SETFL and F_DUPFD_CLOEXEC; clone only for a thread (CLONE_THREAD, no
  namespace flag); kill and tgkill only to itself. clone3, whose flags a filter cannot read, fails with ENOSYS, so
  that the C library starts threads with clone. Refused therefore, among everything else: writing, truncating,
  renaming, linking, changing modes, owners, times, extended attributes or inode flags (FS_IOC_SETFLAGS,
  FS_IOC_FSSETXATTR, file_setattr); sockets; exec; new processes; other processes (ptrace, process_vm_*,
  pidfd_open, pidfd_*); objects that outlive the process (System V shared memory, message queues and semaphores,
  POSIX message queues); memory outside the address space (memfd_create, pipes, io_uring); leases and locks on
  files others use (fcntl F_SETLEASE/F_SETLK, flock); watches (inotify, fanotify); sync; limits, identity,
  scheduling, the terminal (every tty ioctl but the TCGETS probe) and the administration calls.
- **Only the files it needs, read-only** (Landlock, readable_paths()): reading files and listing directories is
  granted beneath the interpreter's standard library and site-packages, the folders the process' modules came
  from (and their real places behind symbolic links, such as colcon's build/ links into src/), the shared
  libraries' folders and /etc/ld.so.cache, the time zone files, /dev/null, /dev/urandom and the process' own
  /proc/<pid>. Nothing else is readable: not the home directory, not the rest of /etc (/etc/shadow), not another
  process' /proc entries. Writing, creating, removing, renaming, linking, truncating, executing and device ioctls
  are granted nowhere (EACCES). A folder that is the home directory or holds it is never granted, even when a
  module was loaded from there.
- **No terminal**: the parent starts the process with stdin and stdout on /dev/null and stderr on a pipe it
  copies to its own log (isolated_engine.py), so no terminal's modes, size or input are within reach.
- **Memory has one bound**: RLIMIT_AS, set before the jail, bounds every mapping; memory that would not count
  (memfd, shared memory segments, message queues, pipe buffers) cannot be made, and setrlimit/prlimit64 are refused.
- **Other processes are out of reach**: no signal leaves the process (Landlock ABI >= 6 scopes signals as well),
  any Landlock domain refuses ptrace-mode access to processes outside it, and their /proc entries are not granted.
- **No privileges**: no_new_privs is set and every capability is dropped (a process running as root keeps uid 0
  and no capability).

What Landlock cannot express on any ABI up to 7, and what stays possible therefore:

- **Looking a path up**: stat (which every import needs: it looks at each candidate path) and open with O_PATH
  are not file accesses to Landlock; a program can learn whether /root/.ssh/id_rsa exists, its size and
  times, not its content. (readlink, access and chdir, not file accesses either, are not on the allowlist.)
- **Descriptors open before the jail** stay usable as they are: its two sockets and stderr (a pipe).

What it does not guarantee:

- **Another user**: the process keeps the node's uid (uid 0 without capabilities if the node runs as root); the
  folders above stay readable (the workspace's sources are there). For secrets inside them, run the node as a
  user of its own.
- **CPU, memory and time** are bounded elsewhere: RLIMIT_AS and the parent's deadline, stall and cancel checks,
  which kill the process group (isolated_engine.py).
- **Its own process**: it may spin, allocate up to its limit, run machine code of its own (ctypes), write to its
  log, close or garble its own sockets (the parent then kills and restarts it). The jail holds for machine code
  too: the kernel checks every system call, whoever makes it.
- **The kernel**: a kernel bug in an allowed call is not contained. The seccomp filter knows the system call
  numbers of x86-64 and AArch64 only; any other architecture, or another ABI on these (x32, 32-bit compat), gets
  EPERM (x32) or a killed process (compat), and on an unknown architecture the filter is not installed (reported).
- **Threads started before enter_jail**: seccomp reaches them (TSYNC), but Landlock (ABI < 8) and the
  capability drop apply to the calling thread only; enter_jail therefore counts the threads and reports the jail
  as incomplete if there are others.

How the allowlist was measured: `strace -f` of the sandbox processes of `cap bench codegen` (4 x 37 items),
`cap bench humaneval` (2 x 164), `cap bench reasoning` (3 x 51), the engine's tests with a sandbox process
(cap_lmp/test: test_isolated_engine, test_invoke, test_approval, test_outcome, test_limits, test_regeneration,
test_engine_options) and test_jail's workloads (lazy imports, NumPy linalg/random/FFT, Shapely, threads, the toy
domain's programs through IsolatedEngine), keeping the lines of each process after its
seccomp(SECCOMP_SET_MODE_FILTER) call and of the threads it started later; then the same workloads, the graph tests
of the four domains and the table-top benchmark's oracle episodes with the filter audited (below): nothing refused.
Seen: read, write, close, lseek, newfstatat, openat (read-only), getdents64, ioctl (TCGETS only), futex, mmap,
munmap, mprotect, madvise, brk, mremap, mbind (OpenBLAS's buffers), clone (threads; clone3 first), set_robust_list,
rseq, gettid, exit, rt_sigprocmask, rt_sigaction, clock_gettime, clock_nanosleep, getrandom. test_jail.py keeps the
method as a test: `enter_jail(audit='all')` hands every system call to a supervisor (seccomp user notification,
cap_lmp.testing.syscall_audit) that records it and lets it proceed, and the test fails, naming the call, when a
workload makes one the filter would refuse; `audit='refusals'` hands over only what the filter refuses
(test_jail.py, and cap_bench's test_the_jail_refuses_nothing_the_language_benchmarks_run).

On a kernel without Landlock or seccomp the jail degrades honestly. The guarantees above rest on seccomp (calls),
Landlock (paths; writes again) and the capability drop; Landlock's network rules (ABI 4) and scopes (ABI 6) are
second layers, whose absence is reported (JailReport.second_layers_missing) but leaves the jail complete.
`enter_jail()` (required, the default) raises JailError naming what could not be applied, after applying the rest;
`enter_jail(required=False)` returns the JailReport, whose `missing` says what does not hold. Both write one line
to stderr (the parent's log). Entering costs about 8 ms here (JailReport.seconds: most of it finding and granting
the ~50 readable paths); the filter adds about 30 ns to an allowed system call (getpid: 186 -> 218 ns), nothing
measurable to a command.
"""
from __future__ import annotations

import ctypes
import errno as errno_codes
import os
import platform
import struct
import sys
import sysconfig
import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

# ------------------------------------------------------------------------------------------------ kernel constants
PR_SET_NO_NEW_PRIVS = 38
PR_SET_SECCOMP = 22
SECCOMP_MODE_FILTER = 2
SECCOMP_SET_MODE_FILTER = 1
SECCOMP_FILTER_FLAG_TSYNC = 1
SECCOMP_FILTER_FLAG_NEW_LISTENER = 1 << 3
SECCOMP_FILTER_FLAG_TSYNC_ESRCH = 1 << 4  # with NEW_LISTENER: TSYNC reports failure as ESRCH, not a thread id
SECCOMP_RET_KILL_PROCESS = 0x80000000
SECCOMP_RET_ERRNO = 0x00050000
SECCOMP_RET_USER_NOTIF = 0x7FC00000
SECCOMP_RET_ALLOW = 0x7FFF0000
REFUSED = SECCOMP_RET_ERRNO | errno_codes.EPERM

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

_CAPABILITY_VERSION_3 = 0x20080522
_CLONE_THREAD = 0x00010000
_CLONE_NEW_NAMESPACES = 0x7E020080  # NEWNS, NEWCGROUP, NEWUTS, NEWIPC, NEWUSER, NEWPID, NEWNET, NEWTIME
_OPEN_WRITE_FLAGS = os.O_WRONLY | os.O_RDWR | os.O_CREAT | os.O_TRUNC  # O_TMPFILE needs a write flag too
_X32_SYSCALL_BIT = 0x40000000
# ioctl commands: the descriptor's own flags and byte count; TCGETS (isatty()) is answered ENOTTY.
_TCGETS = 0x5401
IOCTLS_ALLOWED = {'FIONREAD': 0x541B, 'FIONBIO': 0x5421, 'FIONCLEX': 0x5450, 'FIOCLEX': 0x5451}
# fcntl commands: the descriptor's flags and a copy of it; no locks, leases, owners, signals or notifications.
FCNTLS_ALLOWED = {'F_GETFD': 1, 'F_SETFD': 2, 'F_GETFL': 3, 'F_SETFL': 4, 'F_DUPFD_CLOEXEC': 1030}

# name: (x86-64, AArch64) system call numbers; None where the architecture has no such call. The calls the filter
# allows, and others it refuses that the tests and the audit name.
_SYSCALLS: dict[str, tuple[int | None, int | None]] = {
    # reading files, the process' sockets and log
    'read': (0, 63), 'write': (1, 64), 'readv': (19, 65), 'writev': (20, 66), 'pread64': (17, 67),
    'lseek': (8, 62), 'close': (3, 57), 'open': (2, None), 'openat': (257, 56), 'openat2': (437, 437),
    'stat': (4, None), 'fstat': (5, 80), 'lstat': (6, None), 'newfstatat': (262, None), 'fstatat': (None, 79),
    'statx': (332, 291), 'getdents64': (217, 61), 'readlink': (89, None), 'readlinkat': (267, 78),
    'access': (21, None), 'faccessat': (269, 48), 'faccessat2': (439, 439), 'getcwd': (79, 17),
    'ioctl': (16, 29), 'fcntl': (72, 25),
    # memory
    'brk': (12, 214), 'mmap': (9, 222), 'munmap': (11, 215), 'mremap': (25, 216), 'mprotect': (10, 226),
    'madvise': (28, 233), 'mbind': (237, 235),
    # threads, signals, clocks
    'futex': (202, 98), 'set_robust_list': (273, 99), 'rseq': (334, 293), 'gettid': (186, 178),
    'getpid': (39, 172), 'sched_yield': (24, 124), 'exit': (60, 93), 'exit_group': (231, 94),
    'rt_sigaction': (13, 134), 'rt_sigprocmask': (14, 135), 'rt_sigreturn': (15, 139), 'sigaltstack': (131, 132),
    'restart_syscall': (219, 128), 'kill': (62, 129), 'tgkill': (234, 131),
    'clock_gettime': (228, 113), 'clock_getres': (229, 114), 'clock_nanosleep': (230, 115),
    'nanosleep': (35, 101), 'gettimeofday': (96, 169), 'getrandom': (318, 278),
    'clone': (56, 220), 'clone3': (435, 435),
    # refused: the file system
    'creat': (85, None), 'truncate': (76, 45), 'ftruncate': (77, 46), 'fallocate': (285, 47),
    'rename': (82, None), 'renameat': (264, 38), 'renameat2': (316, 276),
    'mkdir': (83, None), 'mkdirat': (258, 34), 'rmdir': (84, None),
    'link': (86, None), 'linkat': (265, 37), 'unlink': (87, None), 'unlinkat': (263, 35),
    'symlink': (88, None), 'symlinkat': (266, 36), 'mknod': (133, None), 'mknodat': (259, 33),
    'chmod': (90, None), 'fchmod': (91, 52), 'fchmodat': (268, 53), 'fchmodat2': (452, 452),
    'chown': (92, None), 'fchown': (93, 55), 'lchown': (94, None), 'fchownat': (260, 54),
    'utime': (132, None), 'utimes': (235, None), 'utimensat': (280, 88), 'futimesat': (261, None),
    'setxattr': (188, 5), 'lsetxattr': (189, 6), 'fsetxattr': (190, 7), 'setxattrat': (463, 463),
    'removexattr': (197, 14), 'lremovexattr': (198, 15), 'fremovexattr': (199, 16), 'removexattrat': (466, 466),
    'file_getattr': (468, 468), 'file_setattr': (469, 469), 'flock': (73, 32), 'sync': (162, 81),
    'syncfs': (306, 267), 'inotify_init': (253, None), 'inotify_init1': (294, 26), 'inotify_add_watch': (254, 27),
    'fanotify_init': (300, 262), 'fanotify_mark': (301, 263),
    # refused: memory and objects outside the address space and the process
    'memfd_create': (319, 279), 'memfd_secret': (447, 447), 'pipe': (22, None), 'pipe2': (293, 59),
    'shmget': (29, 194), 'shmat': (30, 196), 'shmctl': (31, 195), 'shmdt': (67, 197),
    'msgget': (68, 186), 'msgsnd': (69, 189), 'msgrcv': (70, 188), 'msgctl': (71, 187),
    'semget': (64, 190), 'semop': (65, 193), 'semctl': (66, 191), 'semtimedop': (220, 192),
    'mq_open': (240, 180), 'mq_unlink': (241, 181), 'mq_timedsend': (242, 182), 'mq_timedreceive': (243, 183),
    'mq_notify': (244, 184), 'mq_getsetattr': (245, 185), 'mlock': (149, 228), 'mlockall': (151, 230),
    # refused: sockets, and io_uring which can do without the socket and file calls
    'socket': (41, 198), 'socketpair': (53, 199), 'connect': (42, 203), 'bind': (49, 200),
    'listen': (50, 201), 'accept': (43, 202), 'accept4': (288, 242), 'sendto': (44, 206), 'sendmsg': (46, 211),
    'io_uring_setup': (425, 425), 'io_uring_enter': (426, 426), 'io_uring_register': (427, 427),
    # refused: programs and processes
    'execve': (59, 221), 'execveat': (322, 281), 'uselib': (134, None), 'fork': (57, None), 'vfork': (58, None),
    'unshare': (272, 97), 'setns': (308, 268),
    'ptrace': (101, 117), 'process_vm_readv': (310, 270), 'process_vm_writev': (311, 271),
    'pidfd_open': (434, 434), 'pidfd_getfd': (438, 438), 'pidfd_send_signal': (424, 424), 'kcmp': (312, 272),
    'process_madvise': (440, 440), 'process_mrelease': (448, 448), 'tkill': (200, 130),
    'rt_sigqueueinfo': (129, 138), 'rt_tgsigqueueinfo': (297, 240), 'migrate_pages': (256, 238),
    'move_pages': (279, 239),
    # refused: limits, identity, scheduling
    'setrlimit': (160, 164), 'prlimit64': (302, 261),
    'setuid': (105, 146), 'setgid': (106, 144), 'setreuid': (113, 145), 'setregid': (114, 143),
    'setresuid': (117, 147), 'setresgid': (119, 149), 'setgroups': (116, 159),
    'setfsuid': (122, 151), 'setfsgid': (123, 152), 'capset': (126, 91),
    'setpriority': (141, 140), 'ioprio_set': (251, 30), 'sched_setaffinity': (203, 122),
    'sched_setscheduler': (144, 119), 'sched_setparam': (142, 118), 'sched_setattr': (314, 274),
    # refused: the system
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
    'personality': (135, 92), 'seccomp': (317, 277), 'prctl': (157, 167),
    'landlock_create_ruleset': (444, 444), 'landlock_add_rule': (445, 445), 'landlock_restrict_self': (446, 446),
}
# Allowed as they are, by what they are for (the filter compares read and write first, then these in order). Each was
# measured (see "How the allowlist was measured" above) but these, which keep the process correct where it cannot do
# without them: exit_group (the process ending), rt_sigreturn and restart_syscall (the return from a signal handler,
# the restart of a call a signal interrupted), getpid (raise() and abort(), with tgkill), pread64 (the dynamic
# loader reads the program headers of a library with it when they do not fit its first read: libc's and OpenBLAS's,
# seen before the jail; it reads no more than read and lseek do) and fstat and fstatat (other C libraries' and
# AArch64's names of the newfstatat seen here).
_ALLOWED: dict[str, tuple[str, ...]] = {
    'files Landlock lets it read, its two sockets and its log': (
        'read', 'write', 'newfstatat', 'fstatat', 'fstat', 'lseek', 'close', 'pread64', 'getdents64'),
    'threads and the process': ('futex', 'set_robust_list', 'rseq', 'gettid', 'getpid', 'exit', 'exit_group'),
    'memory, all of it within RLIMIT_AS': ('mmap', 'munmap', 'mprotect', 'madvise', 'brk', 'mremap', 'mbind'),
    'signals to itself': ('rt_sigprocmask', 'rt_sigaction', 'rt_sigreturn', 'restart_syscall'),
    'clocks and randomness': ('clock_gettime', 'clock_nanosleep', 'getrandom'),
}
ALLOWED_CALLS: tuple[str, ...] = tuple(name for names in _ALLOWED.values() for name in names)
# Allowed with their arguments checked (seccomp_program): how, in words, for the report and the audit.
CHECKED_CALLS: dict[str, str] = {
    'openat': 'read-only', 'clone': 'a thread', 'kill': 'itself', 'tgkill': 'itself',
    'ioctl': f'{", ".join(IOCTLS_ALLOWED)}; TCGETS answers ENOTTY',
    'fcntl': ', '.join(FCNTLS_ALLOWED),
}
# Answered ENOSYS: the C library then does the same with a call the filter can check (clone's flags are an argument,
# clone3's are in memory).
ENOSYS_CALLS = ('clone3',)
# AUDIT_ARCH_* (EM_* | 64-bit | little-endian) and which column of _SYSCALLS it reads.
_ARCHITECTURES = {'x86_64': (0xC000003E, 0), 'aarch64': (0xC00000B7, 1)}
AUDIT_MODES = ('', 'refusals', 'all')

# Read-only beneath these, besides the interpreter's and the modules' folders (readable_paths()): the dynamic
# loader's libraries and cache (a lazily imported extension module loads its libraries), the time zone (time's
# localtime), two devices, and the process' own /proc entry (/proc/self resolves to it: the watchdog's memory check
# reads /proc/self/statm).
SYSTEM_READABLE = ('/usr/lib', '/usr/lib64', '/lib', '/lib64', '/usr/local/lib', '/etc/ld.so.cache',
                   '/etc/localtime', '/usr/share/zoneinfo', '/dev/null', '/dev/urandom', '/proc/self')


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
    readable: tuple[str, ...] = ()  # the paths Landlock lets the process read beneath
    audit_fd: int = -1  # with enter_jail(audit=...): the seccomp notification descriptor

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
    readable: list[str] = field(default_factory=list)
    audit_fd: int = -1


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
def _python_places() -> set[str]:
    """Where this interpreter imports from: the standard library and site-packages, the folders on sys.path but the
    working directory (`python -m` puts it first; the sandbox imports nothing from there), what their entries link
    to (colcon's build/<package>/<package> links into src/), and the folder or file of any top-level module loaded
    from elsewhere."""
    paths = sysconfig.get_paths()
    working = os.getcwd()
    places = {paths[key] for key in ('stdlib', 'platstdlib', 'purelib', 'platlib') if key in paths}
    places |= {os.path.abspath(entry) for entry in sys.path
               if entry and os.path.abspath(entry) != working and os.path.isdir(entry)}
    for folder in list(places):
        try:
            with os.scandir(folder) as entries:
                places |= {os.path.realpath(entry.path) for entry in entries if entry.is_symlink() and entry.is_dir()}
        except OSError:
            continue
    prefixes = tuple(os.path.join(place, '') for place in places)
    for name, module in list(sys.modules.items()):
        package = getattr(module, '__path__', None)
        for place in (list(package) if package is not None else [getattr(module, '__file__', None)]):
            if '.' not in name and isinstance(place, str) and os.path.isabs(place) and not place.startswith(prefixes):
                places.add(place)
    return places


def readable_paths() -> list[str]:
    """What Landlock lets the jailed process read (see the module docstring): real paths, nested ones dropped."""
    home = os.path.realpath(os.path.expanduser('~'))
    found: set[str] = set()
    for candidate in (*_python_places(), *SYSTEM_READABLE):
        real = os.path.realpath(candidate)
        if real == '/' or real == home or home.startswith(os.path.join(real, '')) or not os.path.exists(real):
            continue  # never the file system or the home directory as a whole
        found.add(real)
    return sorted(path for path in found
                  if not any(path.startswith(os.path.join(other, '')) for other in found if other != path))


def _grant(ruleset: int, path: str) -> None:
    """Reading beneath `path` (a folder), or reading `path` (a file)."""
    fd = os.open(path, os.O_PATH | os.O_CLOEXEC)
    try:
        rights = _FS_READ_FILE | (_FS_READ_DIR if os.path.isdir(path) else 0)
        rule = _PathBeneathAttr(rights, fd)
        _call(_syscall(_LANDLOCK_ADD_RULE, ruleset, _LANDLOCK_RULE_PATH_BENEATH, ctypes.byref(rule),
                       ctypes.c_uint32(0)), f'landlock_add_rule({path})')
    finally:
        os.close(fd)


def _apply_landlock(abi: int, threads: int, outcome: _Outcome) -> None:
    """Reads beneath readable_paths() only, nothing written anywhere; TCP and (by scope) abstract Unix sockets and
    signals confined to the jail."""
    if abi < 1:
        outcome.missing.append('Landlock (not available on this kernel; seccomp still refuses writes, but every file '
                               'the user may read stays readable)')
        return
    handled_fs = _FS_ABI_1 | (_FS_REFER if abi >= 2 else 0) | (_FS_TRUNCATE if abi >= 3 else 0) \
        | (_FS_IOCTL_DEV if abi >= 5 else 0)
    attr = _RulesetAttr(handled_fs, (_NET_BIND_TCP | _NET_CONNECT_TCP) if abi >= 4 else 0,
                        (_SCOPE_ABSTRACT_UNIX_SOCKET | _SCOPE_SIGNAL) if abi >= 6 else 0)
    ruleset = -1
    try:
        readable = readable_paths()
        ruleset = _call(_syscall(_LANDLOCK_CREATE_RULESET, ctypes.byref(attr), ctypes.c_size_t(ctypes.sizeof(attr)),
                                 ctypes.c_uint32(0)), 'landlock_create_ruleset')
        for path in readable:
            _grant(ruleset, path)
        flags = _LANDLOCK_RESTRICT_SELF_TSYNC if abi >= 8 else 0
        _call(_syscall(_LANDLOCK_RESTRICT_SELF, ruleset, ctypes.c_uint32(flags)), 'landlock_restrict_self')
    except OSError as error:
        outcome.missing.append(f'Landlock ({error})')
        return
    finally:
        if ruleset >= 0:
            os.close(ruleset)
    outcome.readable = readable
    outcome.applied.append(f'reads beneath {len(readable)} paths only, no writes (Landlock ABI {abi})')
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


def syscall_name(number: int, machine: str | None = None) -> str:
    """The name of system call `number` on `machine` (this one by default), or '#<number>' if the table lacks it."""
    column = _ARCHITECTURES.get(machine or platform.machine(), (0, 0))[1]
    return next((name for name, numbers in _SYSCALLS.items() if numbers[column] == number), f'#{number}')


def seccomp_program(machine: str, own_pid: int, refusal: int = REFUSED) -> list[tuple[int, int, int, int]]:
    """The jail's filter for `machine` (platform.machine()): ALLOWED_CALLS pass, CHECKED_CALLS pass by argument,
    ENOSYS_CALLS answer ENOSYS, everything else returns `refusal` (EPERM; a user notification for the audit).
    ValueError for an architecture it does not know."""
    if machine not in _ARCHITECTURES:
        raise ValueError(f'no system call table for {machine}')
    audit_arch, column = _ARCHITECTURES[machine]

    def jumps(names: Sequence[str], target: str) -> list[tuple]:
        numbers = [n for n in (_SYSCALLS[name][column] for name in names) if n is not None]
        return [('jeq', n, target, None) for n in numbers]

    def arg(index: int, high: bool = False) -> tuple:
        return _ld(16 + 8 * index + (4 if high else 0))  # seccomp_data.args, little-endian halves

    program: list[tuple] = [_ld(4), ('jeq', audit_arch, None, 'kill'), _ld(0)]
    if machine == 'x86_64':  # the x32 ABI shares AUDIT_ARCH_X86_64 with its own numbers
        program.append(('jge', _X32_SYSCALL_BIT, 'deny', None))
    program += jumps(ALLOWED_CALLS[:2], 'allow')  # read and write first: most calls are theirs
    program += jumps(['openat'], 'openat') + jumps(['ioctl'], 'ioctl') + jumps(['fcntl'], 'fcntl')
    program += jumps(['clone'], 'clone') + jumps(['kill', 'tgkill'], 'signal') + jumps(ENOSYS_CALLS, 'enosys')
    program += jumps(ALLOWED_CALLS[2:], 'allow')
    # The kernel reads open's flags, ioctl's and fcntl's commands and pid_t as 32-bit values: the low halves.
    program += [
        ('ret', refusal),  # any other call
        ('label', 'openat'), arg(2), ('jset', _OPEN_WRITE_FLAGS, 'deny', 'allow'),  # openat(dirfd, path, flags)
        ('label', 'ioctl'), arg(1), ('jeq', _TCGETS, 'enotty', None),
        *[('jeq', command, 'allow', None) for command in IOCTLS_ALLOWED.values()], ('ret', refusal),
        ('label', 'fcntl'), arg(1), *[('jeq', command, 'allow', None) for command in FCNTLS_ALLOWED.values()],
        ('ret', refusal),
        ('label', 'clone'), arg(0), ('jset', _CLONE_NEW_NAMESPACES, 'deny', None),
        ('jset', _CLONE_THREAD, 'allow', 'deny'),
        ('label', 'signal'), arg(0), ('jeq', own_pid, 'allow', 'deny'),
        ('label', 'allow'), ('ret', SECCOMP_RET_ALLOW),
        ('label', 'deny'), ('ret', refusal),
        ('label', 'enosys'), ('ret', SECCOMP_RET_ERRNO | errno_codes.ENOSYS),
        ('label', 'enotty'), ('ret', SECCOMP_RET_ERRNO | errno_codes.ENOTTY),
        ('label', 'kill'), ('ret', SECCOMP_RET_KILL_PROCESS),
    ]
    return assemble(program)


def notify_all_program(machine: str) -> list[tuple[int, int, int, int]]:
    """A filter that hands every system call of `machine`'s native ABI to a supervisor (audit='all')."""
    if machine not in _ARCHITECTURES:
        raise ValueError(f'no system call table for {machine}')
    return assemble([_ld(4), ('jeq', _ARCHITECTURES[machine][0], None, 'kill'), ('ret', SECCOMP_RET_USER_NOTIF),
                     ('label', 'kill'), ('ret', SECCOMP_RET_KILL_PROCESS)])


def install_seccomp(program: Sequence[tuple[int, int, int, int]], listener: bool = False) -> int:
    """Install a BPF program on every thread of the process (no_new_privs must be set). OSError on failure.

    With `listener`, the filter's user notifications go to the descriptor returned; otherwise -1."""
    filters = (_SockFilter * len(program))(*(_SockFilter(*instruction) for instruction in program))
    prog = _SockFprog(len(program), filters)
    number = syscall_number('seccomp')
    flags = SECCOMP_FILTER_FLAG_TSYNC
    if listener:
        flags |= SECCOMP_FILTER_FLAG_NEW_LISTENER | SECCOMP_FILTER_FLAG_TSYNC_ESRCH
    result = -1
    if number is not None:
        result = _syscall(number, ctypes.c_uint(SECCOMP_SET_MODE_FILTER), ctypes.c_uint(flags), ctypes.byref(prog))
        if listener:
            return _call(result, 'seccomp with a listener')
        if result > 0:
            raise OSError(errno_codes.EBUSY, f'seccomp: thread {result} could not be synchronised')
    if result < 0:  # a kernel before seccomp(2): prctl reaches the calling thread only
        if listener:
            raise OSError(errno_codes.ENOSYS, 'seccomp: no seccomp(2) for a listener')
        _call(_libc.prctl(PR_SET_SECCOMP, SECCOMP_MODE_FILTER, ctypes.addressof(prog), 0, 0), 'seccomp')
    return -1


def _apply_seccomp(outcome: _Outcome, audit: str) -> None:
    machine = platform.machine()
    try:
        if audit == 'all':
            program = notify_all_program(machine)
        else:
            program = seccomp_program(machine, os.getpid(), SECCOMP_RET_USER_NOTIF if audit else REFUSED)
        outcome.audit_fd = install_seccomp(program, listener=bool(audit))
    except (ValueError, OSError) as error:
        outcome.missing.append(f'seccomp ({error}): every system call is allowed')
        return
    if audit:
        outcome.applied.append(f'AUDIT ({audit}): system calls go to a supervisor on descriptor {outcome.audit_fd} '
                               f'(seccomp, {len(program)} instructions)')
        return
    calls = sum(syscall_number(name, machine) is not None for name in (*ALLOWED_CALLS, *CHECKED_CALLS))
    outcome.applied.append(f'only {calls} system calls, openat, ioctl, fcntl, clone and kill by argument (seccomp '
                           f'allowlist, {len(program)} instructions)')


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


def enter_jail(required: bool = True, log: Callable[[str], None] | None = _stderr_line, *,
               audit: str = '') -> JailReport:
    """Jail this process for good (see the module docstring); call it once, from the only thread.

    required=True raises JailError unless the jail is complete (JailReport.missing is empty; what could be applied
    stays applied); required=False returns the report. Either way its summary, one line, goes to `log`.

    `audit` measures the filter, for tests and measurements only: 'refusals' hands each call the filter would
    refuse, 'all' every system call, to a supervisor reading the notification descriptor (JailReport.audit_fd; see
    cap_lmp.testing.syscall_audit), which decides its outcome; without a supervisor such calls fail with ENOSYS.
    """
    if audit not in AUDIT_MODES:
        raise ValueError(f'audit must be one of {AUDIT_MODES}, not {audit!r}')
    started = time.perf_counter()
    outcome = _Outcome()
    threads = _thread_count()
    abi = landlock_abi()
    if _libc.prctl(PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0) != 0:
        outcome.missing.append(f'no_new_privs ({os.strerror(ctypes.get_errno())})')
    _apply_landlock(abi, threads, outcome)
    _drop_capabilities(threads, outcome)
    _apply_seccomp(outcome, audit)  # last: the steps above make calls (open, prctl, capset) the filter refuses
    report = JailReport(tuple(outcome.applied), tuple(outcome.missing), tuple(outcome.second_layers_missing), abi,
                        time.perf_counter() - started, tuple(outcome.readable), outcome.audit_fd)
    if log is not None:
        log(report.summary())
    if required and not report.complete:
        raise JailError(report.summary())
    return report
