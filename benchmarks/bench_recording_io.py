"""Recording format v1 I/O speed and size (``python -m benchmarks.bench_recording_io``).

A paper-length recording (246 s: 61,500 frames × 4 sensors at 250 Hz, 29,520 shoulder samples at
120 Hz) is written with each compression and read back several times. Reports, through
:mod:`benchmarks.report` with the machine: p50/p99/max write and read time (s) and the file
size (bytes) per compression, and p50/p99/max per-frame cost of the streaming writer (µs, what a
live session pays at 250 Hz). No goal is stated for these figures, so all are INFO.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.report import parser, positive_int, report, run_main
from exohil.formats.measurement import Measurement, distribution
from exohil.formats.recording import AngleStream, Recording, SensorStream
from exohil.formats.recording_reader import read_recording
from exohil.formats.recording_writer import RecordingWriter, write_recording

SECONDS = 246.0
SHOULDER_ANGLES = ("elv_angle", "shoulder_elv", "shoulder_rot")


def paper_length_recording(seconds: float = SECONDS) -> Recording:
    """Smooth synthetic tendon lengths (mm) and shoulder angles (deg) with 1 in 500 frames lost."""
    rng = np.random.default_rng(0)
    seq = np.arange(int(seconds * 250))
    seq = seq[rng.random(seq.size) > 0.002]
    t = seq / 250.0
    elevation = 45 - 40 * np.cos(2 * np.pi * t / 8)
    values = 300 + np.outer(elevation, [0.9, 1.1, -0.7, -0.5]) + rng.normal(0, 0.05, (t.size, 4))
    mocap_t = np.arange(int(seconds * 120)) / 120.0
    angles = np.column_stack(
        [30 * np.sin(mocap_t / 3), 45 - 40 * np.cos(2 * np.pi * mocap_t / 8), 0 * mocap_t]
    )
    return Recording(
        sensor_names=("F", "SF", "SR", "R"),
        sensors=SensorStream(seq, t, values),
        mocap={"shoulder": AngleStream(mocap_t, SHOULDER_ANGLES, angles)},
    )


def main() -> None:
    ap = parser(__doc__)
    ap.add_argument("--repeats", type=positive_int, default=5,
                    help="timed runs per measurement")
    args = ap.parse_args()
    rec = paper_length_recording()
    samples = len(rec.mocap["shoulder"])
    print(f"recording: {len(rec.sensors)} sensor frames, {samples} mocap samples")
    measurements: list[Measurement] = []
    with tempfile.TemporaryDirectory() as folder:
        for compression in ("lz4", "zstd", "none"):
            path = Path(folder) / f"{compression}.mcap"
            writes, reads = [], []
            for _ in range(args.repeats):
                start = time.perf_counter()
                write_recording(path, rec, compression=compression)
                writes.append(time.perf_counter() - start)
                start = time.perf_counter()
                read_recording(path)
                reads.append(time.perf_counter() - start)
            measurements.append(Measurement.judge(f"{compression}.size", path.stat().st_size,
                                                  "B"))
            measurements += distribution(f"{compression}.write", writes, "s")
            measurements += distribution(f"{compression}.read", reads, "s")
        per_frame = []
        seq, t, values = rec.sensors.seq, rec.sensors.t, rec.sensors.values
        with RecordingWriter(Path(folder) / "live.mcap", rec.sensor_names) as writer:
            for k in range(20_000):
                start = time.perf_counter()
                writer.add_sensor_frame(int(seq[k]), t[k], values[k])
                per_frame.append((time.perf_counter() - start) * 1e6)
    measurements += distribution("streaming.add_sensor_frame", per_frame, "us",
                                 note="lz4, 1 MiB chunks")
    report("bench_recording_io", measurements, args.json)


if __name__ == "__main__":
    run_main(main)
