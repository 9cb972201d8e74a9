"""Discrepancy workflow on clean suits whose motion capture's angles are noisy.

``python -m benchmarks.bench_discrepancy_angle_noise [--seeds 3] [--first-seed 100]
[--noise 0.1,0.3,0.5,1,2] [--duration 90] [--workers N]``

The workflow takes the motion capture's angles as exact once low-passed (method step 1),
so a tracker's white angle noise that the filter leaves reaches the readings' prediction:
a play operator, which ignores reversals narrower than its width, can read it as a loop
(rule 4 refuses one whose gain is only from frame to frame), and stops can clip a map
fitted to noisy angles where it overshoots the readings' range (discrepancy-limitations.md,
"Noise in the motion capture's angles can be read as stops").
Each recording is a clean suit of ``hidden.py``'s random geometry and movement
(:func:`~exohil.emulators.discrepancy.hidden.angle_noise_recording`: 0.15 mm of sensor
noise at 250 Hz, mocap at 120 Hz) with white noise of each SD added to every angle per
sample; one seed keeps the same suit, movement and noise pattern at every SD. Prints one
row per recording (the cutoff the angles were read at, the effects named, the held-out
gap before → after, the noise floor) and, per SD, how many had nothing named.
"""

from __future__ import annotations

import argparse
import functools
import time
from collections import Counter

from benchmarks.report import (
    description,
    non_negative_float,
    positive_float,
    positive_int,
    run_main,
)
from exohil.emulators.discrepancy import run
from exohil.emulators.discrepancy.hidden import angle_noise_recording
from exohil.emulators.discrepancy.workers import parallel_map
from exohil.harness.machine import machine


def noise_levels(value: str) -> tuple[float, ...]:
    """``--noise``: comma-separated SDs, °, each a :func:`non_negative_float`."""
    try:
        return tuple(non_negative_float(item) for item in value.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a list of numbers: {value!r}") from None
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(
            f"each SD must be a finite number ≥ 0: {value!r}") from None


def run_noisy(duration_s: float, case: tuple[int, float]) -> dict:
    """The workflow's summary on seed and SD ``case``'s recording (one process: the cases
    already run in parallel)."""
    seed, noise_deg = case
    return run(angle_noise_recording(seed, noise_deg, duration_s),
               f"s{seed} {noise_deg:g}°", workers=1).summary


def read_as(summary: dict) -> str:
    """The cutoff the angles were read at, or "as sampled"."""
    cutoff = summary["mocap_low_pass_hz"]
    return "as sampled" if cutoff is None else f"{cutoff:g} Hz"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=description(__doc__))
    parser.add_argument("--seeds", type=positive_int, default=3,
                        help="seeds from --first-seed (default 3)")
    parser.add_argument("--first-seed", type=int, default=100, help="first seed (default 100)")
    parser.add_argument("--noise", type=noise_levels, default=(0.1, 0.3, 0.5, 1.0, 2.0),
                        help="white angle noise SDs, ° per sample, comma-separated "
                             "(default 0.1,0.3,0.5,1,2)")
    parser.add_argument("--duration", type=positive_float, default=90.0,
                        help="s per recording (default 90)")
    parser.add_argument("--workers", type=positive_int, default=None,
                        help="processes (default: CPUs)")
    args = parser.parse_args(argv)
    selected = [(seed, sd) for sd in args.noise
                for seed in range(args.first_seed, args.first_seed + args.seeds)]
    print(f"machine: {machine()}")
    print("| angle noise | seed | angles read | effects named | gap before → after, mm | "
          "floor, mm |")
    print("|---|---|---|---|---|---|")
    start = time.perf_counter()
    clean: Counter[float] = Counter()
    for (seed, sd), s in parallel_map(functools.partial(run_noisy, args.duration), selected,
                                      args.workers):
        clean[sd] += not s["effects"]
        print(f"| {sd:g}° | {seed} | {read_as(s)} | {', '.join(s['effects']) or '—'} | "
              f"{s['gap_before']:.3f} → {s['gap_after']:.3f} | {s['noise_floor']:.3f} |",
              flush=True)
    print(f"\n{len(selected)} recordings in {time.perf_counter() - start:.0f} s")
    for sd in args.noise:
        print(f"{sd:g}°: nothing named on {clean[sd]}/{args.seeds}")


if __name__ == "__main__":
    run_main(main)
