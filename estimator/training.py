"""Training: Adam (lr 1e-3, β 0.9/0.999), batch 500, MSE on normalised angles, early stopping.

As in Varghese et al. except the stopping rule: instead of a fixed 10,000 epochs, training stops
when the validation MSE has not improved for ``patience`` epochs, after ``max_epochs``, or when
the ``time_budget_s`` runs out; the weights of the best validation epoch are kept. Training
windows are shuffled among themselves only (the split is made of contiguous time blocks).

Determinism: for a fixed seed, a fixed epoch count and a fixed thread count on CPU, results
are reproducible (the CPU kernels used — LSTM, linear, conv1d — are deterministic; turning on
``torch.use_deterministic_algorithms`` would import torch's compiler stack, seconds, for
nothing). A wall-clock time budget can stop two runs at different epochs; pass ``max_epochs``
(and a generous budget) for bit-reproducible runs.
"""

from __future__ import annotations

import copy
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from exohil.estimator.classical import ClassicalModel
from exohil.estimator.dataset import DatasetError, TargetSpec
from exohil.estimator.evaluation import evaluate
from exohil.estimator.models import MODEL_KINDS, ModelConfig, build_model
from exohil.estimator.splits import Split
from exohil.estimator.trained import Normalisation, TrainedEstimator
from exohil.estimator.windows import FrameTable

ALL_KINDS = (*MODEL_KINDS, "classical")
#: Least training data `train` accepts, seconds of frames at the sensor rate.
MIN_TRAIN_SECONDS = 1.0


@dataclass
class TrainConfig:
    """Hyper-parameters (paper defaults where the paper gives them)."""

    kind: str = "ennet"
    window: int = 10
    dilation: int = 1
    hidden: int = 64
    batch_size: int = 500
    lr: float = 1e-3
    max_epochs: int = 10_000
    patience: int = 25
    time_budget_s: float = 600.0
    seed: int = 0
    threads: int = 1  # torch intra-op threads; 1 beats 2 on a shared 2-core CPU


def train(
    split: Split,
    sensor_names: tuple[str, ...],
    target: TargetSpec,
    cfg: TrainConfig,
    *,
    offset_frames: int = 0,
    sensor_rate_hz: float = 250.0,
    sources: list[dict] | None = None,
    progress: Callable[[str], None] | None = None,
) -> TrainedEstimator:
    """Fit one estimator on ``split.train`` with early stopping on ``split.val``.

    ``sources`` (e.g. ``[{"path": ..., "sha256": ...}]``) is stored in the checkpoint info.
    ``progress`` receives one-line status strings (the CLI draws them on stderr).
    """
    if cfg.kind not in ALL_KINDS:
        raise ValueError(f"unknown model kind {cfg.kind!r}; choose from {ALL_KINDS}")
    if not split.train:
        raise ValueError("no training frames")
    frames = sum(len(b) for b in split.train)
    if frames < MIN_TRAIN_SECONDS * sensor_rate_hz:
        raise DatasetError(f"too little data to train: {frames} frames "
                           f"({frames / sensor_rate_hz:.2f} s) in the training part; need at "
                           f"least {MIN_TRAIN_SECONDS:g} s ({MIN_TRAIN_SECONDS * sensor_rate_hz:g} "
                           "frames)")
    norm = Normalisation.fit(split.train)
    model_cfg = ModelConfig(cfg.kind, len(sensor_names), len(target.angles), cfg.window,
                            cfg.dilation, cfg.hidden)
    est = TrainedEstimator(model_cfg, tuple(sensor_names), target, norm, offset_frames,
                           sensor_rate_hz)
    start = time.monotonic()
    if cfg.kind == "classical":
        fit_info = _fit_classical(est, split)
    else:
        fit_info = _fit_network(est, split, cfg, progress)
    est.info = {
        "sources": sources or [],
        "split": split.description,
        "seed": cfg.seed,
        "train_config": {k: getattr(cfg, k) for k in cfg.__dataclass_fields__},
        "train_frames": int(sum(len(b) for b in split.train)),
        "val_frames": int(sum(len(b) for b in split.val)),
        "train_seconds": round(time.monotonic() - start, 1),
        **fit_info,
    }
    if split.val:
        est.info["metrics"] = {"validation": evaluate(est, split.val)}
    return est


