"""A sandbox process whose program escaped the in-process checks, for the jail's tests (test_jail.py).

    python -m cap_lmp.testing.escaped_child <mode> <socket fd>

It loads what the real sandbox process loads before its first program (NumPy, Shapely, the engine's
modules), then, by `mode`:

- `free`: no jail (the control case: the same code must succeed here);
- `jail`: `enter_jail()`, the call engine_process makes;
- `jail_without_landlock` / `jail_without_seccomp`: first makes the kernel refuse Landlock (landlock_create_ruleset
  fails with ENOSYS) or seccomp (seccomp(2) ENOSYS, prctl(PR_SET_SECCOMP) EINVAL), as some containers do, then
  `enter_jail(required=False)`;
- `required_without_landlock`: the same, then `enter_jail()`, which must refuse;
- `jail_with_a_thread`: starts a thread first, then `enter_jail(required=False)` (the report must say so);
- `audit_all` / `audit_refusals`: `enter_jail(audit='all' | 'refusals')`, for a SyscallAudit
  (syscall_audit.py) the test attaches to this process.

It sends the outcome ({'jail': report fields} or {'jail_error': message}) on the socket, then runs each message
it receives as raw Python with `channel` (the socket's Connection) in scope — this is the test-only hook that
stands for escaped code: it runs with none of the sandbox's checks — and answers {'ok': True, 'result': ...} or
{'ok': False, 'error': type name, 'errno': ..., 'message': ...}. Only tests start it; its code comes from them.
"""
from __future__ import annotations

import ctypes
import dataclasses
import errno
import json
import sys
import threading
from multiprocessing.connection import Connection

import numpy  # noqa: F401  (loaded before the jail, as in the real sandbox process)
import shapely  # noqa: F401

import cap_lmp.engine  # noqa: F401
from cap_lmp.sandbox import jail

_PR_SET_NO_NEW_PRIVS = 38


def _refuse(rules: list[tuple[str, int | None, int]]) -> None:
    """Make the kernel refuse system calls: (name, required first argument or None, errno)."""
    program: list[tuple] = [('ld', 0)]
    for index, (name, first_arg, code) in enumerate(rules):
        number = jail.syscall_number(name)
        if number is None:
            continue
        skip = f'skip{index}'
        program.append(('jeq', number, None, skip))
        if first_arg is not None:
            program += [('ld', 16), ('jeq', first_arg, None, 'allow')]
        program += [('ret', jail.SECCOMP_RET_ERRNO | code), ('label', skip)]
        if first_arg is not None:
            program.append(('ld', 0))
    program += [('label', 'allow'), ('ret', jail.SECCOMP_RET_ALLOW)]
    ctypes.CDLL(None).prctl(_PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0)
    jail.install_seccomp(jail.assemble(program))


def _enter(mode: str) -> dict:
    if mode == 'free':
        return {'jail': None}
    if mode.endswith('without_landlock'):
        _refuse([('landlock_create_ruleset', None, errno.ENOSYS)])
    elif mode.endswith('without_seccomp'):
        _refuse([('seccomp', None, errno.ENOSYS), ('prctl', jail.PR_SET_SECCOMP, errno.EINVAL)])
    elif mode == 'jail_with_a_thread':
        threading.Thread(target=threading.Event().wait, daemon=True).start()
    try:
        if mode.startswith('audit_'):
            report = jail.enter_jail(audit=mode.removeprefix('audit_'))
        elif mode in ('jail', 'required_without_landlock'):
            report = jail.enter_jail()
        else:
            report = jail.enter_jail(required=False)
    except jail.JailError as error:
        return {'jail_error': str(error)}
    return {'jail': dataclasses.asdict(report)}


def main() -> None:
    mode = sys.argv[1]
    channel = Connection(int(sys.argv[2]))
    channel.send_bytes(json.dumps(_enter(mode)).encode())
    while True:
        try:
            code = channel.recv_bytes().decode()
        except EOFError:
            return
        scope = {'channel': channel, '__name__': 'escaped'}
        try:
            exec(compile(code, '<escaped>', 'exec'), scope)  # the test's own code: the hook this module exists for
            reply = {'ok': True, 'result': scope.get('result')}
        except BaseException as error:  # report everything; the test decides
            reply = {'ok': False, 'error': type(error).__name__, 'errno': getattr(error, 'errno', None),
                     'message': str(error)}
        channel.send_bytes(json.dumps(reply, default=repr).encode())


if __name__ == '__main__':
    main()
