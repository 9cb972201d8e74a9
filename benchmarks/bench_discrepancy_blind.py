"""Discrepancy workflow on recordings written by other code, scored against their answer key.

DIR holds recordings and ``truth.json``: a list of ``{"file", "effect", "family",
"magnitude_x_noise", ...}``, one per recording, ``effect`` one of the vocabulary or ``clean``
(the layout ``benchmarks/blind3/generate.py`` writes). Each recording goes through
``exohil discrepancy``'s workflow as a user would run it (no hint of the effect); the benchmark
prints one line per recording, the confusion matrix (rows hidden, columns first named) and the
issue's three rates. ``--out RUNS`` also keeps each recording's ``discrepancy.json`` summary.

``--twins TWIN_RUNS`` scores by what the data can show: TWIN_RUNS holds the summaries of each
recording's clean twin (the same recording written without its effect, e.g. by
``benchmarks/blind3/generate.py --without-effect``, run through this benchmark with ``--out``;
--out never names TWIN_RUNS, whose summaries it would overwrite). Each effect's line then says
what it adds to the gap before any effect is fitted, in noise variances, (gap² − twin gap²) /
floor², and the rate of right first names is printed apart for the effects that add at least
one: what the static map takes in of an effect, or what is left under the noise, no model can
name.

A recording that cannot be read is reported on its line and left out of the scores; the
others still run.

Run from the repository root::

    python -m benchmarks.blind3.generate --out /tmp/blind3
    python -m benchmarks.bench_discrepancy_blind /tmp/blind3 [--workers N] [--out RUNS]
    python -m benchmarks.blind3.generate --out /tmp/blind3-twins --without-effect
    python -m benchmarks.bench_discrepancy_blind /tmp/blind3-twins --out /tmp/twin-runs
    python -m benchmarks.bench_discrepancy_blind /tmp/blind3 --twins /tmp/twin-runs
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

from benchmarks.bench_discrepancy import print_confusion, print_rates
from benchmarks.report import (
    BenchmarkError,
    description,
    out_folder,
    positive_int,
    refuse_overwrite,
    run_main,
)
from exohil.emulators.discrepancy import run
from exohil.emulators.discrepancy.hidden import KINDS, first_effect
from exohil.emulators.discrepancy.workers import default_workers, parallel_map
from exohil.formats.atomic import write_text
from exohil.formats.errors import InputError
from exohil.formats.recording_reader import read_recording
from exohil.harness.machine import machine


def run_file(path: Path) -> dict:
    """The workflow's summary on one recording, with the seconds it took; ``{"error": why}``
    for a recording that cannot be read or run (bad input, not a bug)."""
    start = time.perf_counter()
    try:
        summary = run(read_recording(path), path.stem).summary
    except InputError as exc:
        return {"error": str(exc)}
    return {**summary, "seconds": round(time.perf_counter() - start, 1)}


def load_truth(folder: Path) -> list[dict]:
    """The answer key, checked: every entry names an existing file and a known effect."""
    key = folder / "truth.json"
    if not key.is_file():
        raise InputError(f"{key} not found (the answer key this benchmark scores against)")
    try:
        truth = json.loads(key.read_text())
    except json.JSONDecodeError as exc:
        raise InputError(f"{key}: not JSON ({exc})") from None
    if not isinstance(truth, list) or not all(isinstance(e, dict) for e in truth):
        raise InputError(f"{key}: must be a list of objects, one per recording")
    if not truth:
        raise InputError(f"{key}: lists no recording")
    for entry in truth:
        if entry.get("effect") not in KINDS or not (folder / str(entry.get("file"))).is_file():
            raise InputError(f"{key}: bad entry {entry.get('file')!r} "
                             f"(effect must be one of {', '.join(KINDS)}, file must exist)")
    return truth


def load_twins(folder: Path, truth: list[dict]) -> dict[str, float]:
    """The clean twins' gaps before any effect, by recording file, for every recording with
    an effect (from their summaries in ``folder``); refused with one line, before any
    recording is run, when one is missing or unreadable."""
    twins = {}
    for entry in truth:
        if entry["effect"] == "clean":
            continue
        path = folder / f"{Path(entry['file']).stem}.json"
        try:
            twin = json.loads(path.read_text())
            twins[entry["file"]] = float(twin["gap_before"])
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise InputError(f"{path}: no twin summary with a gap_before ({exc}); "
                             f"run the twins with --out {folder} first") from None
    return twins


def added_over_twin(summary: dict, twin_gap: float) -> float:
    """What a hidden effect adds to the gap before any effect is fitted, in noise variances:
    (gap² − twin gap²) / floor², ``twin_gap`` being that gap on the same recording without
    the effect.
    Below zero where the two recordings' static maps differ by more than the effect; ±inf
    for a recording without noise (a floor of 0) whose gap differs from its twin's."""
    added = summary["gap_before"] ** 2 - twin_gap**2
    floor = summary["noise_floor"] ** 2
    if floor > 0:
        return added / floor
    return math.copysign(math.inf, added) if added else 0.0


