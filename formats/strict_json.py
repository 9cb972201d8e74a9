"""JSON as the project's files carry it: finite numbers, nesting within the stack.

Python's ``json`` accepts ``NaN`` and ``Infinity``, turns ``1e999`` into ``inf``, builds
integers of thousands of digits and recurses until the interpreter's stack limit. Data read
from a recording or a checkpoint is untrusted, so :func:`loads` refuses all of these with a
``ValueError`` naming the problem, before any of it reaches numpy.
"""

from __future__ import annotations

import json
import math
from typing import Any

#: Largest magnitude of an integer (int64, the widest integer the formats store).
MAX_INT = 2**63 - 1


def dumps(value: Any, **kwargs: Any) -> str:
    """``json.dumps`` of ``value`` with every non-finite float written as ``null`` (a figure
    not measured, such as an RMSE over no frame), so that :func:`loads` reads it back;
    ``kwargs`` go to ``json.dumps``."""
    return json.dumps(_finite(value), allow_nan=False, **kwargs)


def _finite(value: Any) -> Any:
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    return value


def loads(data: str | bytes) -> Any:
    """Parse ``data`` as ``json.loads`` does (bytes in UTF-8, -16 or -32); raises ValueError
    (``UnicodeDecodeError`` and ``JSONDecodeError`` are ValueErrors too) for invalid JSON or
    UTF-8, a non-finite or out-of-range number, or nesting too deep for the parser's
    recursion limit.

    One decoder serves every call: ``json.loads`` with hooks builds a decoder per call, and
    finds the encoding of bytes by a function call of its own. On the 91,000 messages of a
    four-minute recording the two took 0.35 s of 1.2 s (2026-12-07)."""
    if isinstance(data, (bytes, bytearray)):
        data = data.decode(_encoding(data), "surrogatepass")
    elif isinstance(data, str) and data.startswith("\ufeff"):
        raise json.JSONDecodeError("Unexpected UTF-8 BOM (decode using utf-8-sig)", data, 0)
    try:
        return _DECODER.decode(data)
    except RecursionError:
        raise ValueError("JSON nested too deeply") from None


def _encoding(data: bytes | bytearray) -> str:
    """The encoding ``json.loads`` reads ``data`` in: UTF-8 wherever its first two bytes are
    neither zero nor the start of a byte-order mark (an object or array opens with ASCII;
    ``json.detect_encoding`` decides the rest)."""
    if len(data) >= 2 and data[0] in _ASCII_OPENERS and data[1]:
        return "utf-8"
    return json.detect_encoding(data)


def _constant(name: str) -> Any:
    raise ValueError(f"{name} is not a finite number")


def _float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"number {text[:40]} is out of range")
    return value


def _int(text: str) -> int:
    if len(text.lstrip("-")) > 19:
        raise ValueError(f"integer {text[:40]}... is out of range")
    value = int(text)
    if abs(value) > MAX_INT:
        raise ValueError(f"integer {text} is out of range")
    return value


#: The one decoder of :func:`loads`: its hooks refuse what the module docstring lists.
_DECODER = json.JSONDecoder(parse_constant=_constant, parse_float=_float, parse_int=_int)
#: First bytes of a JSON text that no byte-order mark starts with: printable ASCII.
_ASCII_OPENERS = frozenset(range(0x21, 0x7F))
