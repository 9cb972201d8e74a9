"""Recording format v1 on disk: MCAP files with JSON messages (see docs/recording-format.md).

Writing: :class:`RecordingWriter` streams frames and mocap samples into a file (live
sessions); :func:`write_recording` writes a whole in-memory :class:`Recording`, interleaving
all streams in time order. Output is deterministic: no wall-clock times, fixed chunk size and
compression, canonical JSON, sensor values and angles rounded to 1e-4 (mm, deg) and times to
1e-6 s. The MCAP log time and publish time of each message are its ``t`` in nanoseconds.

Reading: :func:`read_recording` (or :func:`scan_recording`, which also reports per-channel
statistics and notes) scans the whole file linearly, so every valid layout reads the same way:
chunked or not, compressed with none/lz4/zstd, with or without summary and indexes, messages in
any order (streams are sorted by log time). Unknown channels and metadata records are ignored
with a note. Any problem raises :class:`~exohil.formats.errors.RecordingError` naming the file.
"""

from __future__ import annotations

import io
import json
import math
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO, Literal

import numpy as np
from mcap.exceptions import EndOfFile
from mcap.records import Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from exohil.formats.errors import RecordingError
from exohil.formats.recording import (
    FORMAT_NAME,
    FORMAT_VERSION,
    MOCAP_PREFIX,
    SENSOR_TOPIC,
    AngleStream,
    Recording,
    Segment,
    SensorStream,
)
from exohil.formats.schemas import (
    MESSAGE_ENCODING,
    SCHEMA_ENCODING,
    SENSOR_SCHEMA_NAME,
    joint_angles_schema,
    joint_angles_schema_name,
    schema_bytes,
    sensor_frame_schema,
)

METADATA_NAME = "exohil.recording"
ANGLE_UNIT = "deg"
DEFAULT_SUIT_SENSORS = ("F", "SF", "SR", "R")
DEFAULT_SENSOR_RATE_HZ = 250.0
DEFAULT_MOCAP_RATE_HZ = 120.0
VALUE_DECIMALS = 4
TIME_DECIMALS = 6
CHUNK_SIZE = 1 << 20
WRITER_LIBRARY = "exohil recording writer, format v1"
RESERVED_KEYS = frozenset(
    {"format", "version", "sensors", "units", "sensor_rate_hz", "mocap_rate_hz", "segments"}
)
Compression = Literal["none", "lz4", "zstd"]
_COMPRESSION = {
    "none": CompressionType.NONE,
    "lz4": CompressionType.LZ4,
    "zstd": CompressionType.ZSTD,
}
_MAGIC = b"\x89MCAP0\r\n"
_NUMBER = (int, float)


def format_number(value: float) -> str:
    """Metadata text of a rate or other number: integers without '.0', at most 12 digits."""
    return format(float(value), ".12g")


def _seconds_to_ns(t: float) -> int:
    return int(round(t * 1e9))