def print_shown_rates(rows: list[tuple[str, str, float]]) -> None:
    """Right first names over ``(hidden, first named, added over twin)`` effect rows, apart
    for the effects that add at least one noise variance to their twin and those that add
    less."""
    for label, part in (("add ≥ 1 noise variance to their twin", [r for r in rows if r[2] >= 1]),
                        ("add less", [r for r in rows if r[2] < 1])):
        right = sum(named == hidden for hidden, named, _ in part)
        print(f"effects that {label}: named right first {right}/{len(part)} "
              f"({right / max(len(part), 1):.1%})")


def main() -> None:
    parser = argparse.ArgumentParser(description=description(__doc__))
    parser.add_argument("folder", type=Path, help="recordings and their truth.json")
    parser.add_argument("--workers", type=positive_int, default=default_workers(),
                        help="processes running recordings side by side (default: one per CPU)")
    parser.add_argument("--out", type=out_folder,
                        help="folder for each recording's summary JSON")
    parser.add_argument("--twins", type=Path, metavar="TWIN_RUNS",
                        help="the clean twins' summary JSON (an earlier --out): also score "
                             "by what each effect adds to its twin's gap")
    args = parser.parse_args()
    truth = load_truth(args.folder)
    twins = load_twins(args.twins, truth) if args.twins else {}
    if args.out:
        inputs = [args.folder / "truth.json", *(args.folder / e["file"] for e in truth)]
        inputs += [args.twins / f"{Path(e['file']).stem}.json" for e in truth] if args.twins \
            else []
        for entry in truth:
            refuse_overwrite(parser, "--out", args.out / f"{Path(entry['file']).stem}.json",
                             inputs)
    print(f"machine: {machine()}")
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
    rows, shown, unreadable = [], [], 0
    paths = [args.folder / entry["file"] for entry in truth]
    for (path, summary), entry in zip(parallel_map(run_file, paths, args.workers), truth,
                                      strict=True):
        if "error" in summary:
            unreadable += 1
            print(f"  {path.stem:<8} {entry['effect']:<11} not scored: {summary['error']}",
                  flush=True)
            continue
        named = first_effect(summary)
        shrink = 1.0 - summary["gap_after"] / summary["gap_before"]
        rows.append((entry["effect"], named, shrink))
        added = ""
        if entry["file"] in twins:
            over = added_over_twin(summary, twins[entry["file"]])
            shown.append((entry["effect"], named, over))
            added = f" {over:+.2f} σ²"
        print(f"  {path.stem:<8} {entry['effect']:<11} {entry.get('family', ''):<26} "
              f"{entry.get('magnitude_x_noise', 0):5.2f}× -> "
              f"{','.join(summary['effects']) or 'clean':<24} gap {summary['gap_before']:.4g} -> "
              f"{summary['gap_after']:.4g} {summary['units']} (floor "
              f"{summary['noise_floor']:.4g}) {summary['seconds']} s{added}", flush=True)
        if args.out:
            write_text(args.out / f"{path.stem}.json", json.dumps(summary, indent=1))
    if not rows:
        raise BenchmarkError(f"none of the {len(truth)} recordings could be run")
    if unreadable:
        print(f"\n{unreadable} of {len(truth)} recordings could not be run: left out")
    print_confusion("", rows)
    print_rates(rows)
    if args.twins:
        print_shown_rates(shown)


if __name__ == "__main__":
    run_main(main, interrupted="summaries already written to --out are kept")
