"""Test helper: recording format v1 files written with the raw ``mcap`` Writer, NOT exohil's
writer, so the reader is checked against an independent implementation of the spec."""

from __future__ import annotations

import json
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