class RecordingWriter:
    """Streaming writer of one recording file.

    Frames and samples are written as they are added (call :meth:`close`, or use ``with``).
    The ``exohil.recording`` metadata record is written at close, so segments may be added
    until then. Sensor ``seq`` must increase strictly; times must be finite and ≥ 0 s.

    Args:
        path: output file (overwritten).
        sensor_names: sensor column names in order; empty for a mocap-only recording (then no
            ``/suit/sensors`` channel is written).
        mocap_joints: joint → angle field names (degrees), one ``/mocap/<joint>`` channel each.
        sensor_units: unit of the sensor values (metadata ``units`` is ``"<sensor_units>,deg"``).
        sensor_rate_hz, mocap_rate_hz: nominal rates written to the metadata.
        metadata: provenance and other str → str entries (reserved keys are computed here).
        compression: chunk compression, "lz4" (default), "zstd" or "none".
        decimals: decimal places kept for sensor values and angles (default 4: 1e-4 mm / deg;
            importers of finer data may keep more).
    """

    def __init__(
        self,
        path: str | Path,
        sensor_names: Sequence[str],
        *,
        mocap_joints: Mapping[str, Sequence[str]] | None = None,
        sensor_units: str = "mm",
        sensor_rate_hz: float = DEFAULT_SENSOR_RATE_HZ,
        mocap_rate_hz: float = DEFAULT_MOCAP_RATE_HZ,
        metadata: Mapping[str, str] | None = None,
        compression: Compression = "lz4",
        decimals: int = VALUE_DECIMALS,
    ) -> None:
        self.path = Path(path)
        self.decimals = decimals
        self.sensor_names = tuple(sensor_names)
        self.mocap_joints = {joint: tuple(names) for joint, names in (mocap_joints or {}).items()}
        _check_names(self.path, self.sensor_names, self.mocap_joints)
        if compression not in _COMPRESSION:
            raise ValueError(f"compression must be one of {sorted(_COMPRESSION)}")
        self._metadata = _metadata_record(
            self.path, self.sensor_names, sensor_units, sensor_rate_hz, mocap_rate_hz, metadata
        )
        self._segments: list[Segment] = []
        self._last_seq: int | None = None
        self._counts: dict[int, int] = {}
        self._file: BinaryIO = open(self.path, "wb")  # closed in close()
        self._writer = Writer(
            self._file, chunk_size=CHUNK_SIZE, compression=_COMPRESSION[compression]
        )
        self._writer.start(profile="", library=WRITER_LIBRARY)
        self._sensor_channel = -1
        if self.sensor_names:
            self._sensor_channel = self._register(
                SENSOR_TOPIC, SENSOR_SCHEMA_NAME, sensor_frame_schema(len(self.sensor_names))
            )
        self._mocap_channels = {
            joint: self._register(
                MOCAP_PREFIX + joint,
                joint_angles_schema_name(joint),
                joint_angles_schema(joint, names),
            )
            for joint, names in self.mocap_joints.items()
        }
        self._closed = False

    def _register(self, topic: str, schema_name: str, schema: dict[str, Any]) -> int:
        schema_id = self._writer.register_schema(
            name=schema_name, encoding=SCHEMA_ENCODING, data=schema_bytes(schema)
        )
        channel_id = self._writer.register_channel(
            topic=topic, message_encoding=MESSAGE_ENCODING, schema_id=schema_id
        )
        self._counts[channel_id] = 0
        return channel_id

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def add_sensor_frame(self, seq: int, t: float, values: Sequence[float]) -> None:
        """Append one sensor frame: device ``seq``, device time ``t`` (s), values in units."""
        self.add_sensor_frames(np.asarray([seq]), np.asarray([t]), np.asarray([values]))

    def add_sensor_frames(self, seq: np.ndarray, t: np.ndarray, values: np.ndarray) -> None:
        """Append frames: ``seq`` (N,) ints, ``t`` (N,) s, ``values`` (N, S)."""
        self._check_open()
        if not self.sensor_names:
            raise RecordingError(f"{self.path}: this recording was opened without sensors")
        seq = np.asarray(seq, dtype=np.int64).reshape(-1)
        values = np.asarray(values, dtype=np.float64)
        if values.ndim != 2 or values.shape != (seq.size, len(self.sensor_names)):
            raise RecordingError(
                f"{self.path}: sensor frames must be ({seq.size}, {len(self.sensor_names)}), "
                f"got {values.shape}"
            )
        previous = np.concatenate(([self._last_seq], seq)) if self._last_seq is not None else seq
        if np.any(np.diff(previous) <= 0):
            raise RecordingError(f"{self.path}: sensor seq must increase strictly")
        times = _rounded_times(self.path, t, seq.size)
        rows = _rounded_values(self.path, values, self.decimals, "sensor values")
        for frame_seq, frame_t, frame_values in zip(seq.tolist(), times, rows, strict=True):
            payload = {"seq": frame_seq, "t": frame_t, "values": frame_values}
            self._emit(self._sensor_channel, frame_t, payload)
        if seq.size:
            self._last_seq = int(seq[-1])

    def add_mocap_sample(self, joint: str, t: float, angles: Sequence[float]) -> None:
        """Append one mocap sample of ``joint`` at ``t`` (s); ``angles`` in degrees."""
        self.add_mocap_samples(joint, np.asarray([t]), np.asarray([angles]))

    def add_mocap_samples(self, joint: str, t: np.ndarray, angles: np.ndarray) -> None:
        """Append samples of ``joint``: ``t`` (M,) s, ``angles`` (M, A) degrees."""
        self._check_open()
        if joint not in self._mocap_channels:
            raise RecordingError(f"{self.path}: joint {joint!r} was not declared at open")
        names = self.mocap_joints[joint]
        angles = np.asarray(angles, dtype=np.float64)
        times = _rounded_times(self.path, t, angles.shape[0] if angles.ndim else -1)
        if angles.ndim != 2 or angles.shape[1] != len(names):
            raise RecordingError(
                f"{self.path}: {joint} angles must be (M, {len(names)}), got {angles.shape}"
            )
        rows = _rounded_values(self.path, angles, self.decimals, f"{joint} angles")
        channel = self._mocap_channels[joint]
        for sample_t, sample in zip(times, rows, strict=True):
            payload = {"t": sample_t, **dict(zip(names, sample, strict=True))}
            self._emit(channel, sample_t, payload)

    def add_channel(self, topic: str, schema_name: str, schema: dict[str, Any]) -> int:
        """Register an extra JSON channel (estimates, robot commands, timing) and return its id
        for :meth:`add_message`. Format v1 readers ignore topics outside ``/suit/sensors`` and
        ``/mocap/*`` (and list them as notes); MCAP tools such as Foxglove show them."""
        self._check_open()
        if topic == SENSOR_TOPIC or topic.startswith(MOCAP_PREFIX):
            raise RecordingError(f"{self.path}: {topic} is a format v1 topic; use the "
                                 "sensor/mocap methods")
        return self._register(topic, schema_name, schema)

    def add_message(self, channel: int, t: float, payload: Mapping[str, Any]) -> None:
        """Append one JSON message at ``t`` (s) to a channel from :meth:`add_channel`
        (finite numbers only: JSON has no NaN)."""
        self._check_open()
        if channel not in self._counts or channel == self._sensor_channel \
                or channel in self._mocap_channels.values():
            raise RecordingError(f"{self.path}: channel {channel} was not added by add_channel")
        self._emit(channel, t, dict(payload))

    def add_segment(self, segment: Segment) -> None:
        """Label a time span (seconds on the sensor clock); stored in the metadata at close."""
        self._check_open()
        self._segments.append(segment)

    def _emit(self, channel: int, t: float, payload: dict[str, Any]) -> None:
        data = json.dumps(payload, separators=(",", ":"), allow_nan=False).encode("utf-8")
        stamp = _seconds_to_ns(t)
        self._writer.add_message(
            channel_id=channel,
            log_time=stamp,
            publish_time=stamp,
            data=data,
            sequence=self._counts[channel] & 0xFFFFFFFF,
        )
        self._counts[channel] += 1

    def _check_open(self) -> None:
        if self._closed:
            raise RecordingError(f"{self.path}: writer already closed")

    def close(self) -> None:
        """Write the metadata record and the summary, and close the file (idempotent)."""
        if self._closed:
            return
        self._closed = True
        try:
            metadata = dict(self._metadata)
            if self._segments:
                metadata["segments"] = json.dumps(
                    [{"name": s.name, "t0": s.t0, "t1": s.t1} for s in self._segments],
                    separators=(",", ":"),
                )
            self._writer.add_metadata(METADATA_NAME, dict(sorted(metadata.items())))
            self._writer.finish()
        finally:
            self._file.close()


