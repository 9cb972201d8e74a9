"""The JSON messages of recording format v1: rounded, canonical encoding on write, and decoding
checked against the v1 schemas on read (see docs/recording-format.md).

Sensor frames are ``{"seq", "t", "values"}`` on ``/suit/sensors``; mocap samples are
``{"t", <angle>: ...}`` on ``/mocap/<joint>``. Written values are rounded to ``decimals``
places (default 1e-4 mm / deg) and times to 1e-6 s; a message's MCAP log time is its ``t`` in
nanoseconds. A message that violates its schema raises
:class:`~exohil.formats.errors.RecordingError` naming the file, topic and message index.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from mcap.records import Schema

from exohil.formats import strict_json
from exohil.formats.errors import RecordingError
from exohil.formats.recording import MOCAP_PREFIX, SENSOR_TOPIC, AngleStream, SensorStream
from exohil.formats.schemas import SCHEMA_ENCODING

VALUE_DECIMALS = 4
#: A sensor column written whole (:func:`sensor_decimals`) keeps at least this share of its
#: range as precision: readings in small units (farads, metres) are not rounded away.
RANGE_PRECISION = 1e-5
#: The most decimal places :func:`sensor_decimals` asks for (a double holds about 16 digits).
MAX_DECIMALS = 15
TIME_DECIMALS = 6
_NUMBER = (int, float)


# ----------------------------------------------------------------------------- encoding


def seconds_to_ns(t: float) -> int:
    """A message time in seconds as MCAP log/publish time, ns."""
    return int(round(t * 1e9))


def encode_message(payload: dict[str, Any]) -> bytes:
    """Canonical JSON of one message: compact, UTF-8, no NaN/inf."""
    return json.dumps(payload, separators=(",", ":"), allow_nan=False).encode("utf-8")


def rounded_times(path: Path, t: np.ndarray, count: int) -> list[float]:
    """``count`` message times (finite, ≥ 0 s) rounded to ``TIME_DECIMALS``."""
    times = np.asarray(t, dtype=np.float64).reshape(-1)
    if times.size != count:
        raise RecordingError(f"{path}: {times.size} times for {count} rows")
    if not np.all(np.isfinite(times)) or np.any(times < 0):
        raise RecordingError(f"{path}: times must be finite and >= 0 s")
    return np.round(times, TIME_DECIMALS).tolist()


def sensor_decimals(values: np.ndarray, decimals: int = VALUE_DECIMALS) -> int:
    """``decimals``, or more where a sensor column (of (N, S) ``values``) spans so little
    that rounding to ``decimals`` places would step by more than :data:`RANGE_PRECISION`
    of its range (readings of 5·10⁻⁴ F rounded to 10⁻⁴ keep two levels); at most
    :data:`MAX_DECIMALS`."""
    values = np.asarray(values, dtype=np.float64)
    if values.ndim != 2 or not values.size or not np.all(np.isfinite(values)):
        return decimals  # nothing to write, or refused by rounded_values
    spans = np.ptp(values, axis=0)
    spans = spans[spans > 0]
    if not spans.size:
        return decimals
    needed = math.ceil(-math.log10(float(spans.min()) * RANGE_PRECISION))
    return int(min(max(decimals, needed), MAX_DECIMALS))


def stored_decimals(arrays: Sequence[np.ndarray], decimals: int = VALUE_DECIMALS) -> int:
    """The decimal places that write ``arrays`` (sensor values, angles) back as they were read:
    ``decimals``, or the fewest more (at most :data:`MAX_DECIMALS`) that rounding leaves every
    value unchanged at. For commands that rewrite a recording (``record cut``, ``record
    recover``): a recording imported with 6 places, or another tool's, loses none of them."""
    for places in range(decimals, MAX_DECIMALS + 1):
        if all(np.array_equal(np.round(values, places), values) for values in arrays
               if np.size(values)):
            return places
    return MAX_DECIMALS


def rounded_values(
    path: Path, values: np.ndarray, decimals: int, what: str
) -> list[list[float]]:
    """Rows of finite values rounded to ``decimals`` places (``what`` names them in errors)."""
    if not np.all(np.isfinite(values)):
        raise RecordingError(f"{path}: {what} must be finite (JSON has no NaN/inf)")
    return np.round(values, decimals).tolist()


# ----------------------------------------------------------------------------- decoding


