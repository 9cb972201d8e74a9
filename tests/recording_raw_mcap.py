"""Test helper: recording format v1 files written with the raw ``mcap`` Writer, NOT exohil's
writer, so the reader is checked against an independent implementation of the spec."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from mcap.writer import CompressionType, IndexType, Writer

SENSOR_SCHEMA = {"type": "object", "properties": {"seq": {"type": "integer"}}}
SHOULDER_SCHEMA = {"type": "object", "properties": {"t": {"type": "number"}}}


def write_raw_recording(
    path: Path,
    *,
    duration_s: float = 240.0,
    dropped_every: int = 997,
    compression: CompressionType = CompressionType.LZ4,
    chunked: bool = True,
    summary: bool = True,
    metadata: dict[str, str] | None = None,
    extra_channel: bool = False,
) -> dict[str, int]:
    """Write a 250 Hz sensor + 120 Hz shoulder recording, interleaved in log-time order.

    Every ``dropped_every``-th frame is dropped (a seq gap of 1). Returns the expected counts.
    """
    seq = np.arange(int(round(duration_s * 250.0)))
    seq = seq[(seq % dropped_every) != dropped_every - 1]
    sensor_t = seq * 0.004
    mocap_t = np.arange(int(round(duration_s * 120.0))) / 120.0
    sensor_values = np.round(300.0 + 10 * np.sin(sensor_t[:, None] + np.arange(4)), 3).tolist()
    elv_angle = np.round(30 * np.sin(mocap_t), 3).tolist()
    shoulder_elv = np.round(45 + 40 * np.sin(0.5 * mocap_t), 3).tolist()
    sensor_t_list, mocap_t_list, seq_list = sensor_t.tolist(), mocap_t.tolist(), seq.tolist()
    events = sorted(
        [(round(t * 1e9), 0, k) for k, t in enumerate(sensor_t_list)]
        + [(round(t * 1e9), 1, k) for k, t in enumerate(mocap_t_list)]
    )
    with open(path, "wb") as stream:
        writer = Writer(
            stream,
            chunk_size=32 * 1024,
            compression=compression,
            use_chunking=chunked,
            index_types=IndexType.ALL if summary else IndexType.NONE,
            repeat_channels=summary,
            repeat_schemas=summary,
            use_statistics=summary,
            use_summary_offsets=summary,
        )
        writer.start(profile="", library="independent test writer")
        sensor_schema = writer.register_schema(
            "other.Frame", "jsonschema", json.dumps(SENSOR_SCHEMA).encode()
        )
        mocap_schema = writer.register_schema(
            "other.Angles", "jsonschema", json.dumps(SHOULDER_SCHEMA).encode()
        )
        sensor_channel = writer.register_channel("/suit/sensors", "json", sensor_schema)
        mocap_channel = writer.register_channel("/mocap/shoulder", "json", mocap_schema)
        if extra_channel:
            debug = writer.register_channel("/debug/text", "json", 0)
            writer.add_message(debug, 0, b'{"note":"hello"}', 0)
        writer.add_metadata(
            "exohil.recording",
            metadata
            if metadata is not None
            else {
                "format": "exohil-recording",
                "version": "1",
                "sensors": "F,SF,SR,R",
                "units": "mm,deg",
                "sensor_rate_hz": "250",
                "mocap_rate_hz": "120",
                "operator": "someone else",
            },
        )
        writer.add_metadata("other.lab", {"room": "B12"})
        for stamp, kind, k in events:
            if kind == 0:
                t = round(sensor_t_list[k], 6)
                body = {"t": t, "seq": seq_list[k], "values": sensor_values[k]}
                writer.add_message(sensor_channel, stamp, json.dumps(body).encode(), stamp)
            else:
                body = {
                    "t": round(mocap_t_list[k], 6),
                    "elv_angle": elv_angle[k],
                    "shoulder_elv": shoulder_elv[k],
                    "shoulder_rot": 0.0,
                }
                writer.add_message(mocap_channel, stamp, json.dumps(body).encode(), stamp)
        writer.finish()
    return {
        "sensor_frames": int(seq.size),
        "mocap_samples": int(mocap_t.size),
        "gaps": int(np.sum(np.diff(seq) > 1)),
        "missing": int(np.sum(np.diff(seq) - 1)),
    }


GOOD_METADATA = {"format": "exohil-recording", "version": "1", "sensors": "F,SF,SR,R"}


def write_sensor_messages(
    path: Path,
    sensor_bodies: list[bytes],
    metadata: dict[str, str] | None = None,
    metadata_name: str = "exohil.recording",
    shoulder_bodies: Sequence[bytes] = (),
) -> Path:
    """An unchunked file with the given raw ``/suit/sensors`` message bodies, 4 ms apart (and
    ``/mocap/shoulder`` ones, 10 ms apart)."""
    with open(path, "wb") as stream:
        writer = Writer(stream, compression=CompressionType.NONE, use_chunking=False)
        writer.start()
        schema = writer.register_schema("s", "jsonschema", b"{}")
        channel = writer.register_channel("/suit/sensors", "json", schema)
        writer.add_metadata(metadata_name, GOOD_METADATA if metadata is None else metadata)
        for k, body in enumerate(sensor_bodies):
            writer.add_message(channel, k * 4_000_000, body, k * 4_000_000)
        if shoulder_bodies:
            mocap = writer.register_channel("/mocap/shoulder", "json", schema)
            for k, body in enumerate(shoulder_bodies):
                writer.add_message(mocap, k * 10_000_000, body, k * 10_000_000)
        writer.finish()
    return path


def frame(seq: int, values: list[object] | None = None) -> bytes:
    """A raw sensor message body."""
    return json.dumps({"seq": seq, "t": seq * 0.004, "values": values or [1, 2, 3, 4]}).encode()


BAD_FILE_CASES = {
    "not_mcap": "not an MCAP file",
    "empty": "not an MCAP file",
    "truncated": "truncated",
    "wrong_format": "metadata format is 'rosbag'",
    "wrong_version": "unsupported recording format version '2'",
    "no_metadata": "no 'exohil.recording' metadata",
    "bad_json": "invalid JSON",
    "string_value": "'values' must be a list of numbers",
    "missing_seq": "'seq' must be an integer",
    "wrong_count": "has 3 values; metadata lists 4 sensors",
    "non_monotonic": "non-monotonic seq",
    "bad_segments": "'segments' is not a JSON list",
    "bad_rate": "sensor_rate_hz='fast'",
    "angle_unit": "angle unit 'rad' unsupported",
    "nan_value": "NaN is not a finite number",
    "infinite_value": "number 1e999 is out of range",
    "huge_seq": "is out of range",
    "deep_json": "nested too deeply",
    "negative_time": "times must be finite and >= 0 s",
    "time_goes_back": "time goes back at message 2",
    "deep_segments": "'segments' is not a JSON list",
    "huge_segment_time": "'segments' is not a JSON list",
    "duplicate_sensor": "metadata sensors 'F,SF,F,R' names F twice; each sensor needs its own",
}
"""Bad-file case → the text its RecordingError must contain."""


def write_bad_file(path: Path, case: str) -> Path:
    """Write one of the ``BAD_FILE_CASES`` to ``path``."""
    if case == "not_mcap":
        path.write_text("seq,t,F\n0,0.0,1.0\n")
    elif case == "empty":
        path.write_bytes(b"")
    elif case == "truncated":  # cut before its metadata record: nothing to recover
        write_raw_recording(path, duration_s=2.0)
        path.write_bytes(path.read_bytes()[:40])
    else:
        bodies = {
            "bad_json": [frame(0), b"{seq: 1"],
            "string_value": [frame(0), frame(1, [1, 2, "3", 4])],
            "missing_seq": [b'{"t": 0.0, "values": [1, 2, 3, 4]}'],
            "wrong_count": [frame(0), frame(1, [1, 2, 3])],
            "non_monotonic": [frame(0), frame(5), frame(3)],
            "nan_value": [frame(0), b'{"seq": 1, "t": 0.004, "values": [NaN, 2, 3, 4]}'],
            "infinite_value": [frame(0), b'{"seq": 1, "t": 0.004, "values": [1e999, 2, 3, 4]}'],
            "huge_seq": [frame(0), b'{"seq": ' + b"9" * 4000 + b', "t": 0.004, "values": [1]}'],
            "deep_json": [frame(0), b'{"seq": 1, "t": 0.004, "values": ' + b"[" * 100_000
                          + b"]" * 100_000 + b"}"],
            "negative_time": [b'{"seq": 0, "t": -1.0, "values": [1, 2, 3, 4]}'],
            "time_goes_back": [frame(0), frame(1),
                               b'{"seq": 2, "t": 0.001, "values": [1, 2, 3, 4]}'],
        }.get(case, [frame(0)])
        metadata = {
            "wrong_format": {**GOOD_METADATA, "format": "rosbag"},
            "wrong_version": {**GOOD_METADATA, "version": "2"},
            "bad_segments": {**GOOD_METADATA, "segments": "[{name: x}]"},
            "bad_rate": {**GOOD_METADATA, "sensor_rate_hz": "fast"},
            "angle_unit": {**GOOD_METADATA, "units": "mm,rad"},
            "duplicate_sensor": {**GOOD_METADATA, "sensors": "F,SF,F,R"},
            "deep_segments": {**GOOD_METADATA, "segments": "[" * 100_000 + "]" * 100_000},
            "huge_segment_time": {**GOOD_METADATA,
                                  "segments": '[{"name": "a", "t0": 0, "t1": 1e999}]'},
        }.get(case)
        name = "exohil.recordings" if case == "no_metadata" else "exohil.recording"
        write_sensor_messages(path, bodies, metadata, metadata_name=name)
    return path
