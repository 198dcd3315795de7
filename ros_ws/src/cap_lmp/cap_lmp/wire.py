"""Messages between lmp_node and its sandbox process: JSON with NumPy arrays, never pickle.

The sandbox process runs untrusted code, so what it sends is untrusted too: decoding builds only JSON values and
numeric NumPy arrays, and a message is at most MAX_MESSAGE_BYTES long. Frames are a 4-byte big-endian length and
the message, the framing of multiprocessing.connection.Connection (which the sandbox process uses); the node reads
them with FrameBuffer from a socket it polls, so a half-sent frame never blocks it.
"""
from __future__ import annotations

import dataclasses
import json
import struct
from typing import Any

import numpy as np

from cap_lmp.errors import RobotApiError, StoppedError

MAX_MESSAGE_BYTES = 4 << 20
MAX_RESULT_BYTES = MAX_MESSAGE_BYTES  # what the node accepts from the sandbox process: events, calls, model
# requests (with their prompt), results
_HEADER = struct.Struct('!i')
MAX_CODE_CHARS = 100_000  # of code and messages the sandbox process sends
# The longest program that runs: a model answer, and a program with the functions generated for it, of more than
# 50,000 characters is refused before it is parsed (engine.check_program_size). Far above any policy the prompts
# produce, and below MAX_CODE_CHARS, so what runs is always shown in full on /cap/code and in the result.
MAX_PROGRAM_CHARS = 50_000
# The longest prompt the sandbox process may send for a model request (the session's history grows with every
# command); it fits a message of MAX_MESSAGE_BYTES.
MAX_PROMPT_CHARS = 1_000_000
MEMORY_EXIT_CODE = 3  # the sandbox process' exit status when it ran out of memory
# Exception types a robot API error travels as, by name; any other error travels as its nearest base among them.
API_ERRORS: dict[str, type[Exception]] = {
    'StoppedError': StoppedError, 'RobotApiError': RobotApiError, 'ValueError': ValueError,
    'TypeError': TypeError, 'KeyError': KeyError, 'IndexError': IndexError, 'RuntimeError': RuntimeError,
}
# A function passed to a robot API call travels as {CALLABLE_KEY: handle, 'name': its name} (engine_process.py).
CALLABLE_KEY = '$callable'


@dataclasses.dataclass(frozen=True)
class CallableHandle:
    """A function of the running program, passed to a robot API call (`run_controller(f, ...)`): the robot function
    receives this instead, and may call the function through IsolatedEngine.invoke until it returns."""

    id: int
    name: str


MAX_ITEMS = 200_000  # values (list items, array elements) in one message
_ARRAY_KEY = '__ndarray__'
# Only plain numeric arrays cross the boundary: no object, string or structured dtypes.
_ARRAY_KINDS = 'biuf'


class WireError(ValueError):
    """A value cannot be sent to or received from the other process."""


class _Budget:
    """Counts the items an encoding visits: aliased lists (`[row] * 1000`) must not turn into hours of work."""

    def __init__(self, limit: int) -> None:
        self.left = limit

    def spend(self, count: int) -> None:
        self.left -= count
        if self.left < 0:
            raise WireError(f'a value with more than {MAX_ITEMS} items cannot be passed to the robot')


def _to_json(value: Any, budget: _Budget) -> Any:
    budget.spend(1)
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, np.generic) and value.dtype.kind in _ARRAY_KINDS:
        return value.item()
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in _ARRAY_KINDS:
            raise WireError(f'an array of {value.dtype} cannot be passed to the robot, only numbers')
        budget.spend(value.size)
        return {_ARRAY_KEY: [list(value.shape), value.dtype.str, value.ravel().tolist()]}
    if isinstance(value, (list, tuple)):
        budget.spend(len(value))
        return [_to_json(item, budget) for item in value]
    if isinstance(value, dict):
        if not all(isinstance(key, str) for key in value):
            raise WireError('only dictionaries with text keys can be passed to the robot')
        budget.spend(len(value))
        return {key: _to_json(item, budget) for key, item in value.items()}
    raise WireError(f'a {type(value).__name__} cannot be passed to the robot')


def _array(fields: Any) -> np.ndarray:
    try:
        shape, dtype_text, flat = fields
        dtype = np.dtype(str(dtype_text))
    except (TypeError, ValueError) as error:
        raise WireError(f'malformed array in a message: {error}') from None
    if dtype.kind not in _ARRAY_KINDS or not isinstance(flat, list):
        raise WireError(f'an array of {dtype} is not accepted')
    if not isinstance(shape, list) or not all(isinstance(n, int) and n >= 0 for n in shape):
        raise WireError('malformed array shape in a message')
    try:
        return np.array(flat, dtype=dtype).reshape(shape)
    except (TypeError, ValueError, OverflowError) as error:
        raise WireError(f'malformed array in a message: {error}') from None


def _from_json(document: dict) -> Any:
    if len(document) == 1 and _ARRAY_KEY in document:
        return _array(document[_ARRAY_KEY])
    return document


def encode(message: dict[str, Any]) -> bytes:
    """One message as bytes; WireError if a value cannot be sent or the message is too long."""
    try:
        data = json.dumps(_to_json(message, _Budget(MAX_ITEMS)), separators=(',', ':')).encode('utf-8')
    except RecursionError:
        raise WireError('a value nested too deeply cannot be passed to the robot') from None
    except ValueError as error:  # an integer with more digits than Python converts to text
        raise WireError(f'a value cannot be passed to the robot: {error}') from None
    if len(data) > MAX_MESSAGE_BYTES:
        raise WireError(f'a message of {len(data)} bytes is longer than the limit of {MAX_MESSAGE_BYTES}')
    return data


def decode(data: bytes) -> dict[str, Any]:
    """The message in `data`; WireError for anything but a JSON object of the kinds encode() writes."""
    try:
        message = json.loads(data.decode('utf-8'), object_hook=_from_json)
    except (ValueError, RecursionError) as error:  # also JSON and Unicode errors, and over-long integers
        raise WireError(f'malformed message: {type(error).__name__}') from None
    if not isinstance(message, dict):
        raise WireError('malformed message: not an object')
    return message


def frame(data: bytes) -> bytes:
    """`data` with its length in front."""
    return _HEADER.pack(len(data)) + data


class FrameBuffer:
    """Bytes read from a socket in, whole messages out; a frame longer than `max_bytes` is a WireError."""

    def __init__(self, max_bytes: int) -> None:
        self.max_bytes = max_bytes
        self._buffer = bytearray()

    def feed(self, chunk: bytes) -> None:
        self._buffer += chunk

    def next_frame(self) -> bytes | None:
        """The next whole message, or None until all of it has arrived."""
        if len(self._buffer) < _HEADER.size:
            return None
        (length,) = _HEADER.unpack_from(self._buffer)
        if length < 0 or length > self.max_bytes:
            raise WireError(f'a message of {length} bytes announced (limit {self.max_bytes})')
        end = _HEADER.size + length
        if len(self._buffer) < end:
            return None
        data = bytes(self._buffer[_HEADER.size:end])
        del self._buffer[:end]
        return data
