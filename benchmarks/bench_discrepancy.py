"""Discrepancy workflow: hidden-effect confusion matrix and timing.

1. Sweep: recordings with exactly one hidden effect (each of the five, two model families —
   ``lib`` = exohil.emulators.effects, ``alt`` = independent implementations — two
   magnitudes, perturbed 3–5-tendon suits, seeds) and clean controls; prints the confusion
   matrix (rows: hidden, columns: first named effect) per family, the rate of right first
   effects, the share of named cases whose held-out gap shrank by ≥ 50 %, and clean → nothing;
   then each named case that did not halve, beside its clean control (the same suit and
   movement without the effect) and its noise floor: where half the gap before is under the
   floor, no model can halve it (a held-out gap keeps the noise).
2. Timing: the workflow on a four-minute 250 Hz recording (the paper protocol fixture, every
   effect on; ``--time-on FILE`` times another recording instead), p50/p99/max over
   ``--repeats`` runs, with the machine. Target: ≤ 60 s. ``--mocap-late SECONDS`` times it
   with its motion capture stamped that late (negative: early): a clock offset, which the
   workflow reads back, and the slowest case measured (docs/discrepancy-results.md).

Run from the repository root: ``python -m benchmarks.bench_discrepancy [--seeds 5]
[--duration 90] [--repeats 3] [--families lib,alt] [--first-seed 1000]``. ``--families other``
runs the third family (hidden.py), which probes effects written yet another way;
``--repeats 0`` skips the timing; ``--workers`` sets how many processes run the sweep's
cases (default one per CPU), ``--time-workers`` how many try each step's candidates in the
timed runs (default one per CPU, as ``exohil discrepancy`` does). ``--motion DIR`` drives
the suits with the real shoulder motion of every ``.mot`` file in DIR, joined in name order
(e.g. ``../shared/realdata/shoulder-ik``), instead of the seeded random movement;
``--duration`` is then the motion's own length. With the defaults (5 seeds: 120 cases) the
sweep takes about 5½ minutes on two cores (docs/discrepancy-results.md), then the timing runs.
"""

from __future__ import annotations

import argparse
import time
from collections import Counter
from dataclasses import replace
from pathlib import Path

import numpy as np

from benchmarks.report import (
    description,
    finite_float,
    non_negative_int,
    positive_float,
    positive_int,
    run_main,
)
from exohil.emulators.discrepancy import run
from exohil.emulators.discrepancy.hidden import (
    FAMILIES,
    KINDS,
    SENSOR_RATE_HZ,
    Case,
    cases,
    first_effect,
    run_cases,
    stamped_late,
)
from exohil.emulators.discrepancy.workers import default_workers, workers_for
from exohil.emulators.protocols import mot_trajectory
from exohil.formats.errors import RecordingError
from exohil.formats.recording import Recording
from exohil.formats.recording_reader import read_recording
from exohil.harness.machine import machine

FIXTURE = Path(__file__).resolve().parents[1] / "fixtures" / "paper_protocol.mcap"


def sweep(seeds: range, duration_s: float, families: tuple[str, ...], workers: int,
          motion: tuple[str, ...] = ()) -> None:
    results, summaries = [], {}
    for case, summary in run_cases(cases(seeds, duration_s=duration_s, families=families,
                                         motion=motion), workers):
        named = first_effect(summary)
        shrink = 1.0 - summary["gap_after"] / summary["gap_before"]
        results.append((case, named, shrink))
        summaries[case] = summary
        print(f"  {case.label:<30} -> {named:<11} gap {summary['gap_before']:.3f} -> "
              f"{summary['gap_after']:.3f} ({shrink:.0%})", flush=True)
    for family in families + ("all",) if len(families) > 1 else families:
        rows = [(case.kind, named, shrink) for case, named, shrink in results
                if family == "all" or case.family == family]
        print_confusion(f"{family}; ", rows)
    print_rates([(case.kind, named, shrink) for case, named, shrink in results])
    print_short_of_half(summaries)


