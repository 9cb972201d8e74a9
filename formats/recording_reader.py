"""Reading recording format v1 files (MCAP with JSON messages; see docs/recording-format.md).

:func:`read_recording` (or :func:`scan_recording`, which also reports per-channel statistics
and notes) scans the whole file linearly, so every valid layout reads the same way: chunked or
not, compressed with none/lz4/zstd, with or without summary and indexes, messages in any order
(streams are sorted by log time). Unknown channels and metadata records are ignored with a
note. Any problem raises :class:`~exohil.formats.errors.RecordingError` naming the file.
"""

from __future__ import annotations

import io
import math
import os
import stat
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from mcap.exceptions import EndOfFile
from mcap.records import Channel, Footer, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

from exohil.formats.errors import RecordingError
from exohil.formats.recording import MOCAP_PREFIX, SENSOR_TOPIC, Recording
from exohil.formats.recording_messages import decode_angles, decode_sensors
from exohil.formats.recording_metadata import (
    METADATA_NAME,
    merged_metadata,
    rate,
    segments,
    sensor_names,
    sensor_units,
)
from exohil.formats.schemas import MESSAGE_ENCODING

_MAGIC = b"\x89MCAP0\r\n"


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
    #: bytes after the last complete record of a file that was never closed (no footer), which
    #: are lost; None for a complete file, and for one whose footer is there but whose closing
    #: magic is cut off (every record is in it; a note says so)
    lost_bytes: int | None = None
    #: bytes of the closing MCAP magic missing after the footer (0 when it is whole, or when
    #: the file was cut before its footer)
    magic_missing: int = 0


def read_recording(path: str | Path) -> Recording:
    """Read a recording format v1 file (see module docstring for what is accepted)."""
    return scan_recording(path).recording


def scan_recording(path: str | Path) -> RecordingScan:
    """Read a recording and report its channels and any notes (ignored channels, defaults)."""
    path = Path(path)
    data = _read_mcap_bytes(path)
    raw = _read_records(path, data)
    notes: list[str] = []
    magic_missing = 0
    if raw.cut_at is not None and raw.footer_seen:
        # closed by its writer (the footer is the last record), then cut inside the 8 bytes
        # of MCAP magic that follow it: no record is missing
        magic_missing = len(_MAGIC) - (len(data) - raw.cut_at)
        which = ("its closing MCAP magic (8 bytes) is" if magic_missing == len(_MAGIC) else
                 f"the last {magic_missing} of the 8 bytes of its closing MCAP magic are")
        notes.append(f"cut short after its footer: {which} missing (other MCAP readers may "
                     "refuse it); it was closed and every record is there, so nothing is "
                     "lost; `exohil record recover` writes a clean copy")
    elif raw.cut_at is not None:
        if not any(record.name == METADATA_NAME for record in raw.metadata):
            raise RecordingError(f"{path}: truncated MCAP file (cut at byte {len(data)}, last "
                                 f"complete record at {raw.cut_at}) before any "
                                 f"'{METADATA_NAME}' metadata; nothing to recover")
        what = (f"{len(data) - raw.cut_at} bytes after the last complete record at byte "
                f"{raw.cut_at} are lost" if len(data) > raw.cut_at else
                f"it ends after a complete record (byte {raw.cut_at}), but what its writer "
                "had not yet written out is not in it")
        notes.append(f"cut short: a recording that was never closed (no footer); {what}; "
                     "`exohil record recover` writes a clean copy")
    metadata = merged_metadata(path, raw.metadata, notes)
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
    names = sensor_names(path, metadata, sensor_messages, notes)
    sensors = decode_sensors(path, sensor_messages, len(names))
    mocap = {
        joint: decode_angles(path, joint, messages, mocap_schemas.get(joint))
        for joint, messages in mocap_messages.items()
    }
    sensor_estimate = sensors.rate_from_times()
    first_mocap = next(iter(mocap.values()), None)
    mocap_estimate = (
        _span_rate(len(first_mocap) - 1.0, first_mocap.t) if first_mocap is not None else math.nan
    )
    recording = Recording(
        sensor_names=names,
        sensors=sensors,
        mocap=mocap,
        sensor_units=sensor_units(path, metadata),
        # a recording without sensors has no sensor rate: its absence is not worth a note
        sensor_rate_hz=rate(path, metadata, "sensor_rate_hz", sensor_estimate,
                            notes if names else []),
        mocap_rate_hz=rate(path, metadata, "mocap_rate_hz", mocap_estimate, notes),
        segments=segments(path, metadata),
        metadata=metadata,
    )
    lost = None if raw.cut_at is None or raw.footer_seen else len(data) - raw.cut_at
    return RecordingScan(recording=recording, channels=channels, notes=notes, lost_bytes=lost,
                         magic_missing=magic_missing)


def _read_mcap_bytes(path: Path) -> bytes:
    """The whole file, after checking that it is a regular file that starts like MCAP (so a
    device such as /dev/zero, a FIFO or a large file of something else is never read)."""
    try:
        if not stat.S_ISREG(path.stat().st_mode):  # before open(): a FIFO would block there
            raise RecordingError(f"{path}: not a regular file")
        with open(path, "rb") as stream:
            if not stat.S_ISREG(os.fstat(stream.fileno()).st_mode):
                raise RecordingError(f"{path}: not a regular file")
            head = stream.read(len(_MAGIC))
            if head != _MAGIC:
                raise RecordingError(f"{path}: not an MCAP file (missing MCAP magic bytes)")
            return head + stream.read()
    except OSError as exc:
        raise RecordingError(f"{path}: cannot read: {exc.strerror or exc}") from exc


@dataclass
class _RawFile:
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    messages: dict[int, list[tuple[int, bytes]]] = field(default_factory=dict)
    metadata: list[Metadata] = field(default_factory=list)
    cut_at: int | None = None  #: byte offset where a cut-short file stops parsing
    footer_seen: bool = False  #: whether the footer record (written at close) was read


def _read_records(path: Path, data: bytes) -> _RawFile:
    """Every record of ``data``; a file that ends inside a record (a recording killed before
    it was closed) keeps what came before, with ``cut_at`` set."""
    raw = _RawFile()
    stream = io.BytesIO(data)
    reader = StreamReader(stream, validate_crcs=True)
    complete = 0
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
            elif isinstance(record, Footer):
                raw.footer_seen = True
            complete = stream.tell()
    except (EndOfFile, struct.error):
        # A short read: the file stops inside a record (or a length field is corrupt).
        raw.cut_at = complete
    except Exception as exc:
        # Corrupt bytes surface as CRC, decompression (lz4, zstandard), UTF-8 and struct errors
        # from several libraries with no common base class; all mean the same to the caller.
        raise RecordingError(f"{path}: corrupt MCAP data: {type(exc).__name__}: {exc}") from exc
    return raw


def _span_rate(steps: float, t: np.ndarray) -> float:
    """``steps`` sample intervals over the span of ``t`` (s), Hz; NaN for an empty span."""
    span = float(t[-1] - t[0]) if t.size >= 2 else 0.0
    return steps / span if span > 0 else math.nan
