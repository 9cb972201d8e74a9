"""Per-frame latency of the streaming estimator backends (``python -m benchmarks.bench_inference``).

Builds ENNet (hidden 64, window 10, dense 512-256-128-64-32, 4 sensors → 2 angles; random
weights: latency does not depend on their values) — or loads ``--checkpoint`` — then times
``StreamingEstimator.push`` for each backend over many frames and reports p50/p99/max in µs
(``push.<backend>``, judged against the goal p99 ≤ 100 µs of docs/estimator.md) through
:mod:`benchmarks.report`, after the library versions and load average. Warm-up frames are
excluded. A last "fixed work" row times constant NumPy work of about the same duration: its p99
shows how much of the tail is the machine rather than the engine. ``--pace-hz 250`` spaces the
calls like the live 250 Hz stream instead of calling back to back (caches go cold between
frames).
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Protocol

import numpy as np

from benchmarks.report import load_average, parser, positive_int, report
from exohil.formats.measurement import (
    DISTRIBUTION_STATS,
    Limit,
    Measurement,
    distribution,
)

if TYPE_CHECKING:
    from exohil.estimator.trained import TrainedEstimator

#: docs/estimator.md, "Benchmark": goal p99 ≤ 100 µs per pushed frame, for every backend
PUSH_LIMITS = {"p99": Limit(high=100.0, unit="us", inclusive=True)}


class Pushable(Protocol):
    """What :func:`time_push` times: a streaming estimator or the fixed-work baseline."""

    def push(self, row: np.ndarray) -> object: ...


def library_versions() -> str:
    """Versions of the libraries the backends run on (those installed)."""
    from importlib.metadata import PackageNotFoundError, version

    found = []
    for name in ("numpy", "torch", "onnxruntime"):
        try:
            found.append(f"{name} {version(name)}")
        except PackageNotFoundError:
            continue
    return ", ".join(found)


def random_estimator(kind: str = "ennet", hidden: int = 64, window: int = 10) -> TrainedEstimator:
    """A TrainedEstimator with random weights (for timing only)."""
    import torch

    from exohil.estimator.dataset import TargetSpec
    from exohil.estimator.models import ModelConfig, build_model
    from exohil.estimator.trained import Normalisation, TrainedEstimator

    torch.manual_seed(0)
    cfg = ModelConfig(kind, 4, 2, window=window, hidden=hidden)
    norm = Normalisation(np.full(4, 500.0), np.full(4, 20.0), np.zeros(2), np.full(2, 30.0))
    return TrainedEstimator(cfg, ("F", "SF", "SR", "R"), TargetSpec("shoulder", ("a", "b")),
                            norm, network=build_model(cfg).eval())


class FixedWork:
    """Machine-noise baseline: the same NumPy work every call (12 float32 256×256 matrix-vector
    products, ≈ the ENNet p50), so its tail is the machine's, not an engine's."""

    def __init__(self) -> None:
        rng = np.random.default_rng(1)
        self.w = rng.random((256, 256), dtype=np.float32)
        self.v = rng.random(256, dtype=np.float32)
        self.out = np.empty(256, dtype=np.float32)

    def push(self, _row: np.ndarray) -> np.ndarray:
        for _ in range(12):
            np.dot(self.v, self.w, out=self.out)
        return self.out


def time_push(engine: Pushable, frames: np.ndarray, warmup: int = 200,
              pace_hz: float = 0.0) -> np.ndarray:
    """Per-call latencies in µs (after ``warmup`` calls).

    ``pace_hz`` > 0 starts one call every 1/pace_hz s, as a live stream does (sleep, then spin
    the last 0.5 ms for an accurate start); 0 calls back to back (caches stay warm).
    """
    for row in frames[:warmup]:
        engine.push(row)
    out = np.empty(frames.shape[0] - warmup)
    clock = time.perf_counter_ns
    period_ns = int(1e9 / pace_hz) if pace_hz > 0 else 0
    due = clock()
    for i, row in enumerate(frames[warmup:]):
        if period_ns:
            due += period_ns
            while clock() < due - 500_000:
                time.sleep(0.0002)
            while clock() < due:
                pass
        t0 = clock()
        engine.push(row)
        out[i] = (clock() - t0) / 1000.0
    return out


def main() -> None:
    from exohil.estimator.checkpoint import load_checkpoint
    from exohil.estimator.inference import BACKENDS, StreamingEstimator

    ap = parser(__doc__)
    ap.add_argument("--frames", type=positive_int, default=20_000,
                    help="timed frames per backend")
    ap.add_argument("--checkpoint", help="time this checkpoint instead of a random ENNet")
    ap.add_argument("--pace-hz", type=float, default=0.0,
                    help="one push every 1/HZ s like a live stream (e.g. 250); default: back "
                         "to back")
    args = ap.parse_args()
    est = load_checkpoint(args.checkpoint) if args.checkpoint else random_estimator()
    rng = np.random.default_rng(0)
    frames = est.norm.x_mean + est.norm.x_std * rng.standard_normal((args.frames + 200,
                                                                      est.config.n_sensors))
    pace_hz = args.pace_hz
    pacing = f"paced at {pace_hz:g} Hz" if pace_hz > 0 else "back to back"
    print(f"libraries: {library_versions()}")
    print(f"load average before: {load_average()}")
    print(f"model: {est.kind} hidden {est.config.hidden} window {est.config.window} "
          f"sensors {est.config.n_sensors} angles {est.config.n_angles}; {args.frames} frames; "
          f"{pacing}")
    measurements: list[Measurement] = []
    for backend in BACKENDS:
        name = f"push.{backend}"
        try:
            engine = StreamingEstimator(est, backend)
        except ValueError as exc:
            measurements += [Measurement.skipped(f"{name}.{stat}", "us", str(exc),
                                                 PUSH_LIMITS.get(stat))
                             for stat in DISTRIBUTION_STATS]
            continue
        measurements += distribution(name, time_push(engine, frames, pace_hz=pace_hz), "us",
                                     PUSH_LIMITS, note=pacing)
    measurements += distribution("fixed_work", time_push(FixedWork(), frames, pace_hz=pace_hz),
                                 "us", note=f"{pacing}; noise baseline")
    print(f"load average after: {load_average()}")
    report("bench_inference", measurements, args.json)


if __name__ == "__main__":
    main()