def print_short_of_half(summaries: dict[Case, dict]) -> None:
    """Each named case whose held-out gap did not halve, with its clean control's gap before
    and its noise floor, and how many of them no model could halve: those whose gap before
    is under twice the floor."""
    short = [(case, s) for case, s in summaries.items()
             if first_effect(s) != "clean" and s["gap_after"] > 0.5 * s["gap_before"]]
    if not short:
        return
    print("\nnamed but not halved (gap before -> after; its clean control; half the gap "
          "before against the noise floor):")
    for case, s in short:
        control = summaries.get(replace(case, kind="clean"))
        control_gap = ("(it is one)" if case.kind == "clean" else
                       f"{control['gap_before']:.3f}" if control else "not run")
        print(f"  {case.label:<30} {s['gap_before']:.3f} -> {s['gap_after']:.3f}; clean control "
              f"{control_gap}; half {0.5 * s['gap_before']:.3f} against {s['noise_floor']:.3f}")
    hopeless = sum(s["gap_before"] < 2.0 * s["noise_floor"] for _, s in short)
    print(f"of these {len(short)}, {hopeless} {'has' if hopeless == 1 else 'have'} a gap "
          "before under twice the noise floor: no model can halve them")


def print_confusion(title: str, rows: list[tuple[str, str, float]]) -> None:
    """The confusion matrix of ``(hidden, first named, gap shrink)`` rows."""
    print(f"\nconfusion matrix ({title}rows hidden, columns first named, "
          f"'clean' = nothing named), {len(rows)} cases")
    print(f"{'hidden':<12}" + "".join(f"{c:>11}" for c in KINDS))
    for kind in KINDS:
        counts = Counter(named for hidden, named, _ in rows if hidden == kind)
        print(f"{kind:<12}" + "".join(f"{counts.get(c, 0):>11}" for c in KINDS))


def print_rates(rows: list[tuple[str, str, float]]) -> None:
    """The issue's three rates over ``(hidden, first named, gap shrink)`` rows."""
    effect_rows = [r for r in rows if r[0] != "clean"]
    right = sum(named == hidden for hidden, named, _ in effect_rows)
    named_rows = [r for r in rows if r[1] != "clean"]
    shrunk = sum(shrink >= 0.5 for _, _, shrink in named_rows)
    clean_rows = [r for r in rows if r[0] == "clean"]
    quiet = sum(named == "clean" for _, named, _ in clean_rows)
    print(f"\nfirst named effect right: {right}/{len(effect_rows)} "
          f"({right / max(len(effect_rows), 1):.1%}; required ≥ 90 %)")
    print(f"gap shrank ≥ 50 % when named: {shrunk}/{len(named_rows)} "
          f"({shrunk / max(len(named_rows), 1):.1%}; required: all)")
    print(f"clean → nothing: {quiet}/{len(clean_rows)} "
          f"({quiet / max(len(clean_rows), 1):.1%}; required ≥ 90 %)")


def timing(repeats: int, path: Path = FIXTURE, workers: int | None = None,
           rec: Recording | None = None, mocap_late_s: float = 0.0) -> None:
    """Time the workflow on ``rec`` (read from ``path`` when not given), its motion capture
    stamped ``mocap_late_s`` seconds late (:func:`~.hidden.stamped_late`)."""
    rec = read_recording(path) if rec is None else rec
    span = rec.sensors.t[-1] - rec.sensors.t[0]
    processes = workers_for(workers)
    moved = ""
    if mocap_late_s:
        rec = stamped_late(rec, mocap_late_s)
        moved = (f", motion capture stamped {abs(mocap_late_s):g} s "
                 f"{'late' if mocap_late_s > 0 else 'early'}")
    print(f"\ntiming: {path.name}{moved}, {len(rec.sensors)} sensor frames ({span:.1f} s) x "
          f"{len(rec.sensor_names)} sensors; candidates on {processes} "
          f"process{'es' if processes > 1 else ''}")
    seconds = []
    for _ in range(repeats):
        start = time.perf_counter()
        summary = run(rec, path.name, workers=processes).summary
        seconds.append(time.perf_counter() - start)
    s = np.asarray(seconds)
    print(f"named {summary['effects']}, gap {summary['gap_before']:.3f} -> "
          f"{summary['gap_after']:.3f} {summary['units']}")
    print(f"workflow (without file output)     p50 {np.percentile(s, 50):7.2f} s   "
          f"p99 {np.percentile(s, 99):7.2f} s   max {s.max():7.2f} s   (target ≤ 60 s)")


