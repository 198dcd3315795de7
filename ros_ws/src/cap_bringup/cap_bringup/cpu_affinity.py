"""Keep a process whose threads share one interpreter lock on one CPU.

The one-process graph runs a dozen Python threads (the physics loop, two executors, action callbacks, the robot
API) that hand the interpreter lock to each other thousands of times a second. With the threads spread over two
CPUs, each handoff is a wake-up on the other CPU, and on a virtual machine that is a cross-CPU interrupt: measured
on a 2-vCPU VM, a pick-and-place graph simulating as fast as possible ran at 0.4x real time spread over both CPUs
and at 15x real time on one (`benchmarks/place_accuracy.py --moves 4`: 196 s of wall time, then 12.6 s). The
process gains little from a second CPU anyway, since its threads wait for the one lock; other processes (a
second benchmark job, the model server) use the other CPUs.
"""
from __future__ import annotations

import os


def pin_to_one_cpu(index: int = 0) -> int | None:
    """Pin every thread of this process, and so every thread and child it starts later, to one allowed CPU.

    `index` picks the CPU among those allowed, modulo their number (bench job i takes CPU i). Returns the CPU, or
    None where there is nothing to choose (one CPU allowed) or the platform has no affinity.
    """
    if not hasattr(os, 'sched_setaffinity'):
        return None
    allowed = sorted(os.sched_getaffinity(0))
    if len(allowed) < 2:
        return None
    cpu = allowed[index % len(allowed)]
    try:
        threads = [int(tid) for tid in os.listdir('/proc/self/task')]
    except OSError:
        threads = [0]
    for tid in threads:  # on Linux the affinity is per thread: set it for those running now
        try:
            os.sched_setaffinity(tid, {cpu})
        except OSError:  # a thread that ended meanwhile
            pass
    return cpu


def cpus_besides(index: int, allowed: list[int]) -> list[int]:
    """The CPUs of `allowed` other than the one `pin_to_one_cpu(index)` picks among them (for a process that should
    keep off the graph's CPU, such as the web console); empty when there are fewer than two."""
    allowed = sorted(allowed)
    if len(allowed) < 2:
        return []
    pinned = allowed[index % len(allowed)]
    return [cpu for cpu in allowed if cpu != pinned]