def _fit_classical(est: TrainedEstimator, split: Split) -> dict:
    model = ClassicalModel.create(est.sensor_rate_hz)
    fit = model.fit(
        [est.norm.x(b.x) for b in split.train], [est.norm.y(b.y) for b in split.train],
        [est.norm.x(b.x) for b in split.val], [est.norm.y(b.y) for b in split.val],
    )
    est.classical = model
    return {"ridge": fit["ridge"], "best_val_mse": fit["val_mse"]}


def _fit_network(
    est: TrainedEstimator, split: Split, cfg: TrainConfig,
    progress: Callable[[str], None] | None,
) -> dict:
    import torch

    torch.set_num_threads(cfg.threads)
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    net = build_model(est.config)
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr, betas=(0.9, 0.999))
    loss_fn = torch.nn.MSELoss()

    def table(blocks):  # normalised frames of a split part
        t = FrameTable.from_blocks(blocks)
        t.x = est.norm.x(t.x).astype(np.float32)
        t.y = est.norm.y(t.y).astype(np.float32)
        return t

    tr = table(split.train)
    va = table(split.val) if split.val else tr
    win, dil = est.config.window, est.config.dilation
    va_frames = np.arange(len(va))
    va_x = torch.from_numpy(va.windows(va_frames, win, dil))
    va_y = torch.from_numpy(va.y)

    def val_mse() -> float:
        net.eval()
        with torch.inference_mode():
            pred = torch.cat([net(va_x[s : s + 8192]) for s in range(0, len(va), 8192)])
        net.train()
        return float(loss_fn(pred, va_y))

    start = time.monotonic()
    best, best_state, best_epoch, epoch, last_print = float("inf"), None, 0, 0, 0.0
    train_loss = float("nan")
    stop = "max_epochs"
    net.train()
    for epoch in range(1, cfg.max_epochs + 1):
        order = rng.permutation(len(tr))
        total, count = 0.0, 0
        for s in range(0, len(order), cfg.batch_size):
            frames = order[s : s + cfg.batch_size]
            xb = torch.from_numpy(tr.windows(frames, win, dil))
            yb = torch.from_numpy(tr.y[frames])
            opt.zero_grad(set_to_none=True)
            loss = loss_fn(net(xb), yb)
            loss.backward()
            opt.step()
            total += float(loss.detach()) * len(frames)
            count += len(frames)
            elapsed = time.monotonic() - start
            if progress and elapsed - last_print > 0.5:
                last_print = elapsed
                progress(_status(cfg.kind, epoch, total / count, best, elapsed, cfg.time_budget_s))
            if elapsed > cfg.time_budget_s:
                break
        train_loss = total / max(count, 1)
        v = val_mse()
        if v < best:
            best, best_epoch, best_state = v, epoch, copy.deepcopy(net.state_dict())
        if time.monotonic() - start > cfg.time_budget_s:
            stop = "time_budget"
            break
        if epoch - best_epoch >= cfg.patience:
            stop = "early_stopping"
            break
    if best_state is not None:
        net.load_state_dict(best_state)
    net.eval()
    est.network = net
    if progress:
        progress(_status(cfg.kind, epoch, train_loss, best, time.monotonic() - start,
                         cfg.time_budget_s) + f" — stopped: {stop}")
    return {"epochs": epoch, "best_epoch": best_epoch, "best_val_mse": best,
            "stopped_by": stop, "final_train_mse": train_loss}


def _status(kind: str, epoch: int, loss: float, best: float, elapsed: float,
            budget: float) -> str:
    left = max(0.0, budget - elapsed)
    return (f"[{kind}] epoch {epoch} train mse {loss:.4f} best val {best:.4f} "
            f"elapsed {elapsed:5.0f}s, ≤{left:4.0f}s left")


def progress_printer(stream=sys.stderr, log_every_s: float = 10.0) -> Callable[[str], None]:
    """A ``progress`` callback: redraws one status line on a terminal; on a pipe or log file
    writes a line at most every ``log_every_s`` seconds (and every final "stopped" line)."""
    last = [-float("inf")]

    def show(line: str) -> None:
        if stream.isatty():
            stream.write("\r\x1b[2K" + line + ("\n" if "stopped" in line else ""))
        elif "stopped" in line or time.monotonic() - last[0] >= log_every_s:
            last[0] = time.monotonic()
            stream.write(line + "\n")
        stream.flush()

    return show
