"""Calibration methods compared (``python -m benchmarks.bench_calibration --case ...``).

Each ``--case NAME BASE CAL TEST`` is a trained checkpoint BASE, calibration recordings CAL and
test recordings TEST of the new wearer or donning (CAL and TEST: comma-separated files or
globs). Every method adapts BASE with the CAL recordings and is scored on the TEST recordings:
the combined RMSE (root mean square over the target angles of exohil's accuracy RMSE: where
elevation ≥ 20° for the shoulder, every frame for other joints), averaged over ``--seeds``,
and its ratio to the uncalibrated model's (issue 15's goal for the default method: ≤ 0.5), and
the default method's wall time (goal ≤ 30 s; the command also loads files).

Methods: ``default`` is :func:`exohil.estimator.calibration.calibrate` with its defaults
(every weight fine-tuned on jittered inputs, the jitter chosen on held-out calibration
frames); ``plain`` is the same without jitter, ``jitterX`` with the jitter fixed at X;
``lr3e-4`` and ``steps300``/``steps900`` change one setting; ``input-affine``
learns a per-sensor gain and offset in front of the frozen network; ``head`` fine-tunes the
dense head only (the temporal encoder frozen), plainly.
"""

from __future__ import annotations

import copy
import glob
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from benchmarks.report import parser, positive_int, refuse_overwrite, report, run_main
from exohil.formats.measurement import Limit, Measurement

RATIO_LIMIT = Limit(high=0.5, unit="ratio", inclusive=True)
TIME_LIMIT = Limit(high=30.0, unit="s", inclusive=True)
#: Variants of the default configuration (CalibrationConfig fields), by method name.
VARIANTS = {
    "default": {},
    "plain": {"jitter": 0.0},
    "jitter0.03": {"jitter": 0.03},
    "jitter0.1": {"jitter": 0.1},
    "jitter0.3": {"jitter": 0.3},
    "lr3e-4": {"lr": 3e-4},
    "steps300": {"steps": 300},
    "steps900": {"steps": 900},
}
LOCAL = ("input-affine", "head")


def _files(spec: str) -> list[Path]:
    return [Path(p) for part in spec.split(",") for p in sorted(glob.glob(part))]


def _blocks(est, paths: list[Path]):
    """The recordings' blocks cut at movement segments, as ``exohil calibrate`` sees them."""
    from exohil.estimator.workflow import load_recordings

    data = load_recordings(paths, est.target.joint, est.target.angles, est.sensor_names)
    return [b for b in data.blocks(est.offset_frames) if len(b)]


def combined_rmse(est, blocks) -> float:
    from exohil.estimator.evaluation import evaluate

    acc = evaluate(est, blocks)["accuracy"]
    values = [v for k, v in acc.items() if k.startswith("accuracy.rmse.") and v is not None]
    return float(np.sqrt(np.mean(np.square(values))))


def _local(base, blocks, method: str, seed: int, steps: int = 300, lr: float = 3e-4):
    """The two methods outside exohil: a per-sensor input gain and offset (network frozen,
    folded into the normalisation afterwards), or the dense head fine-tuned alone."""
    import torch

    from exohil.estimator.training import NormalisedFrames

    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    est = copy.deepcopy(base)
    net = est.network
    table = NormalisedFrames(est, blocks).table
    n = table.x.shape[1]
    gain, offset = torch.ones(n, requires_grad=True), torch.zeros(n, requires_grad=True)
    for p in net.parameters():
        p.requires_grad_(False)
    if method == "head":
        params = list(net.head.parameters())
        for p in params:
            p.requires_grad_(True)
    else:
        params, lr = [gain, offset], 1e-2
    opt = torch.optim.Adam(params, lr=lr)
    net.train()
    for _ in range(steps):
        frames = rng.integers(0, len(table), 500)
        x = torch.from_numpy(table.windows(frames, est.config.window, est.config.dilation))
        loss = torch.mean((net(x * gain + offset) - torch.from_numpy(table.y[frames])) ** 2)
        opt.zero_grad()
        loss.backward()
        opt.step()
    net.eval()
    if method == "input-affine":  # z' = g·(x − m)/s + o  ⇔  x normalised by m − o·s/g, s/g
        g, o = gain.detach().double().numpy(), offset.detach().double().numpy()
        est.norm = replace(est.norm, x_std=base.norm.x_std / g,
                           x_mean=base.norm.x_mean - o * base.norm.x_std / g)
    return est


def main() -> None:
    from exohil.estimator.calibration import CalibrationConfig, calibrate
    from exohil.estimator.checkpoint import load_checkpoint

    ap = parser(__doc__)
    ap.add_argument("--case", nargs=4, action="append", required=True,
                    metavar=("NAME", "BASE", "CAL", "TEST"),
                    help="a base checkpoint, calibration and test recordings (repeatable)")
    ap.add_argument("--methods", default=",".join([*VARIANTS, *LOCAL]),
                    help="comma-separated methods (default: all)")
    ap.add_argument("--seeds", type=positive_int, default=2, help="seeds per method")
    args = ap.parse_args()
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    unknown = sorted(set(methods) - set(VARIANTS) - set(LOCAL))
    if unknown:
        ap.error(f"unknown methods {unknown}; choose from {[*VARIANTS, *LOCAL]}")
    cases = []
    for name, base_path, cal_spec, test_spec in args.case:
        cal_paths, test_paths = _files(cal_spec), _files(test_spec)
        for spec, paths in ((cal_spec, cal_paths), (test_spec, test_paths)):
            if not paths:
                ap.error(f"--case {name}: no files match {spec!r}")
        refuse_overwrite(ap, "--json", args.json, [base_path, *cal_paths, *test_paths])
        cases.append((name, base_path, cal_paths, test_paths))
    loaded = []  # every case's inputs, read before the first case runs
    for name, base_path, cal_paths, test_paths in cases:
        base = load_checkpoint(base_path)
        loaded.append((name, base, _blocks(base, cal_paths), _blocks(base, test_paths)))
    measurements: list[Measurement] = []
    for name, base, cal, test in loaded:
        seconds = sum(len(b) for b in cal) / base.sensor_rate_hz
        before = combined_rmse(base, test)
        measurements.append(Measurement(f"{name}.uncalibrated.rmse", before, "deg",
                                        note=f"calibration {seconds:.1f} s"))
        for method in methods:
            errors, times = [], []
            for seed in range(args.seeds):
                start = time.monotonic()
                if method in VARIANTS:
                    cfg = replace(CalibrationConfig(seed=seed), **VARIANTS[method])
                    est = calibrate(base, cal, cfg)
                else:
                    est = _local(base, cal, method, seed)
                times.append(time.monotonic() - start)
                errors.append(combined_rmse(est, test))
            mean = float(np.mean(errors))
            print(f"{name} {method}: {mean:.2f} deg ({' '.join(f'{e:.2f}' for e in errors)}), "
                  f"{np.mean(times):.1f} s", flush=True)
            measurements.append(Measurement(f"{name}.{method}.rmse", mean, "deg",
                                            note="seeds " + " ".join(f"{e:.2f}" for e in errors)))
            ratio = mean / before
            measurements.append(
                Measurement.judge(f"{name}.{method}.ratio", ratio, "ratio", RATIO_LIMIT)
                if method == "default" else Measurement(f"{name}.{method}.ratio", ratio, "ratio"))
            if method == "default":
                measurements.append(Measurement.judge(f"{name}.default.seconds", max(times), "s",
                                                      TIME_LIMIT, note="slowest seed"))
    report("bench_calibration", measurements, args.json)


if __name__ == "__main__":
    run_main(main)