def _check_names(
    path: Path, sensor_names: tuple[str, ...], joints: Mapping[str, tuple[str, ...]]
) -> None:
    for name in sensor_names:
        if not name or "," in name or name != name.strip():
            raise RecordingError(f"{path}: invalid sensor name {name!r} (empty, comma, spaces)")
    if len(set(sensor_names)) != len(sensor_names):
        raise RecordingError(f"{path}: duplicate sensor names {sensor_names}")
    for joint, names in joints.items():
        if not joint or "/" in joint:
            raise RecordingError(f"{path}: invalid joint name {joint!r}")
        if "t" in names or len(set(names)) != len(names):
            raise RecordingError(f"{path}: invalid angle names {names} for joint {joint}")


def _metadata_record(
    path: Path,
    sensor_names: tuple[str, ...],
    sensor_units: str,
    sensor_rate_hz: float,
    mocap_rate_hz: float,
    extra: Mapping[str, str] | None,
) -> dict[str, str]:
    record: dict[str, str] = {}
    for key, value in (extra or {}).items():
        if not isinstance(key, str) or not isinstance(value, str):
            raise RecordingError(f"{path}: metadata must be str → str, got {key!r}: {value!r}")
        if key not in RESERVED_KEYS:
            record[key] = value
    record.update(
        {
            "format": FORMAT_NAME,
            "version": str(FORMAT_VERSION),
            "sensors": ",".join(sensor_names),
            "units": f"{sensor_units},{ANGLE_UNIT}",
            "sensor_rate_hz": format_number(sensor_rate_hz),
            "mocap_rate_hz": format_number(mocap_rate_hz),
        }
    )
    return record


