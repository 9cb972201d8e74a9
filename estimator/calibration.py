"""Calibration: adapt a trained network to a new wearer or a new donning from a short
recording with ground truth (30–60 s of the calibration protocol, docs/calibration.md).

Method (chosen by measurement, docs/calibration.md "How the method was chosen"): fine-tune
every weight of the network on the calibration frames, starting from the trained weights,
with Adam at ``lr`` for a fixed number of minibatch ``steps``, each training window given a
random per-sensor offset (σ = ``jitter`` of the sensor's training standard deviation) and
gain (σ = ``jitter`` / 3). The jitter keeps 60 s of data from being memorised and makes the
adapted network tolerate the offset drift a sensor shows over the following minutes, at the
cost of precision where the sensors do not drift. How much jitter suits a suit is chosen from
the calibration data (``jitter=None``): each of :data:`JITTER_CANDIDATES` fine-tunes on the
first part of every calibration block and is scored on the rest (the last
:data:`HOLDOUT_SHARE`); the largest within one standard error of the best score is used on
all the data (:func:`_select_jitter`).

The normalisation, window and target of the trained model are kept, so the calibrated model
runs on every engine like the one it came from. On both wearer pairs of the graphene knee
data this beat a per-sensor gain and offset on the inputs (the network frozen), fine-tuning
the dense head only, and fine-tuning every weight without the jitter
(``python -m benchmarks.bench_calibration``).

The calibration recordings are training data: they join ``info["sources"]``, so the
held-out rule (conformance ``heldout.overlap``) refuses to score on them, and where their
readings lie joins the training coverage (:mod:`exohil.estimator.coverage`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np

from exohil.estimator.coverage import input_statistics
from exohil.estimator.dataset import Block, DatasetError
from exohil.estimator.defaults import CALIBRATION_JITTERS
from exohil.estimator.evaluation import evaluate
from exohil.estimator.trained import TrainedEstimator
from exohil.estimator.training import NormalisedFrames
from exohil.formats.errors import InputError

#: The method's name as written into a calibrated checkpoint.
METHOD = "fine-tune all weights on jittered inputs"
#: Least calibration data accepted, seconds of frames at the model's rate.
MIN_CALIBRATION_SECONDS = 5.0
#: Seconds of calibration frames the protocol is written for (docs/calibration.md): less is
#: taken, with a warning, since it holds fewer of the protocol's movements.
ADVISED_CALIBRATION_SECONDS = 30.0
#: Calibration frames whose every angle stays within this range, degrees, hold about one
#: pose: fine-tuning on them teaches that pose (taken, with a warning).
MIN_CALIBRATION_RANGE_DEG = 10.0
#: Input jitter levels tried when none is given (σ of the offset, sensor standard deviations).
JITTER_CANDIDATES = CALIBRATION_JITTERS
#: σ of the relative gain jitter per unit of offset jitter.
GAIN_PER_OFFSET = 1.0 / 3.0
#: The end of every calibration block on which the jitter candidates are scored.
HOLDOUT_SHARE = 0.25
#: Fine-tuning steps of each candidate (the final fit takes ``CalibrationConfig.steps``).
SELECTION_STEPS = 200


class CalibrationError(InputError):
    """A model or calibration data that calibration cannot use."""


@dataclass(frozen=True)
class CalibrationConfig:
    """Fine-tuning settings (defaults: docs/calibration.md)."""

    steps: int = 600
    lr: float = 1e-3
    batch_size: int = 500
    jitter: float | None = None  # σ of the input offset (std units); None: chosen from data
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
    if cfg.steps < 1 or cfg.batch_size < 1 or (cfg.jitter is not None and cfg.jitter < 0):
        raise ValueError(f"bad calibration settings {cfg}")
    start = time.monotonic()
    selection: dict[str, dict[str, float]] = {}
    jitter = cfg.jitter
    if jitter is None:
        jitter, selection = _select_jitter(base, blocks, cfg, progress)
    est = _copy(base)
    _fine_tune(est, NormalisedFrames(est, blocks), cfg.steps, jitter, cfg, progress)
    before, after = evaluate(base, blocks), evaluate(est, blocks)
    base_info = dict(base.info)
    est.info = {
        "sources": [*base_info.get("sources", []),
                    *({**s, "role": "calibration"} for s in (sources or []))],
        # the end of each block of its training recordings that the base model never saw
        "test_fraction": base_info.get("test_fraction", 0.0),
        # the base model's reading unit, which the calibration recordings were checked against
        **({"sensor_units": base_info["sensor_units"]} if "sensor_units" in base_info else {}),
        "calibration": {
            "method": METHOD,
            "base_checkpoint": base_source or {},
            "recordings": sources or [],
            "seconds": round(seconds, 2),
            "frames": frames,
            # where the calibration readings lie (estimator.coverage counts them as trained on)
            **input_statistics(blocks),
            "config": asdict(cfg),
            "jitter": jitter,
            # each candidate jitter's held-out MSE and its standard error; empty when the
            # jitter was given
            "jitter_selection": selection,
            "elapsed_s": round(time.monotonic() - start, 1),
            "accuracy_before": before["accuracy"],  # on the calibration frames
            "accuracy_after": after["accuracy"],
        },
        "base_info": base_info,
        "metrics": {"calibration": after},
    }
    return est


def _copy(base: TrainedEstimator) -> TrainedEstimator:
    """A new estimator with ``base``'s settings and a copy of its weights (no info)."""
    return TrainedEstimator(base.config, base.sensor_names, base.target, base.norm,
                            base.offset_frames, base.sensor_rate_hz,
                            state=base.weights(dtype=np.float32))


