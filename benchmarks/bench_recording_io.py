"""Recording format v1 I/O speed and size (``python -m benchmarks.bench_recording_io``).

A paper-length recording (246 s: 61,500 frames × 4 sensors at 250 Hz, 29,520 shoulder samples at
120 Hz) is written with each compression and read back several times; prints p50/p99/max
seconds, the file size, the per-frame cost of the streaming writer (µs, what a live session pays
at 250 Hz), and the machine.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from exohil.formats.recording import AngleStream, Recording, SensorStream
from exohil.formats.recording_reader import read_recording
from exohil.formats.recording_writer import RecordingWriter, write_recording
from exohil.harness.machine import machine

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


def percentiles(samples: list[float]) -> str:
    p50, p99 = np.percentile(samples, [50, 99])
    return f"p50 {p50:.3f}  p99 {p99:.3f}  max {max(samples):.3f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5, help="timed runs per measurement")
    args = parser.parse_args()
    rec = paper_length_recording()
    print(f"machine: {machine()}")
    samples = len(rec.mocap["shoulder"])
    print(f"recording: {len(rec.sensors)} sensor frames, {samples} mocap samples")
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
            size = path.stat().st_size
            print(f"{compression:>5}: {size / 1e6:6.2f} MB  write s {percentiles(writes)}")
            print(f"{'':>5}  {'':>9}  read  s {percentiles(reads)}")
        per_frame = []
        seq, t, values = rec.sensors.seq, rec.sensors.t, rec.sensors.values
        with RecordingWriter(Path(folder) / "live.mcap", rec.sensor_names) as writer:
            for k in range(20_000):
                start = time.perf_counter()
                writer.add_sensor_frame(int(seq[k]), t[k], values[k])
                per_frame.append((time.perf_counter() - start) * 1e6)
        p50, p99 = np.percentile(per_frame, [50, 99])
        worst = max(per_frame)
        print(f"streaming add_sensor_frame µs: p50 {p50:.1f}  p99 {p99:.1f}  max {worst:.1f}")


if __name__ == "__main__":
    main()
