"""Writing recording format v1 files (MCAP with JSON messages; see docs/recording-format.md).

:class:`RecordingWriter` streams frames and mocap samples into a file as they come (live
sessions); :func:`write_recording` writes a whole in-memory :class:`Recording`, interleaving
all streams in time order. Output is deterministic: no wall-clock times, fixed chunk size and
compression, canonical JSON, sensor values and angles rounded to 1e-4 (mm, deg) and times to
1e-6 s (:mod:`exohil.formats.recording_messages`), the metadata record written at close
(:mod:`exohil.formats.recording_metadata`).

A *durable* :class:`RecordingWriter` (live recordings) trades that determinism for safety: the
metadata record goes first, and at least every :data:`DURABLE_FLUSH_S` seconds the chunk in
progress is written out and the file synced to disk, so a killed process or a power cut loses
at most that last second; the reader then reads the file and notes that it was cut short.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, BinaryIO, Literal

import numpy as np
from mcap.writer import CompressionType, Writer

from exohil.formats.atomic import replacing
from exohil.formats.errors import RecordingError
from exohil.formats.recording import MOCAP_PREFIX, SENSOR_TOPIC, Recording, Segment
from exohil.formats.recording_messages import (
    TIME_DECIMALS,
    VALUE_DECIMALS,
    encode_message,
    rounded_times,
    rounded_values,
    seconds_to_ns,
    sensor_decimals,
)
from exohil.formats.recording_metadata import (
    DEFAULT_MOCAP_RATE_HZ,
    DEFAULT_SENSOR_RATE_HZ,
    METADATA_NAME,
    RESERVED_KEYS,
    metadata_record,
    plain_field,
    segments_text,
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

CHUNK_SIZE = 1 << 20
#: A durable writer closes a chunk and syncs the file at least this often (wall clock, s).
DURABLE_FLUSH_S = 1.0
WRITER_LIBRARY = "exohil recording writer, format v1"
Compression = Literal["none", "lz4", "zstd"]
_COMPRESSION = {
    "none": CompressionType.NONE,
    "lz4": CompressionType.LZ4,
    "zstd": CompressionType.ZSTD,
}


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
        sensor_decimals: decimal places kept for sensor values, where they differ from
            ``decimals`` (:func:`write_recording` keeps more for readings in small units).
        durable: write the metadata first and close a chunk and sync the file at least every
            :data:`DURABLE_FLUSH_S` s, so a killed writer leaves a readable file (module doc).
        name: the file as error messages name it (default ``path``; the final name when
            ``path`` is a temporary one).
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
        sensor_decimals: int | None = None,
        durable: bool = False,
        name: str | Path | None = None,
    ) -> None:
        self.path = Path(path)
        self.name = Path(name) if name is not None else self.path
        self.durable = durable
        self.decimals = decimals
        self.sensor_decimals = decimals if sensor_decimals is None else sensor_decimals
        self.sensor_names = tuple(sensor_names)
        self.mocap_joints = {joint: tuple(names) for joint, names in (mocap_joints or {}).items()}
        check_names(self.name, self.sensor_names, self.mocap_joints)
        if compression not in _COMPRESSION:
            raise ValueError(f"compression must be one of {sorted(_COMPRESSION)}")
        self._metadata = metadata_record(
            self.name, self.sensor_names, sensor_units, sensor_rate_hz, mocap_rate_hz, metadata
        )
        self._segments: list[Segment] = []
        self._late: dict[str, str] = {}
        self._last_seq: int | None = None
        self._last_t = 0.0
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
        self._next_sync = time.monotonic() + DURABLE_FLUSH_S
        if durable:
            self._writer.add_metadata(METADATA_NAME, dict(sorted(self._metadata.items())))
            self._sync()

    def _sync(self) -> None:
        """Write out the chunk in progress and push the file to disk."""
        self._writer.flush()
        os.fsync(self._file.fileno())
        self._next_sync = time.monotonic() + DURABLE_FLUSH_S

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
            raise RecordingError(f"{self.name}: this recording was opened without sensors")
        given = np.asarray(seq)
        if given.ndim != 1 or (given.size and not np.issubdtype(given.dtype, np.integer)
                               and not np.all(np.mod(given, 1) == 0)):
            raise RecordingError(f"{self.name}: sensor seq must be a 1-D array of whole "
                                 f"numbers, got shape {given.shape} {given.dtype}")
        seq = given.astype(np.int64)
        values = np.asarray(values, dtype=np.float64)
        if values.ndim != 2 or values.shape != (seq.size, len(self.sensor_names)):
            raise RecordingError(
                f"{self.name}: sensor frames must be ({seq.size}, {len(self.sensor_names)}), "
                f"got {values.shape}"
            )
        previous = np.concatenate(([self._last_seq], seq)) if self._last_seq is not None else seq
        if np.any(np.diff(previous) <= 0):
            raise RecordingError(f"{self.name}: sensor seq must increase strictly")
        times = rounded_times(self.name, t, seq.size)
        if times and (times[0] < self._last_t or np.any(np.diff(times) < 0)):
            raise RecordingError(f"{self.name}: sensor times must not go back (the reader "
                                 "refuses such a file)")
        rows = rounded_values(self.name, values, self.sensor_decimals, "sensor values")
        for frame_seq, frame_t, frame_values in zip(seq.tolist(), times, rows, strict=True):
            payload = {"seq": frame_seq, "t": frame_t, "values": frame_values}
            self._emit(self._sensor_channel, frame_t, payload)
        if seq.size:
            self._last_seq = int(seq[-1])
            self._last_t = times[-1]

    def add_mocap_sample(self, joint: str, t: float, angles: Sequence[float]) -> None:
        """Append one mocap sample of ``joint`` at ``t`` (s); ``angles`` in degrees."""
        self.add_mocap_samples(joint, np.asarray([t]), np.asarray([angles]))

    def add_mocap_samples(self, joint: str, t: np.ndarray, angles: np.ndarray) -> None:
        """Append samples of ``joint``: ``t`` (M,) s, ``angles`` (M, A) degrees."""
        self._check_open()
        if joint not in self._mocap_channels:
            raise RecordingError(f"{self.name}: joint {joint!r} was not declared at open")
        names = self.mocap_joints[joint]
        angles = np.asarray(angles, dtype=np.float64)
        times = rounded_times(self.name, t, angles.shape[0] if angles.ndim else -1)
        if angles.ndim != 2 or angles.shape[1] != len(names):
            raise RecordingError(
                f"{self.name}: {joint} angles must be (M, {len(names)}), got {angles.shape}"
            )
        rows = rounded_values(self.name, angles, self.decimals, f"{joint} angles")
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
            raise RecordingError(f"{self.name}: {topic} is a format v1 topic; use the "
                                 "sensor/mocap methods")
        return self._register(topic, schema_name, schema)

    def add_message(self, channel: int, t: float, payload: Mapping[str, Any]) -> None:
        """Append one JSON message at ``t`` (s) to a channel from :meth:`add_channel`
        (finite numbers only: JSON has no NaN)."""
        self._check_open()
        if channel not in self._counts or channel == self._sensor_channel \
                or channel in self._mocap_channels.values():
            raise RecordingError(f"{self.name}: channel {channel} was not added by add_channel")
        self._emit(channel, rounded_times(self.name, np.asarray([t]), 1)[0], dict(payload))

    def add_segment(self, segment: Segment) -> None:
        """Label a time span (seconds on the sensor clock); stored in the metadata at close.
        RecordingError now, not at close, for a span the reader would refuse."""
        self._check_open()
        if not isinstance(segment, Segment) or not isinstance(segment.name, str):
            raise RecordingError(f"{self.name}: a segment is a Segment(name, t0, t1), got "
                                 f"{segment!r}")
        try:
            t0, t1 = float(segment.t0), float(segment.t1)
        except (TypeError, ValueError):
            raise RecordingError(f"{self.name}: segment {segment.name!r} needs numbers for "
                                 f"t0 and t1, got {segment.t0!r}, {segment.t1!r}") from None
        if not (math.isfinite(t0) and math.isfinite(t1) and t0 <= t1):
            raise RecordingError(f"{self.name}: segment {segment.name!r} spans {t0} .. {t1} s: "
                                 "finite times, t0 <= t1")
        self._segments.append(Segment(segment.name, t0, t1))

    def add_metadata(self, extra: Mapping[str, str]) -> None:
        """Provenance known only at the end (e.g. a measured rate): stored in the metadata
        record written at close (a durable file then holds a second record, merged on read).
        The format's own keys cannot be changed this way."""
        self._check_open()
        fixed = set(extra) & RESERVED_KEYS
        if fixed:
            raise RecordingError(f"{self.name}: cannot change {sorted(fixed)} at close")
        self._late.update({str(k): str(v) for k, v in extra.items()})

    def _emit(self, channel: int, t: float, payload: dict[str, Any]) -> None:
        data = encode_message(payload)
        stamp = seconds_to_ns(t)
        self._writer.add_message(
            channel_id=channel,
            log_time=stamp,
            publish_time=stamp,
            data=data,
            sequence=self._counts[channel] & 0xFFFFFFFF,
        )
        self._counts[channel] += 1
        if self.durable and time.monotonic() >= self._next_sync:
            self._sync()

    def _check_open(self) -> None:
        if self._closed:
            raise RecordingError(f"{self.name}: writer already closed")

    def close(self) -> None:
        """Write the metadata record and the summary, and close the file (idempotent)."""
        if self._closed:
            return
        self._closed = True
        try:
            metadata = dict(self._metadata)
            if self._segments:
                metadata["segments"] = segments_text(self._segments)
            metadata.update(self._late)
            if not self.durable or self._segments or self._late:  # durable: has it already
                self._writer.add_metadata(METADATA_NAME, dict(sorted(metadata.items())))
            self._writer.finish()
            if self.durable:
                self._file.flush()
                os.fsync(self._file.fileno())
        finally:
            self._file.close()


