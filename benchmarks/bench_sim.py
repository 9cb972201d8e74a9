"""Suit simulation speed: the full Table III protocol (≈ 246 s, 61,565 frames × 4 sensors at
250 Hz) with every effect of the default profile on. Target: ≤ 2 s per simulation.

Run from the repository root: ``python -m benchmarks.bench_sim [--repeats N]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from exohil.emulators.effects import Signal
from exohil.emulators.protocols import paper_protocol
from exohil.emulators.simulate import geometric_signal, simulate
from exohil.emulators.suit_profile import load_default_profile
from exohil.harness.machine import machine


def timings(fn, repeats: int) -> np.ndarray:
    out = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        out.append(time.perf_counter() - start)
    return np.asarray(out)


def report(label: str, seconds: np.ndarray) -> None:
    p50, p99, worst = np.percentile(seconds, 50), np.percentile(seconds, 99), seconds.max()
    print(f"{label:<34} p50 {p50:7.3f} s   p99 {p99:7.3f} s   max {worst:7.3f} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=10)
    args = parser.parse_args()
    print(f"machine: {machine()}; numpy {np.__version__}")
    profile = load_default_profile()
    trajectory = paper_protocol(seed=1)
    ideal = geometric_signal(trajectory, profile)
    kinds = ", ".join(e.name for e in profile.effects.effects)
    print(f"protocol: {trajectory.duration_s:.1f} s, {len(ideal.t)} sensor frames x "
          f"{ideal.n_sensors} sensors, effects: {kinds}")
    report("full simulate() (all effects)",
           timings(lambda: simulate(trajectory, profile, seed=1), args.repeats))
    report("geometry only", timings(lambda: geometric_signal(trajectory, profile), args.repeats))
    for effect in profile.effects.effects:
        signal = Signal(ideal.t, ideal.values, ideal.keep)
        report(f"effect {effect.name}",
               timings(lambda e=effect, s=signal: e.apply(s, np.random.default_rng(0)),
                       args.repeats))


if __name__ == "__main__":
    main()