def _rounded_times(path: Path, t: np.ndarray, count: int) -> list[float]:
    times = np.asarray(t, dtype=np.float64).reshape(-1)
    if times.size != count:
        raise RecordingError(f"{path}: {times.size} times for {count} rows")
    if not np.all(np.isfinite(times)) or np.any(times < 0):
        raise RecordingError(f"{path}: times must be finite and >= 0 s")
    return np.round(times, TIME_DECIMALS).tolist()


def _rounded_values(
    path: Path, values: np.ndarray, decimals: int, what: str
) -> list[list[float]]:
    if not np.all(np.isfinite(values)):
        raise RecordingError(f"{path}: {what} must be finite (JSON has no NaN/inf)")
    return np.round(values, decimals).tolist()


def write_recording(
    path: str | Path,
    rec: Recording,
    *,
    compression: Compression = "lz4",
    decimals: int = VALUE_DECIMALS,
) -> None:
    """Write ``rec`` to ``path``, all streams interleaved in time order (ties: sensors first,
    then mocap joints in dict order). Identical input gives identical bytes. ``compression``
    and ``decimals`` as for :class:`RecordingWriter`."""
    mocap_items = list(rec.mocap.items())
    with RecordingWriter(
        path,
        rec.sensor_names,
        mocap_joints={joint: stream.names for joint, stream in mocap_items},
        sensor_units=rec.sensor_units,
        sensor_rate_hz=rec.sensor_rate_hz,
        mocap_rate_hz=rec.mocap_rate_hz,
        metadata=rec.metadata,
        compression=compression,
        decimals=decimals,
    ) as writer:
        for segment in rec.segments:
            writer.add_segment(segment)
        streams: list[tuple[np.ndarray, Any]] = []
        if rec.sensor_names:
            sensors = rec.sensors
            streams.append(
                (
                    np.asarray(sensors.t, dtype=np.float64),
                    lambda rows: writer.add_sensor_frames(
                        sensors.seq[rows], sensors.t[rows], sensors.values[rows]
                    ),
                )
            )
        for joint, stream in mocap_items:
            streams.append(
                (
                    np.asarray(stream.t, dtype=np.float64),
                    lambda rows, joint=joint, stream=stream: writer.add_mocap_samples(
                        joint, stream.t[rows], stream.angles[rows]
                    ),
                )
            )
        _write_interleaved(streams)