def check_names(
    where: str | Path, sensor_names: tuple[str, ...], joints: Mapping[str, tuple[str, ...]]
) -> None:
    """Refuse (:class:`RecordingError`, prefixed by ``where``: the file written, or where the
    names came from) names the format cannot hold: empty, with a comma or outer spaces, or
    twice; a joint with a slash; an angle named ``t``."""
    for name in sensor_names:
        if not plain_field(name):
            raise RecordingError(f"{where}: invalid sensor name {name!r} (empty, comma, spaces)")
    if len(set(sensor_names)) != len(sensor_names):
        raise RecordingError(f"{where}: duplicate sensor names {sensor_names}")
    for joint, names in joints.items():
        if not joint or "/" in joint:
            raise RecordingError(f"{where}: invalid joint name {joint!r}")
        if "t" in names or len(set(names)) != len(names):
            raise RecordingError(f"{where}: invalid angle names {names} for joint {joint}")


def write_recording(
    path: str | Path,
    rec: Recording,
    *,
    compression: Compression = "lz4",
    decimals: int = VALUE_DECIMALS,
) -> None:
    """Write ``rec`` to ``path``, all streams interleaved in time order (ties: sensors first,
    then mocap joints in dict order). Identical input gives identical bytes. ``compression``
    and ``decimals`` as for :class:`RecordingWriter`; sensor values keep more decimals where
    a sensor's range needs them (:func:`~exohil.formats.recording_messages.sensor_decimals`).
    Written under a temporary name and renamed when complete (:mod:`formats.atomic`):
    ``path`` is never left half-written."""
    with replacing(path) as tmp:
        _write_recording(tmp, Path(path), rec, compression, decimals)


def _write_recording(path: Path, name: Path, rec: Recording, compression: Compression,
                     decimals: int) -> None:
    mocap_items = list(rec.mocap.items())
    with RecordingWriter(
        path,
        rec.sensor_names,
        name=name,
        mocap_joints={joint: stream.names for joint, stream in mocap_items},
        sensor_units=rec.sensor_units,
        sensor_rate_hz=rec.sensor_rate_hz,
        mocap_rate_hz=rec.mocap_rate_hz,
        metadata=rec.metadata,
        compression=compression,
        decimals=decimals,
        sensor_decimals=sensor_decimals(rec.sensors.values, decimals),
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