def main() -> None:
    parser = argparse.ArgumentParser(description=description(__doc__))
    parser.add_argument("--seeds", type=positive_int, default=5, help="seeds per (effect, "
                        "family, magnitude)")
    parser.add_argument("--duration", type=positive_float, default=90.0,
                        help="recording length, s")
    parser.add_argument("--first-seed", type=int, default=1000, help="first seed")
    parser.add_argument("--families", default="lib,alt",
                        help=f"comma-separated, of {', '.join(FAMILIES)}")
    parser.add_argument("--repeats", type=non_negative_int, default=3,
                        help="timing repeats (0: none)")
    parser.add_argument("--no-sweep", action="store_true", help="timing only")
    parser.add_argument("--time-on", type=Path, default=FIXTURE, metavar="FILE",
                        help="the recording to time (default: the paper protocol fixture)")
    parser.add_argument("--mocap-late", type=finite_float, default=0.0, metavar="SECONDS",
                        help="time it with its motion capture stamped SECONDS late "
                             "(negative: early), a clock offset the workflow reads back "
                             "(default 0: as recorded)")
    parser.add_argument("--motion", type=Path, metavar="DIR",
                        help="drive the suits with the real motion of DIR/*.mot (OpenSim "
                             "inverse kinematics), joined in name order")
    parser.add_argument("--workers", type=positive_int, default=default_workers(),
                        help="processes for the sweep (default: one per CPU; the timing "
                             "always runs alone, after it)")
    parser.add_argument("--time-workers", type=positive_int, default=None, metavar="N",
                        help="processes trying each step's candidates in the timed runs "
                             "(default: one per CPU, as `exohil discrepancy`)")
    args = parser.parse_args()
    families = tuple(args.families.split(","))
    if args.no_sweep and args.repeats == 0:
        parser.error("--no-sweep with --repeats 0 does nothing")
    if args.mocap_late and args.repeats == 0:
        parser.error("--mocap-late with --repeats 0 times nothing")
    timed = None
    if args.repeats > 0:  # before the sweep, not after it
        if not args.time_on.is_file():
            parser.error(f"--time-on: no such file: {args.time_on}")
        try:
            timed = read_recording(args.time_on)
        except RecordingError as exc:
            parser.error(f"--time-on: {exc}")
    if not set(families) <= set(FAMILIES):
        parser.error(f"--families: choose from {', '.join(FAMILIES)}")
    motion: tuple[str, ...] = ()
    if args.motion is not None:
        motion = tuple(str(path) for path in sorted(args.motion.glob("*.mot")))
        if not motion:
            parser.error(f"--motion: no .mot file in {args.motion}")
    print(f"machine: {machine()}; numpy {np.__version__}")
    if motion:
        length = mot_trajectory(motion).frame_times(SENSOR_RATE_HZ)[-1]
        print(f"motion: {len(motion)} .mot files from {args.motion} ({length:.1f} s): "
              + ", ".join(Path(path).stem for path in motion))
    if not args.no_sweep:
        sweep(range(args.first_seed, args.first_seed + args.seeds), args.duration, families,
              args.workers, motion)
    if args.repeats > 0:
        timing(args.repeats, args.time_on, args.time_workers, timed, args.mocap_late)


if __name__ == "__main__":
    run_main(main)