def _write_interleaved(streams: list[tuple[np.ndarray, Any]]) -> None:
    """Call each stream's writer on runs of consecutive rows, in global time order."""
    if sum(t.size for t, _ in streams) == 0:
        return
    stamps = np.concatenate(
        [np.round(np.round(t, TIME_DECIMALS) * 1e9) for t, _ in streams]
    )
    which = np.concatenate([np.full(t.size, k) for k, (t, _) in enumerate(streams)])
    rows = np.concatenate([np.arange(t.size) for t, _ in streams])
    order = np.lexsort((rows, which, stamps))
    which, rows = which[order], rows[order]
    run_starts = np.flatnonzero(np.diff(which, prepend=-1))
    run_ends = np.append(run_starts[1:], which.size)
    for start, end in zip(run_starts.tolist(), run_ends.tolist(), strict=True):
        streams[int(which[start])][1](rows[start:end])


# ----------------------------------------------------------------------------- reading


@dataclass
class ChannelSummary:
    """One MCAP channel as found in a file.

    Attributes:
        topic, schema_name, message_encoding: as registered.
        message_count: messages on the channel.
        first_t, last_t: first and last log time, seconds (NaN without messages).
        used: False for channels the recording model ignores.
    """

    topic: str
    schema_name: str
    message_encoding: str
    message_count: int
    first_t: float
    last_t: float
    used: bool

    @property
    def mean_rate_hz(self) -> float:
        """(count − 1) / span, Hz; NaN with fewer than two messages or a zero span."""
        span = self.last_t - self.first_t
        if self.message_count < 2 or not span > 0:
            return float("nan")
        return (self.message_count - 1) / span


@dataclass
class RecordingScan:
    """A recording plus what the reader saw on the way: channels and notes."""

    recording: Recording
    channels: list[ChannelSummary]
    notes: list[str] = field(default_factory=list)


def read_recording(path: str | Path) -> Recording:
    """Read a recording format v1 file (see module docstring for what is accepted)."""
    return scan_recording(path).recording


