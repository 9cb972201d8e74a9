"""Calibration: adapt a trained network to a new wearer or a new donning from a short
recording with ground truth (30–60 s of the calibration protocol, docs/calibration.md).

Method (chosen by measurement, docs/calibration.md "How the method was chosen"): fine-tune
every weight of the network on the calibration frames, starting from the trained weights,
with Adam at ``lr`` for a fixed number of minibatch ``steps``, each training window given a
random per-sensor offset and gain (``offset_jitter`` and ``gain_jitter``, in units of the
sensor's training standard deviation). The jitter is what makes it work: 60 s of data
cannot then be memorised, and the adapted network tolerates the slow offset drift a donning
brings over the following minutes.

The normalisation, window and target of the trained model are kept, so the calibrated model
runs on every engine like the one it came from. On both wearer pairs of the graphene knee
data this beat a per-sensor gain and offset on the inputs (the network frozen), fine-tuning
the dense head only, and fine-tuning every weight without the jitter
(``python -m benchmarks.bench_calibration``).

The calibration recordings are training data: they join ``info["sources"]``, so the
held-out rule (conformance ``heldout.overlap``) refuses to score on them.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np

from exohil.estimator.dataset import Block, DatasetError
from exohil.estimator.evaluation import evaluate
from exohil.estimator.trained import TrainedEstimator
from exohil.estimator.training import NormalisedFrames
from exohil.formats.errors import InputError

#: The method's name as written into a calibrated checkpoint.
METHOD = "fine-tune all weights on jittered inputs"
#: Least calibration data accepted, seconds of frames at the model's rate.
MIN_CALIBRATION_SECONDS = 5.0


class CalibrationError(InputError):
    """A model or calibration data that calibration cannot use."""


@dataclass(frozen=True)
class CalibrationConfig:
    """Fine-tuning settings (defaults: docs/calibration.md)."""

    steps: int = 600
    lr: float = 1e-3
    batch_size: int = 500
    offset_jitter: float = 0.3  # σ of a per-window sensor offset, training standard deviations
    gain_jitter: float = 0.1  # σ of a per-window relative sensor gain
    seed: int = 0
    threads: int = 1


def calibrate(
    base: TrainedEstimator,
    blocks: list[Block],
    cfg: CalibrationConfig | None = None,
    *,
    base_source: dict | None = None,
    sources: list[dict] | None = None,
    progress: Callable[[str], None] | None = None,
) -> TrainedEstimator:
    """A new estimator: ``base`` fine-tuned on the calibration ``blocks`` (``base`` itself is
    left as it was).

    ``base_source`` ({"file", "sha256"} of the base checkpoint) and ``sources`` (the
    calibration recordings, same form) are written into the new estimator's ``info``, with
    the method, its settings, how many seconds of data were used and the error on the
    calibration frames before and after. Raises CalibrationError for a model that has no
    windowed network (the classical model, a stateful ENNet) or too little data.
    """
    cfg = cfg or CalibrationConfig()
    if not base.has_network:
        raise CalibrationError(f"a {base.kind} model has no network to fine-tune; calibration "
                               "adapts the neural estimators (ennet, lnnet, cnn, ann)")
    if base.config.stateful:
        raise CalibrationError("calibrating a stateful ENNet is not supported (it needs "
                               "training through time); calibrate a windowed model")
    frames = sum(len(b) for b in blocks)
    seconds = frames / base.sensor_rate_hz
    if seconds < MIN_CALIBRATION_SECONDS:
        raise DatasetError(f"too little calibration data: {frames} frames ({seconds:.1f} s); "
                           f"need at least {MIN_CALIBRATION_SECONDS:g} s of frames with "
                           "ground truth")
    if cfg.steps < 1 or cfg.batch_size < 1 or min(cfg.offset_jitter, cfg.gain_jitter) < 0:
        raise ValueError(f"bad calibration settings {cfg}")
    start = time.monotonic()
    est = TrainedEstimator(base.config, base.sensor_names, base.target, base.norm,
                           base.offset_frames, base.sensor_rate_hz,
                           state=base.weights(dtype=np.float32))
    _fine_tune(est, NormalisedFrames(est, blocks), cfg, progress)
    before, after = evaluate(base, blocks), evaluate(est, blocks)
    base_info = dict(base.info)
    est.info = {
        "sources": [*base_info.get("sources", []),
                    *({**s, "role": "calibration"} for s in (sources or []))],
        "calibration": {
            "method": METHOD,
            "base_checkpoint": base_source or {},
            "recordings": sources or [],
            "seconds": round(seconds, 2),
            "frames": frames,
            "config": asdict(cfg),
            "elapsed_s": round(time.monotonic() - start, 1),
            "accuracy_before": before["accuracy"],  # on the calibration frames
            "accuracy_after": after["accuracy"],
        },
        "base_info": base_info,
        "metrics": {"calibration": after},
    }
    return est


def _fine_tune(est: TrainedEstimator, data: NormalisedFrames, cfg: CalibrationConfig,
               progress: Callable[[str], None] | None) -> None:
    """Adam on the MSE of the normalised network targets over jittered windows (in place)."""
    import torch

    torch.set_num_threads(cfg.threads)
    gen = torch.Generator().manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    net = est.network
    assert isinstance(net, torch.nn.Module)
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
    table, win, dil = data.table, est.config.window, est.config.dilation
    n_sensors = table.x.shape[1]
    start, last = time.monotonic(), -1.0
    net.train()
    for step in range(cfg.steps):
        frames = rng.integers(0, len(table), cfg.batch_size)
        xb = torch.from_numpy(table.windows(frames, win, dil))
        shape = (len(frames), 1, n_sensors)
        xb = (xb * (1.0 + cfg.gain_jitter * torch.randn(shape, generator=gen))
              + cfg.offset_jitter * torch.randn(shape, generator=gen))
        loss = torch.mean((net(xb) - torch.from_numpy(table.y[frames])) ** 2)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        elapsed = time.monotonic() - start
        if progress and (elapsed - last >= 0.5 or step == cfg.steps - 1):
            last = elapsed
            done = " — stopped: all steps done" if step == cfg.steps - 1 else ""
            mse = float(loss.detach())
            progress(f"[calibrate] step {step + 1}/{cfg.steps} train mse {mse:.4f} "
                     f"elapsed {elapsed:4.1f}s{done}")
    net.eval()
