"""Suit simulation speed: the full Table III protocol (≈ 246 s, 61,565 frames × 4 sensors at
250 Hz) with every effect of the default profile on. Target: ≤ 2 s per simulation.

Run from the repository root: ``python -m benchmarks.bench_sim [--repeats N] [--json FILE]``.
Reports p50/p99/max wall time in s of the full ``simulate()`` (judged against the target: its
max, since every simulation must meet it), of the geometry alone and of each effect alone,
through :mod:`benchmarks.report`.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from benchmarks.report import parser, positive_int, report, run_main
from exohil.emulators.effects import Effect, Signal
from exohil.emulators.protocols import paper_protocol
from exohil.emulators.simulate import geometric_signal, simulate
from exohil.emulators.suit_profile import load_default_profile
from exohil.formats.measurement import Limit, Measurement, distribution

#: the target of this module's doc: every full simulation of the protocol within 2 s
SIMULATE_LIMITS = {"max": Limit(high=2.0, unit="s", inclusive=True)}


def timings(fn: Callable[[], object], repeats: int) -> np.ndarray:
    """Wall time of ``repeats`` calls of ``fn``, s."""
    out = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        out.append(time.perf_counter() - start)
    return np.asarray(out)


def applying(effect: Effect, signal: Signal) -> Callable[[], object]:
    """One application of ``effect`` to ``signal``, with a fresh seeded generator each time."""
    return lambda: effect.apply(signal, np.random.default_rng(0))


def main() -> None:
    ap = parser(__doc__)
    ap.add_argument("--repeats", type=positive_int, default=10, help="timed runs of each")
    args = ap.parse_args()
    print(f"numpy {np.__version__}")
    profile = load_default_profile()
    trajectory = paper_protocol(seed=1)
    ideal = geometric_signal(trajectory, profile)
    kinds = ", ".join(e.name for e in profile.effects.effects)
    print(f"protocol: {trajectory.duration_s:.1f} s, {len(ideal.t)} sensor frames x "
          f"{ideal.n_sensors} sensors, effects: {kinds}")
    measurements: list[Measurement] = distribution(
        "simulate", timings(lambda: simulate(trajectory, profile, seed=1), args.repeats), "s",
        SIMULATE_LIMITS, note="all effects")
    measurements += distribution(
        "geometry", timings(lambda: geometric_signal(trajectory, profile), args.repeats), "s")
    for effect in profile.effects.effects:
        signal = Signal(ideal.t, ideal.values, ideal.keep)
        measurements += distribution(f"effect.{effect.name}",
                                     timings(applying(effect, signal), args.repeats), "s")
    report("bench_sim", measurements, args.json)


if __name__ == "__main__":
    run_main(main)
