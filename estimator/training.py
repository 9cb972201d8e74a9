"""Training: Adam (lr 1e-3, β 0.9/0.999), batch 500, MSE on the normalised network targets,
early stopping on the same MSE over the validation part.

As in Varghese et al. except two things. The target: for a shoulder θ/φ target the networks
learn the humerus direction (a unit vector; see :meth:`TrainedEstimator.encode`), whose error
is well defined at every pose, where the paper's MSE on θ is dominated by frames with the arm
hanging, where θ is undefined. The stopping rule: instead of a fixed 10,000 epochs, training
stops when the validation MSE has not improved for ``patience`` epochs, after ``max_epochs``,
or when the ``time_budget_s`` runs out; the weights of the best validation epoch are kept.
Training windows are shuffled among themselves only (the split is made of contiguous time
blocks); a stateful ENNet trains on whole streams instead (:func:`_stream_batches`).

Determinism: for a fixed seed, a fixed epoch count and a fixed thread count on CPU, results
are reproducible (the CPU kernels used — LSTM, linear, conv1d — are deterministic; turning on
``torch.use_deterministic_algorithms`` would import torch's compiler stack, seconds, for
nothing). A wall-clock time budget can stop two runs at different epochs; pass ``max_epochs``
(and a generous budget) for bit-reproducible runs.
"""

from __future__ import annotations

import copy
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from exohil.estimator.classical import ClassicalModel
from exohil.estimator.coverage import input_statistics
from exohil.estimator.dataset import Block, DatasetError, TargetSpec
from exohil.estimator.defaults import DEFAULT_DENSE
from exohil.estimator.evaluation import evaluate
from exohil.estimator.models import MODEL_KINDS, ModelConfig, build_model
from exohil.estimator.splits import Split
from exohil.estimator.trained import (
    DIRECTION_ANGLES,
    Normalisation,
    TrainedEstimator,
    encode_targets,
    is_direction_target,
)
from exohil.estimator.windows import FrameTable

ALL_KINDS = (*MODEL_KINDS, "classical")
#: Largest gradient norm per update (LSTMs trained through time need the clip).
GRADIENT_CLIP = 1.0
#: Stateful ENNet training (truncated backpropagation through time, :func:`_stream_batches`):
#: streams per minibatch, their length (seconds, so at any sensor rate a stream spans the same
#: time: 1250 frames at 250 Hz), frames per backpropagated chunk, seconds not scored at the
#: start of a stream that starts inside a block, and the share that start at a block start.
STREAMS_PER_BATCH = 64
STREAM_SECONDS = 5.0
TBPTT_FRAMES = 50
BURN_IN_SECONDS = 1.0
FROM_START_SHARE = 0.1
#: Stream batches per epoch at least (an epoch of long streams is few updates otherwise).
MIN_STREAM_GROUPS = 4
#: Least training data `train` accepts, seconds of frames at the sensor rate.
MIN_TRAIN_SECONDS = 1.0