def scan_recording(path: str | Path) -> RecordingScan:
    """Read a recording and report its channels and any notes (ignored channels, defaults)."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise RecordingError(f"{path}: cannot read: {exc.strerror or exc}") from exc
    if not data.startswith(_MAGIC):
        raise RecordingError(f"{path}: not an MCAP file (missing MCAP magic bytes)")
    raw = _read_records(path, data)
    notes: list[str] = []
    metadata = _recording_metadata(path, raw.metadata, notes)
    channels: list[ChannelSummary] = []
    sensor_messages: list[tuple[int, bytes]] = []
    mocap_messages: dict[str, list[tuple[int, bytes]]] = {}
    mocap_schemas: dict[str, Schema | None] = {}
    for channel_id, channel in raw.channels.items():
        messages = raw.messages.get(channel_id, [])
        schema = raw.schemas.get(channel.schema_id)
        used = channel.topic == SENSOR_TOPIC or (
            channel.topic.startswith(MOCAP_PREFIX) and len(channel.topic) > len(MOCAP_PREFIX)
        )
        stamps = [stamp for stamp, _ in messages]
        channels.append(
            ChannelSummary(
                topic=channel.topic,
                schema_name=schema.name if schema else "",
                message_encoding=channel.message_encoding,
                message_count=len(messages),
                first_t=min(stamps) * 1e-9 if stamps else math.nan,
                last_t=max(stamps) * 1e-9 if stamps else math.nan,
                used=used,
            )
        )
        if not used:
            notes.append(f"ignored channel {channel.topic} ({len(messages)} messages)")
            continue
        if channel.message_encoding != MESSAGE_ENCODING:
            raise RecordingError(
                f"{path}: channel {channel.topic} has message encoding "
                f"{channel.message_encoding!r}, expected 'json'"
            )
        if channel.topic == SENSOR_TOPIC:
            sensor_messages.extend(messages)
        else:
            joint = channel.topic[len(MOCAP_PREFIX) :]
            mocap_messages.setdefault(joint, []).extend(messages)
            mocap_schemas.setdefault(joint, schema)
    unknown = set(raw.messages) - set(raw.channels)
    if unknown:
        raise RecordingError(f"{path}: messages on unregistered channel ids {sorted(unknown)}")
    sensor_names = _sensor_names(path, metadata, sensor_messages, notes)
    sensors = _decode_sensors(path, sensor_messages, len(sensor_names))
    mocap = {
        joint: _decode_angles(path, joint, messages, mocap_schemas.get(joint))
        for joint, messages in mocap_messages.items()
    }
    sensor_units = _sensor_units(path, metadata)
    sensor_estimate = (
        _span_rate(float(sensors.seq[-1] - sensors.seq[0]), sensors.t) if len(sensors) else math.nan
    )
    first_mocap = next(iter(mocap.values()), None)
    mocap_estimate = (
        _span_rate(len(first_mocap) - 1.0, first_mocap.t) if first_mocap is not None else math.nan
    )
    recording = Recording(
        sensor_names=sensor_names,
        sensors=sensors,
        mocap=mocap,
        sensor_units=sensor_units,
        sensor_rate_hz=_rate(path, metadata, "sensor_rate_hz", sensor_estimate, notes),
        mocap_rate_hz=_rate(path, metadata, "mocap_rate_hz", mocap_estimate, notes),
        segments=_segments(path, metadata),
        metadata=metadata,
    )
    return RecordingScan(recording=recording, channels=channels, notes=notes)


@dataclass
class _RawFile:
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    messages: dict[int, list[tuple[int, bytes]]] = field(default_factory=dict)
    metadata: list[Metadata] = field(default_factory=list)


def _read_records(path: Path, data: bytes) -> _RawFile:
    raw = _RawFile()
    reader = StreamReader(io.BytesIO(data), validate_crcs=True)
    try:
        for record in reader.records:
            if isinstance(record, Message):
                raw.messages.setdefault(record.channel_id, []).append(
                    (record.log_time, record.data)
                )
            elif isinstance(record, Channel):
                raw.channels.setdefault(record.id, record)
            elif isinstance(record, Schema):
                raw.schemas.setdefault(record.id, record)
            elif isinstance(record, Metadata):
                raw.metadata.append(record)
    except (EndOfFile, struct.error) as exc:
        # A short read: the file stops inside a record (or a length field is corrupt).
        raise RecordingError(f"{path}: truncated MCAP file (ends inside a record)") from exc
    except Exception as exc:
        # Corrupt bytes surface as CRC, decompression (lz4, zstandard), UTF-8 and struct errors
        # from several libraries with no common base class; all mean the same to the caller.
        raise RecordingError(f"{path}: corrupt MCAP data: {type(exc).__name__}: {exc}") from exc
    return raw


def _recording_metadata(path: Path, records: list[Metadata], notes: list[str]) -> dict[str, str]:
    ours = [record for record in records if record.name == METADATA_NAME]
    for record in records:
        if record.name != METADATA_NAME:
            notes.append(f"ignored metadata record {record.name!r}")
    if not ours:
        raise RecordingError(
            f"{path}: no '{METADATA_NAME}' metadata record; not an exohil recording"
        )
    if len(ours) > 1:
        notes.append(f"{len(ours)} '{METADATA_NAME}' records; merged in file order")
    metadata: dict[str, str] = {}
    for record in ours:
        metadata.update(record.metadata)
    found_format = metadata.get("format")
    if found_format != FORMAT_NAME:
        raise RecordingError(
            f"{path}: metadata format is {found_format!r}, expected {FORMAT_NAME!r}"
        )
    found_version = metadata.get("version")
    if found_version != str(FORMAT_VERSION):
        raise RecordingError(
            f"{path}: unsupported recording format version {found_version!r} "
            f"(this reader supports {FORMAT_VERSION})"
        )
    return metadata


def _sensor_names(
    path: Path, metadata: dict[str, str], messages: list[tuple[int, bytes]], notes: list[str]
) -> tuple[str, ...]:
    text = metadata.get("sensors")
    if text is not None:
        return tuple(name.strip() for name in text.split(",") if name.strip())
    if not messages:
        return ()
    try:
        count = len(json.loads(messages[0][1])["values"])
    except (ValueError, KeyError, TypeError) as exc:
        raise RecordingError(f"{path}: {SENSOR_TOPIC} message 0 is not a sensor frame") from exc
    names = DEFAULT_SUIT_SENSORS if count == 4 else tuple(f"ch{k}" for k in range(count))
    notes.append(f"metadata has no 'sensors'; using {','.join(names)}")
    return names


def _decode_sensors(path: Path, messages: list[tuple[int, bytes]], width: int) -> SensorStream:
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
            f"after {seq[k - 1]}"
        )
    return SensorStream(seq=seq, t=t, values=values)


def _decode_angles(
    path: Path, joint: str, messages: list[tuple[int, bytes]], schema: Schema | None
) -> AngleStream:
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
    return AngleStream(t=t, names=names, angles=angles)


def _schema_angle_names(schema: Schema | None) -> tuple[str, ...]:
    """Angle names declared by a jsonschema, in order (``required`` keeps the order that
    sorted ``properties`` lose); used only when a channel has no messages."""
    if schema is None or schema.encoding != SCHEMA_ENCODING:
        return ()
    try:
        declared = json.loads(schema.data)
        names = declared.get("required") or list(declared.get("properties", {}))
    except (ValueError, AttributeError):
        return ()
    return tuple(name for name in names if isinstance(name, str) and name != "t")


def _json_object(path: Path, topic: str, index: int, data: bytes) -> dict[str, Any]:
    try:
        value = json.loads(data)
    except ValueError as exc:
        raise _schema_error(path, topic, index, f"invalid JSON ({exc})") from exc
    if not isinstance(value, dict):
        raise _schema_error(path, topic, index, "message is not a JSON object")
    return value


def _schema_error(path: Path, topic: str, index: int, problem: str) -> RecordingError:
    return RecordingError(f"{path}: {topic} message {index} violates the v1 schema: {problem}")


def _sensor_units(path: Path, metadata: dict[str, str]) -> str:
    text = metadata.get("units", f"mm,{ANGLE_UNIT}")
    sensor_unit, _, angle_unit = text.rpartition(",")
    if not sensor_unit:
        return text or "mm"
    if angle_unit.strip().lower() not in ("deg", "degree", "degrees"):
        raise RecordingError(f"{path}: angle unit {angle_unit!r} unsupported (v1 uses deg)")
    return sensor_unit.strip()


def _rate(
    path: Path, metadata: dict[str, str], key: str, estimate: float, notes: list[str]
) -> float:
    """The metadata rate ``key``; when absent, ``estimate`` (or the v1 default if NaN)."""
    text = metadata.get(key)
    if text is not None:
        try:
            rate = float(text)
        except ValueError:
            rate = math.nan
        if not (math.isfinite(rate) and rate > 0):
            raise RecordingError(f"{path}: metadata {key}={text!r} is not a positive number")
        return rate
    default = DEFAULT_SENSOR_RATE_HZ if key == "sensor_rate_hz" else DEFAULT_MOCAP_RATE_HZ
    rate = estimate if math.isfinite(estimate) and estimate > 0 else default
    notes.append(f"metadata has no {key}; using {format_number(rate)} Hz")
    return rate


def _span_rate(steps: float, t: np.ndarray) -> float:
    """``steps`` sample intervals over the span of ``t`` (s), Hz; NaN for an empty span."""
    span = float(t[-1] - t[0]) if t.size >= 2 else 0.0
    return steps / span if span > 0 else math.nan


def _segments(path: Path, metadata: dict[str, str]) -> list[Segment]:
    text = metadata.get("segments")
    if not text:
        return []
    try:
        items = json.loads(text)
        segments = [Segment(str(s["name"]), float(s["t0"]), float(s["t1"])) for s in items]
    except (ValueError, KeyError, TypeError) as exc:
        raise RecordingError(
            f"{path}: metadata 'segments' is not a JSON list of {{name, t0, t1}}: {exc}"
        ) from exc
    for segment in segments:
        if not (math.isfinite(segment.t0) and math.isfinite(segment.t1)):
            raise RecordingError(f"{path}: segment {segment.name!r} has a non-finite time")
    return segments
