"""Discrepancy workflow on recordings written by other code, scored against their answer key.

DIR holds recordings and ``truth.json``: a list of ``{"file", "effect", "family",
"magnitude_x_noise", ...}``, one per recording, ``effect`` one of the vocabulary or ``clean``
(the layout ``benchmarks/blind3/generate.py`` writes). Each recording goes through
``exohil discrepancy``'s workflow as a user would run it (no hint of the effect); the benchmark
prints one line per recording, the confusion matrix (rows hidden, columns first named) and the
issue's three rates. ``--out RUNS`` also keeps each recording's ``discrepancy.json`` summary.

Run from the repository root::

    python -m benchmarks.blind3.generate --out /tmp/blind3
    python -m benchmarks.bench_discrepancy_blind /tmp/blind3 [--workers N] [--out RUNS]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from benchmarks.bench_discrepancy import print_confusion, print_rates
from exohil.emulators.discrepancy import run
from exohil.emulators.discrepancy.hidden import KINDS, first_effect
from exohil.emulators.discrepancy.workers import default_workers, parallel_map
from exohil.formats.atomic import write_text
from exohil.formats.recording_reader import read_recording
from exohil.harness.machine import machine


def run_file(path: Path) -> dict:
    """The workflow's summary on one recording, with the seconds it took."""
    start = time.perf_counter()
    summary = run(read_recording(path), path.stem).summary
    return {**summary, "seconds": round(time.perf_counter() - start, 1)}


def load_truth(folder: Path) -> list[dict]:
    """The answer key, checked: every entry names an existing file and a known effect."""
    key = folder / "truth.json"
    if not key.is_file():
        raise SystemExit(f"error: {key} not found (the answer key this benchmark scores against)")
    try:
        truth = json.loads(key.read_text())
    except json.JSONDecodeError as exc:
        raise SystemExit(f"error: {key}: not JSON ({exc})") from None
    if not isinstance(truth, list) or not all(isinstance(e, dict) for e in truth):
        raise SystemExit(f"error: {key}: must be a list of objects, one per recording")
    for entry in truth:
        if entry.get("effect") not in KINDS or not (folder / str(entry.get("file"))).is_file():
            raise SystemExit(f"error: {key}: bad entry {entry.get('file')!r} "
                             f"(effect must be one of {', '.join(KINDS)}, file must exist)")
    return truth


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path, help="recordings and their truth.json")
    parser.add_argument("--workers", type=int, default=default_workers(),
                        help="processes running recordings side by side (default: one per CPU)")
    parser.add_argument("--out", type=Path, help="folder for each recording's summary JSON")
    args = parser.parse_args()
    truth = load_truth(args.folder)
    print(f"machine: {machine()}")
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    paths = [args.folder / entry["file"] for entry in truth]
    for (path, summary), entry in zip(parallel_map(run_file, paths, args.workers), truth,
                                      strict=True):
        named = first_effect(summary)
        shrink = 1.0 - summary["gap_after"] / summary["gap_before"]
        rows.append((entry["effect"], named, shrink))
        print(f"  {path.stem:<8} {entry['effect']:<11} {entry.get('family', ''):<26} "
              f"{entry.get('magnitude_x_noise', 0):5.2f}× -> "
              f"{','.join(summary['effects']) or 'clean':<24} gap {summary['gap_before']:.4g} -> "
              f"{summary['gap_after']:.4g} {summary['units']} (floor "
              f"{summary['noise_floor']:.4g}) {summary['seconds']} s", flush=True)
        if args.out:
            write_text(args.out / f"{path.stem}.json", json.dumps(summary, indent=1))
    print_confusion("", rows)
    print_rates(rows)


if __name__ == "__main__":
    main()
