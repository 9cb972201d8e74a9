"""Per-frame latency of the streaming estimator backends (``python -m benchmarks.bench_inference``).

Loads ``--checkpoint`` (default: the reference ENNet, ``fixtures/models/ennet.npz``; ``random``:
an ENNet of hidden 64, window 10, dense 512-256-128-64-32 with random weights) and times
``StreamingEstimator.push`` for each backend over many frames and reports p50/p99/max in µs
(``push.<backend>``, judged against the goal p99 ≤ 100 µs of docs/estimator.md) through
:mod:`benchmarks.report`, after the library versions and load average. Warm-up frames are
excluded. A last "fixed work" row times constant NumPy work of about the same duration: its p99
shows how much of the tail is the machine rather than the engine. ``--pace-hz 250`` spaces the
calls like the live 250 Hz stream instead of calling back to back (caches go cold between
frames). ``push.default_over_fixed_work.p99`` is the default backend's p99 over the baseline's
(issue 11: at most 1.5 when paced at 250 Hz).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np

from benchmarks.report import (
    load_average,
    non_negative_float,
    parser,
    positive_int,
    refuse_overwrite,
    report,
    run_main,
)
from exohil.formats.measurement import (
    DISTRIBUTION_STATS,
    Limit,
    Measurement,
    distribution,
)

#: the reference ENNet the demo and the conformance suite run
REFERENCE_ENNET = Path(__file__).resolve().parent.parent / "fixtures" / "models" / "ennet.npz"

if TYPE_CHECKING:
    from exohil.estimator.trained import TrainedEstimator

#: docs/estimator.md, "Benchmark": goal p99 ≤ 100 µs per pushed frame, for every backend
PUSH_LIMITS = {"p99": Limit(high=100.0, unit="us", inclusive=True)}
#: fewest timed frames whose p99 is judged (a p99 of fewer is not a tail)
MIN_FRAMES = 100
#: issue 11: the default engine's p99 at most 1.5 × the fixed-work baseline's p99 of the same run
BASELINE_RATIO_LIMIT = Limit(high=1.5, unit="ratio", inclusive=True)


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
    from exohil.estimator.inference import BACKENDS, StreamingEstimator, default_backend

    ap = parser(__doc__)
    ap.add_argument("--frames", type=positive_int, default=20_000,
                    help=f"timed frames per backend (at least {MIN_FRAMES})")
    ap.add_argument("--checkpoint", default=str(REFERENCE_ENNET),
                    help="checkpoint to time (default: the reference ENNet, "
                         "fixtures/models/ennet.npz); 'random' times a random-weight ENNet "
                         "of hidden 64, window 10 and the paper's dense stack")
    ap.add_argument("--pace-hz", type=non_negative_float, default=0.0,
                    help="one push every 1/HZ s like a live stream (e.g. 250); default: back "
                         "to back")
    ap.add_argument("--backend", dest="backends", action="append", choices=BACKENDS,
                    help="time only this backend (repeatable; default: every backend)")
    args = ap.parse_args()
    if args.frames < MIN_FRAMES:
        ap.error(f"--frames: at least {MIN_FRAMES} for a p99 to judge, got {args.frames}")
    if args.checkpoint != "random":
        refuse_overwrite(ap, "--json", args.json, [args.checkpoint])
    est = random_estimator() if args.checkpoint == "random" else load_checkpoint(args.checkpoint)
    rng = np.random.default_rng(0)
    frames = est.norm.x_mean + est.norm.x_std * rng.standard_normal((args.frames + 200,
                                                                      est.config.n_sensors))
    pace_hz = args.pace_hz
    pacing = f"paced at {pace_hz:g} Hz" if pace_hz > 0 else "back to back"
    print(f"libraries: {library_versions()}")
    print(f"load average before: {load_average()}")
    cfg = est.config
    memory = "carried state" if cfg.stateful else f"window {cfg.window}×{cfg.dilation}"
    print(f"model: {args.checkpoint}: {est.kind} hidden {cfg.hidden} {memory} dense "
          f"{'-'.join(map(str, cfg.dense))} sensors {cfg.n_sensors} outputs {cfg.n_outputs}; "
          f"{args.frames} frames; {pacing}")
    measurements: list[Measurement] = []
    p99 = {}
    for backend in args.backends or BACKENDS:
        name = f"push.{backend}"
        try:
            engine = StreamingEstimator(est, backend)
        except ValueError as exc:
            measurements += [Measurement.skipped(f"{name}.{stat}", "us", str(exc),
                                                 PUSH_LIMITS.get(stat))
                             for stat in DISTRIBUTION_STATS]
            continue
        times = time_push(engine, frames, pace_hz=pace_hz)
        p99[backend] = float(np.percentile(times, 99))
        measurements += distribution(name, times, "us", PUSH_LIMITS, note=pacing)
    baseline = time_push(FixedWork(), frames, pace_hz=pace_hz)
    measurements += distribution("fixed_work", baseline, "us", note=f"{pacing}; noise baseline")
    default = default_backend(est)
    if default in p99:
        measurements.append(Measurement.judge(
            "push.default_over_fixed_work.p99", p99[default] / np.percentile(baseline, 99),
            "ratio", BASELINE_RATIO_LIMIT, f"default backend {default}; {pacing}"))
    print(f"load average after: {load_average()}")
    report("bench_inference", measurements, args.json)


if __name__ == "__main__":
    run_main(main)