def decode_sensors(path: Path, messages: list[tuple[int, bytes]], width: int) -> SensorStream:
    """Sensor frames (log time, JSON) sorted by log time into a stream of ``width`` sensors;
    ``seq`` must increase strictly."""
    messages.sort(key=lambda item: item[0])
    count = len(messages)
    seq = np.empty(count, dtype=np.int64)
    t = np.empty(count, dtype=np.float64)
    values = np.empty((count, width), dtype=np.float64)
    for k, (_, data) in enumerate(messages):
        frame = _json_object(path, SENSOR_TOPIC, k, data)
        frame_seq, frame_t, frame_values = frame.get("seq"), frame.get("t"), frame.get("values")
        if type(frame_seq) is not int:
            raise _schema_error(path, SENSOR_TOPIC, k, "'seq' must be an integer")
        if type(frame_t) not in _NUMBER:
            raise _schema_error(path, SENSOR_TOPIC, k, "'t' must be a number")
        if type(frame_values) is not list or not all(type(v) in _NUMBER for v in frame_values):
            raise _schema_error(path, SENSOR_TOPIC, k, "'values' must be a list of numbers")
        if len(frame_values) != width:
            raise RecordingError(
                f"{path}: {SENSOR_TOPIC} frame {k} (seq {frame_seq}) has {len(frame_values)} "
                f"values; metadata lists {width} sensors"
            )
        seq[k], t[k] = frame_seq, frame_t
        values[k] = frame_values
    bad = np.flatnonzero(np.diff(seq) <= 0)
    if bad.size:
        k = int(bad[0]) + 1
        raise RecordingError(
            f"{path}: non-monotonic seq in {SENSOR_TOPIC}: frame {k} has seq {seq[k]} "
            f"(t {t[k]:.6f} s) after seq {seq[k - 1]} (t {t[k - 1]:.6f} s), in the order "
            "of the messages' log times; seq must increase with it"
        )
    _check_times(path, SENSOR_TOPIC, t)
    _check_finite(path, SENSOR_TOPIC, values, "sensor value")
    return SensorStream(seq=seq, t=t, values=values)


def decode_angles(
    path: Path, joint: str, messages: list[tuple[int, bytes]], schema: Schema | None
) -> AngleStream:
    """Mocap samples of ``joint`` (log time, JSON) sorted by log time; the angle names come
    from the first message (from ``schema`` when there is none)."""
    topic = MOCAP_PREFIX + joint
    messages.sort(key=lambda item: item[0])
    names = _schema_angle_names(schema)
    t = np.empty(len(messages), dtype=np.float64)
    rows: list[list[float]] = []
    for k, (_, data) in enumerate(messages):
        sample = _json_object(path, topic, k, data)
        sample_t = sample.pop("t", None)
        if type(sample_t) not in _NUMBER:
            raise _schema_error(path, topic, k, "'t' must be a number")
        if k == 0:
            names = tuple(sample)
        if tuple(sample) != names and set(sample) != set(names):
            raise _schema_error(path, topic, k, f"fields {sorted(sample)} differ from {names}")
        row = [sample[name] for name in names]
        if not all(type(v) in _NUMBER for v in row):
            raise _schema_error(path, topic, k, "angle fields must be numbers")
        t[k] = sample_t
        rows.append(row)
    angles = np.asarray(rows, dtype=np.float64).reshape(len(messages), len(names))
    _check_times(path, topic, t)
    _check_finite(path, topic, angles, "angle")
    return AngleStream(t=t, names=names, angles=angles)


def _check_times(path: Path, topic: str, t: np.ndarray) -> None:
    """Message times (in log-time order) must be finite, ≥ 0 s and never go back."""
    bad = np.flatnonzero(~np.isfinite(t) | (t < 0))
    if bad.size:
        raise RecordingError(f"{path}: {topic} message {int(bad[0])} has time "
                             f"{float(t[bad[0]]):g} s; times must be finite and >= 0 s "
                             "(shift the writer's clock to start at 0 or later)")
    back = np.flatnonzero(np.diff(t) < 0)
    if back.size:
        k = int(back[0]) + 1
        raise RecordingError(f"{path}: {topic} time goes back at message {k}: "
                             f"{t[k]:.6f} s after {t[k - 1]:.6f} s")


def first_non_finite(values: np.ndarray) -> tuple[int, int] | None:
    """(row, column) of the first value of 2-D ``values`` that is not finite, or None."""
    bad = np.argwhere(~np.isfinite(values))
    return (int(bad[0][0]), int(bad[0][1])) if bad.size else None


def _check_finite(path: Path, topic: str, values: np.ndarray, what: str) -> None:
    bad = first_non_finite(values)
    if bad is not None:
        raise RecordingError(f"{path}: {topic} message {bad[0]} has a non-finite {what} "
                             f"(column {bad[1]})")


def _schema_angle_names(schema: Schema | None) -> tuple[str, ...]:
    """Angle names declared by a jsonschema, in order (``required`` keeps the order that
    sorted ``properties`` lose); used only when a channel has no messages."""
    if schema is None or schema.encoding != SCHEMA_ENCODING:
        return ()
    try:
        declared = strict_json.loads(schema.data)
        names = declared.get("required") or list(declared.get("properties", {}))
    except (ValueError, AttributeError):
        return ()
    return tuple(name for name in names if isinstance(name, str) and name != "t")


def _json_object(path: Path, topic: str, index: int, data: bytes) -> dict[str, Any]:
    try:
        value = strict_json.loads(data)
    except ValueError as exc:
        raise _schema_error(path, topic, index, f"invalid JSON ({exc})") from exc
    if not isinstance(value, dict):
        raise _schema_error(path, topic, index, "message is not a JSON object")
    return value


def _schema_error(path: Path, topic: str, index: int, problem: str) -> RecordingError:
    return RecordingError(f"{path}: {topic} message {index} violates the v1 schema: {problem}")