def _select_jitter(base: TrainedEstimator, blocks: list[Block], cfg: CalibrationConfig,
                   progress: Callable[[str], None] | None,
                   ) -> tuple[float, dict[str, dict[str, float]]]:
    """The jitter to calibrate with, and each candidate's held-out score.

    Each of :data:`JITTER_CANDIDATES` fine-tunes :data:`SELECTION_STEPS` steps on the first
    part of every block and is scored on the rest (its last :data:`HOLDOUT_SHARE`): the MSE
    of the normalised network targets, and its standard error over the held-out blocks. The
    largest jitter within one standard error of the best score is chosen (the
    one-standard-error rule): the held-out frames lie seconds after the fitted ones, so they
    cannot show the drift of the following minutes that the jitter guards against, and the
    more robust model is preferred unless it measurably costs accuracy.
    """
    cuts = [len(b) - max(1, round(len(b) * HOLDOUT_SHARE)) for b in blocks]
    fit = [b.slice(0, c) for b, c in zip(blocks, cuts, strict=True) if c > 0]
    held = [b.slice(c, len(b)) for b, c in zip(blocks, cuts, strict=True)]
    scores: dict[str, dict[str, float]] = {}
    for jitter in JITTER_CANDIDATES:
        est = _copy(base)
        _fine_tune(est, NormalisedFrames(est, fit), SELECTION_STEPS, jitter, cfg, progress)
        data = NormalisedFrames(est, held)
        sizes = np.array([b - a for a, b in data.bounds])
        per_block = np.array(data.squared_errors(est)) / (sizes * data.table.y.shape[1])
        se = float(np.std(per_block, ddof=1) / np.sqrt(len(per_block))) \
            if len(per_block) > 1 else 0.0
        scores[f"{jitter:g}"] = {"mse": float(np.average(per_block, weights=sizes)), "se": se}
    best = min(scores.values(), key=lambda s: s["mse"])
    chosen = max(float(j) for j, s in scores.items() if s["mse"] <= best["mse"] + best["se"])
    return chosen, scores


def _fine_tune(est: TrainedEstimator, data: NormalisedFrames, steps: int, jitter: float,
               cfg: CalibrationConfig, progress: Callable[[str], None] | None) -> None:
    """Adam on the MSE of the normalised network targets over windows given a random offset
    (σ ``jitter``) and gain (σ ``jitter`` · :data:`GAIN_PER_OFFSET`) per sensor (in place)."""
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
    for step in range(steps):
        frames = rng.integers(0, len(table), cfg.batch_size)
        xb = torch.from_numpy(table.windows(frames, win, dil))
        shape = (len(frames), 1, n_sensors)
        xb = (xb * (1.0 + jitter * GAIN_PER_OFFSET * torch.randn(shape, generator=gen))
              + jitter * torch.randn(shape, generator=gen))
        loss = torch.mean((net(xb) - torch.from_numpy(table.y[frames])) ** 2)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        elapsed = time.monotonic() - start
        if progress and (elapsed - last >= 0.5 or step == steps - 1):
            last = elapsed
            done = " — stopped: all steps done" if step == steps - 1 else ""
            mse = float(loss.detach())
            progress(f"[calibrate] jitter {jitter:g} step {step + 1}/{steps} train mse "
                     f"{mse:.4f} elapsed {elapsed:4.1f}s{done}")
    net.eval()
