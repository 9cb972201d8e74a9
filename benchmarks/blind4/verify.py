"""Check a blind-4 set against its twins: every recording reads back, its metadata carries no
effect information, and each twin differs from its recording only on the touched sensors
(sequence numbers, times and motion capture identical), by the magnitude its truth gives.

    python -m benchmarks.blind4.verify /tmp/blind4 /tmp/blind4-twins
"""

from __future__ import annotations

import argparse
import json
from collections import Counter
from pathlib import Path

import numpy as np

from benchmarks.report import description
from exohil.formats.recording_reader import read_recording

ALLOWED_METADATA = {"format", "version", "sensors", "units", "sensor_rate_hz", "mocap_rate_hz",
                    "generator", "seed"}


def check_pair(folder: Path, twins: Path, entry: dict, twin: dict) -> bool:
    """One recording against its twin; prints a line and returns whether it holds."""
    rec = read_recording(folder / entry["file"])
    other = read_recording(twins / twin["file"])
    assert set(rec.metadata) <= ALLOWED_METADATA, rec.metadata
    assert rec.metadata == other.metadata
    assert np.array_equal(rec.sensors.seq, other.sensors.seq)
    assert np.array_equal(rec.sensors.t, other.sensors.t)
    mocap, twin_mocap = rec.mocap["shoulder"], other.mocap["shoulder"]
    assert np.array_equal(mocap.angles, twin_mocap.angles)
    assert np.array_equal(mocap.t, twin_mocap.t)
    delta = rec.sensors.values - other.sensors.values
    names = rec.sensor_names
    changed = [n for n, col in zip(names, delta.T, strict=True) if np.abs(col).max() > 0]
    touched = entry["sensors_touched"]
    ok = set(changed) <= set(touched)
    if entry["noise_kind"] != "gauss_quant":  # quantisation can hide a tiny difference
        ok = ok and (entry["effect"] == "clean") == (not changed)
    sd = np.array([entry["noise_sd"][n] for n in names])
    per_sensor = np.sqrt(np.mean(delta**2, axis=0)) / sd
    index = [names.index(n) for n in touched]
    magnitude = float(np.sqrt(np.mean(per_sensor[index] ** 2))) if touched else 0.0
    gaps = int((np.diff(rec.sensors.seq) > 1).sum())
    print(f"{entry['file']} {entry['effect']:10s} {entry['family']:38s} {rec.sensor_units:10s} "
          f"S={len(names):2d} N={len(rec.sensors):6d} M={len(mocap):6d} gaps={gaps:3d} "
          f"mag(truth)={entry['magnitude_x_noise']:.2f} mag(files)={magnitude:.2f} "
          f"changed={len(changed)}/{len(touched)} {'OK' if ok else 'BAD'}")
    return ok


def main() -> None:
    parser = argparse.ArgumentParser(description=description(__doc__))
    parser.add_argument("folder", type=Path, help="the recordings and truth.json")
    parser.add_argument("twins", type=Path, help="their twins (--without-effect)")
    args = parser.parse_args()
    keys = [folder / "truth.json" for folder in (args.folder, args.twins)]
    missing = [str(key) for key in keys if not key.is_file()]
    if missing:
        parser.error(f"{missing[0]} not found (the answer key written with the recordings)")
    truth, twins = (json.loads(key.read_text()) for key in keys)
    assert len(truth) == len(twins)
    print(Counter(e["effect"] for e in truth), Counter(e["effect"] for e in twins))
    bad = sum(not check_pair(args.folder, args.twins, e, t)
              for e, t in zip(truth, twins, strict=True))
    print("bad", bad)
    raise SystemExit(1 if bad else 0)


if __name__ == "__main__":
    main()
