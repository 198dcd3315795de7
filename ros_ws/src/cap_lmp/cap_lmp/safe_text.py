"""Text that leaves the node: always encodable, bounded, and safe to print.

Whatever a generated program, a model or a command sender produces may hold lone surrogates (`chr(55296)`), which
cannot be encoded as UTF-8 (rclpy raises while publishing a string field, and the thread that tried dies), or
terminal control sequences, which would act on the user's terminal when printed. Every string that leaves the node
(results, feedback, /cap/status, /cap/code, /cap/say, logs) goes through `wire_text`; every string a `cap` command
prints goes through `terminal_text` as well.
"""
from __future__ import annotations

import re
from typing import Any

MAX_MESSAGE_CHARS = 10_000  # a message, error or said line; code has its own limit (wire.MAX_CODE_CHARS)

# C0 and C1 controls and DEL, except tab and newline, which text and code legitimately hold.
_CONTROL = re.compile('[\x00-\x08\x0b-\x1f\x7f-\x9f]')


def wire_text(value: Any, limit: int = MAX_MESSAGE_CHARS) -> str:
    """`value` as a str that encodes as UTF-8 and holds at most `limit` characters (plus a cut mark).

    Lone surrogates become U+FFFD. A non-str value is described by its type only: building str() of an arbitrary
    object here could cost without bound (callers format what they mean to show before).
    """
    if not isinstance(value, str):
        value = f'<{type(value).__name__}>'
    if len(value) > limit:
        value = value[:limit] + '...'
    try:
        value.encode('utf-8')
        return value
    except UnicodeEncodeError:  # lone surrogates: their bytes are not UTF-8, so decoding replaces them
        return value.encode('utf-8', 'surrogatepass').decode('utf-8', 'replace')


def terminal_text(value: Any, limit: int = MAX_MESSAGE_CHARS) -> str:
    """`wire_text(value)` with control characters (escape sequences, carriage returns, ...) shown as `\\xNN`."""
    return _CONTROL.sub(lambda match: f'\\x{ord(match.group()):02x}', wire_text(value, limit))


def one_line(value: Any, limit: int = MAX_MESSAGE_CHARS) -> str:
    """`wire_text(value)` on one line: every run of white space and control characters becomes one space.

    A command is one instruction: a newline in it would start a second line of the prompt, which the model reads
    as code or as a further instruction.
    """
    return ' '.join(_CONTROL.sub(' ', wire_text(value, limit)).split())
