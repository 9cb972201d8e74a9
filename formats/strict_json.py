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
    """Parse ``data``; raises ValueError (``UnicodeDecodeError`` and ``JSONDecodeError`` are
    ValueErrors too) for invalid JSON or UTF-8, a non-finite or out-of-range number, or
    nesting too deep for the parser's recursion limit."""
    try:
        return json.loads(data, parse_constant=_constant, parse_float=_float, parse_int=_int)
    except RecursionError:
        raise ValueError("JSON nested too deeply") from None


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
