"""The limits of one sandboxed run, and the file name that marks sandboxed code."""
from __future__ import annotations

from dataclasses import dataclass

# Code objects whose file name starts with this are sandboxed: the tracer watches only them.
SANDBOX_FILE_PREFIX = '<cap-sandbox'


@dataclass(frozen=True)
class SandboxLimits:
    """Limits for one program run. Defaults fit table-top policies with room to spare.

    The time limit counts time inside robot API calls (motions take seconds each) but not time waiting for the model.
    """

    time_limit_s: float = 300.0
    max_sequence_length: int = 1_000_000
    max_array_elements: int = 2_000_000
    max_int_bits: int = 100_000
    max_format_width: int = 10_000
    max_call_depth: int = 150
    max_memory_growth_bytes: int = 1 << 30
    # Reading the resident size releases the interpreter lock for a moment. At one read per 5 ms, CPython's switch
    # interval, a thread waiting for the lock saw it change hands within each of its 5 ms waits, never asked the
    # program to yield, and starved: the sandbox process's heartbeat and cancel threads went silent for seconds
    # during a tight loop. Four switch intervals leave them their turn.
    memory_check_interval_s: float = 0.02