@dataclass
class TrainConfig:
    """Hyper-parameters (paper defaults where the paper gives them)."""

    kind: str = "ennet"
    window: int | None = 10  # None: the model's default (estimator.workflow.model_config)
    dilation: int | None = 1
    hidden: int = 64
    stateful: bool = False
    dense: tuple[int, ...] = DEFAULT_DENSE
    output: str = "auto"  # "auto": a direction for a shoulder θ/φ target, else the angles
    batch_size: int = 500
    lr: float = 1e-3
    max_epochs: int = 10_000
    patience: int = 25
    time_budget_s: float = 300.0
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
    sensor_units: str | None = None,
) -> TrainedEstimator:
    """Fit one estimator on ``split.train`` with early stopping on ``split.val``.

    ``sources`` (e.g. ``[{"path": ..., "sha256": ...}]``) is stored in the checkpoint info,
    and so is ``sensor_units``, the unit of the training readings (``info.sensor_units``:
    :func:`~exohil.estimator.checkpoint.ensure_fits` refuses readings in another).
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
    output = cfg.output
    if output == "auto":
        output = "direction" if is_direction_target(target) else "angles"
    if output == "direction" and not is_direction_target(target):
        raise DatasetError(f"a direction output needs the target angles {list(DIRECTION_ANGLES)}"
                           f", not {list(target.angles)}")
    stateful = cfg.stateful and cfg.kind == "ennet"
    model_cfg = ModelConfig(cfg.kind, len(sensor_names), len(target.angles),
                            1 if stateful else cfg.window or 1,
                            1 if stateful else cfg.dilation or 1,
                            cfg.hidden, dense=tuple(cfg.dense), output=output,
                            stateful=stateful)
    norm = Normalisation.fit(
        np.concatenate([b.x for b in split.train]),
        encode_targets(output, target, np.concatenate([b.y for b in split.train])),
        scale_y=output != "direction")
    est = TrainedEstimator(model_cfg, tuple(sensor_names), target, norm, offset_frames,
                           sensor_rate_hz)
    start = time.monotonic()
    if cfg.kind == "classical":
        fit_info = _fit_classical(est, split)
    else:
        fit_info = _fit_network(est, split, cfg, progress)
    est.info = {
        "sources": sources or [],
        **({} if sensor_units is None else {"sensor_units": sensor_units}),
        "split": split.description,
        "seed": cfg.seed,
        "train_config": {k: getattr(cfg, k) for k in cfg.__dataclass_fields__},
        "train_frames": frames,
        "val_frames": int(sum(len(b) for b in split.val)),
        "train_seconds": round(time.monotonic() - start, 1),
        # where the training frames lie (estimator.coverage: readings beyond them are told)
        "training_inputs": input_statistics(split.train),
        **fit_info,
    }
    if split.val:
        est.info["metrics"] = {"validation": evaluate(est, split.val)}
    return est


def _fit_classical(est: TrainedEstimator, split: Split) -> dict:
    model = ClassicalModel.create(est.sensor_rate_hz)

    def targets(blocks: list[Block]) -> list[np.ndarray]:
        return [est.norm.y(est.encode(b.y)) for b in blocks]

    fit = model.fit([est.norm.x(b.x) for b in split.train], targets(split.train),
                    [est.norm.x(b.x) for b in split.val], targets(split.val))
    est.classical = model
    return {"ridge": fit["ridge"], "best_val_mse": fit["val_mse"]}


class NormalisedFrames:
    """One split part as normalised float32 arrays: sensors x (N, S), network targets y
    (N, K), each frame's block start (windows and streams never cross a block), and the
    (start, stop) frames of every block."""

    def __init__(self, est: TrainedEstimator, blocks: list[Block]) -> None:
        table = FrameTable.from_blocks(blocks, dtype=np.float64)
        self.table = FrameTable(est.norm.x(table.x).astype(np.float32),
                                est.norm.y(est.encode(table.y)).astype(np.float32),
                                table.block_start)
        starts = np.unique(table.block_start).tolist()
        self.bounds = list(zip(starts, [*starts[1:], len(table)], strict=True))

    def __len__(self) -> int:
        return len(self.table)

    def squared_errors(self, est: TrainedEstimator) -> list[float]:
        """The sum of squared errors of ``est``'s network outputs over each block (in
        ``bounds`` order), on the normalised targets."""
        return [float(np.sum((est.network_outputs(self.table.x[a:b]) - self.table.y[a:b]) ** 2))
                for a, b in self.bounds]


def _fit_network(
    est: TrainedEstimator, split: Split, cfg: TrainConfig,
    progress: Callable[[str], None] | None,
) -> dict:
    """Adam on the MSE of the normalised network targets; early stopping on the same MSE on
    the validation part (a well-posed figure for a direction output: the squared chord
    between estimated and true arm direction)."""
    import torch

    torch.set_num_threads(cfg.threads)
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    net = build_model(est.config)
    est.network = net
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr, betas=(0.9, 0.999))
    tr = NormalisedFrames(est, split.train)
    va = NormalisedFrames(est, split.val) if split.val else tr
    batches = (_stream_batches if est.config.stateful else _window_batches)(est, tr, cfg, rng)

    def val_mse() -> float:
        total = sum(va.squared_errors(est))
        net.train()
        return total / (len(va) * va.table.y.shape[1])

    name = f"{cfg.kind}-stateful" if est.config.stateful else cfg.kind  # as --model names it
    start = time.monotonic()
    best, best_state, best_epoch, epoch, last_print = float("inf"), None, 0, 0, 0.0
    train_loss = float("nan")
    stop = "max_epochs"
    net.train()
    for epoch in range(1, cfg.max_epochs + 1):
        total, count = 0.0, 0
        for loss, frames in batches():
            opt.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(net.parameters(), GRADIENT_CLIP)
            opt.step()
            total += float(loss.detach()) * frames
            count += frames
            elapsed = time.monotonic() - start
            if progress and elapsed - last_print > 0.5:
                last_print = elapsed
                progress(_status(name, epoch, total / count, best, elapsed, cfg.time_budget_s))
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
    if progress:
        progress(_status(name, epoch, train_loss, best, time.monotonic() - start,
                         cfg.time_budget_s) + f" — stopped: {stop}")
    return {"epochs": epoch, "best_epoch": best_epoch, "best_val_mse": best,
            "stopped_by": stop, "final_train_mse": train_loss}


def _window_batches(est: TrainedEstimator, tr: NormalisedFrames, cfg: TrainConfig,
                    rng: np.random.Generator):
    """One epoch's minibatches for a windowed model: shuffled frames, each with its window;
    yields (loss, frames)."""
    import torch

    net, table = est.network, tr.table
    win, dil = est.config.window, est.config.dilation

    def epoch():
        order = rng.permutation(len(table))
        for s in range(0, len(order), cfg.batch_size):
            frames = order[s : s + cfg.batch_size]
            xb = torch.from_numpy(table.windows(frames, win, dil))
            yb = torch.from_numpy(table.y[frames])
            yield torch.mean((net(xb) - yb) ** 2), len(frames)

    return epoch


def _stream_batches(est: TrainedEstimator, tr: NormalisedFrames, cfg: TrainConfig,
                    rng: np.random.Generator):
    """One epoch's minibatches for a stateful ENNet, by truncated backpropagation through time.

    :data:`STREAMS_PER_BATCH` streams of up to :data:`STREAM_SECONDS`, each starting at a
    random frame of a training block (at the block's start with probability
    :data:`FROM_START_SHARE`), run side by side in chunks of :data:`TBPTT_FRAMES`, the LSTM
    state carried (detached) from chunk to chunk: each update sees as many arm poses as
    streams. A stream that starts inside a block starts from a zero state the true history
    would not give, so its first :data:`BURN_IN_SECONDS` are not scored. An epoch scores
    about as many frames as the training part holds, in at least :data:`MIN_STREAM_GROUPS`
    batches of streams. Yields (loss, scored frames).
    """
    import torch

    net, table = est.network, tr.table
    starts = np.asarray([a for a, _ in tr.bounds])
    stops = np.asarray([b for _, b in tr.bounds])
    lengths = stops - starts
    stream_frames = max(1, round(STREAM_SECONDS * est.sensor_rate_hz))
    burn_in_frames = round(BURN_IN_SECONDS * est.sensor_rate_hz)
    scored_per_group = STREAMS_PER_BATCH * max(1, min(stream_frames, int(lengths.max()))
                                               - burn_in_frames)
    groups = max(MIN_STREAM_GROUPS, int(np.ceil(len(tr) / scored_per_group)))

    def group() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        block = rng.choice(len(starts), STREAMS_PER_BATCH, p=lengths / lengths.sum())
        fresh = rng.random(STREAMS_PER_BATCH) < FROM_START_SHARE
        first = np.where(fresh, starts[block],
                         starts[block] + rng.random(STREAMS_PER_BATCH) * lengths[block])
        first = first.astype(np.int64)
        stop = np.minimum(first + stream_frames, stops[block])
        longest = int((stop - first).max())
        x = np.zeros((STREAMS_PER_BATCH, longest, table.x.shape[1]), dtype=np.float32)
        y = np.zeros((STREAMS_PER_BATCH, longest, table.y.shape[1]), dtype=np.float32)
        scored = np.zeros((STREAMS_PER_BATCH, longest, 1), dtype=np.float32)
        for k in range(STREAMS_PER_BATCH):
            lo, hi = int(first[k]), int(stop[k])
            x[k, : hi - lo], y[k, : hi - lo] = table.x[lo:hi], table.y[lo:hi]
            burn = 0 if lo == starts[block[k]] else min(burn_in_frames, (hi - lo) // 2)
            scored[k, burn : hi - lo] = 1.0
        return x, y, scored

    def epoch():
        for _ in range(groups):
            x, y, scored = group()
            state = None
            for c in range(0, x.shape[1], TBPTT_FRAMES):
                part = slice(c, c + TBPTT_FRAMES)
                weight = torch.from_numpy(scored[:, part])
                frames = float(weight.sum())
                out, state = net.sequence(torch.from_numpy(x[:, part]), state)
                state = (state[0].detach(), state[1].detach())
                if frames == 0:
                    continue
                err = (out - torch.from_numpy(y[:, part])) ** 2 * weight
                yield err.sum() / (frames * y.shape[2]), int(frames)

    return epoch


def _status(kind: str, epoch: int, loss: float, best: float, elapsed: float,
            budget: float) -> str:
    left = max(0.0, budget - elapsed)
    shown = f"{best:.4f}" if math.isfinite(best) else "—"  # no epoch validated yet
    return (f"[{kind}] epoch {epoch} train mse {loss:.4f} best val {shown} "
            f"elapsed {elapsed:5.0f}s, ≤{left:4.0f}s left")


def progress_printer(stream=None, log_every_s: float = 10.0) -> Callable[[str], None]:
    """A ``progress`` callback: redraws one status line on a terminal; on a pipe or log file
    writes a line at most every ``log_every_s`` seconds (and every final "stopped" line).
    ``stream`` defaults to the ``sys.stderr`` of the call (not of the import)."""
    stream = sys.stderr if stream is None else stream
    last = [-float("inf")]

    def show(line: str) -> None:
        if stream.isatty():
            stream.write("\r\x1b[2K" + line + ("\n" if "stopped" in line else ""))
        elif "stopped" in line or time.monotonic() - last[0] >= log_every_s:
            last[0] = time.monotonic()
            stream.write(line + "\n")
        stream.flush()

    return show
