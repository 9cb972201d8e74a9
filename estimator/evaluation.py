"""Accuracy metrics in degrees: per angle RMSE, MAE and max |error|, overall and per movement.

The JSON layout (``exohil evaluate --json``)::

    {"rmse": {"<angle>": deg, ...}, "mae": {...}, "max": {...}, "frames": N,
     "per_segment": {"<movement>": {"rmse": {...}, "mae": {...}, "max": {...}, "frames": n}}}

Every frame of every block is scored (windows are edge-padded at block starts, see
:mod:`exohil.estimator.windows`). Frames outside any labelled segment count towards the overall
figures only.
"""

from __future__ import annotations

import numpy as np

from exohil.estimator.dataset import Block
from exohil.estimator.trained import TrainedEstimator


def error_stats(err: np.ndarray, angles: tuple[str, ...]) -> dict:
    """RMSE/MAE/max of an (N, A) error array (degrees), keyed by angle name."""
    return {
        "rmse": {a: float(np.sqrt(np.mean(err[:, j] ** 2))) for j, a in enumerate(angles)},
        "mae": {a: float(np.mean(np.abs(err[:, j]))) for j, a in enumerate(angles)},
        "max": {a: float(np.max(np.abs(err[:, j]))) for j, a in enumerate(angles)},
        "frames": int(err.shape[0]),
    }


def evaluate_predictions(
    blocks: list[Block], predictions: list[np.ndarray], angles: tuple[str, ...],
    min_angle: dict[str, float] | None = None,
) -> dict:
    """Metrics of given predictions (degrees) against the blocks' targets.

    ``min_angle`` ({angle: degrees}) scores only frames whose true angle is at least that
    value (e.g. θ only where φ ≥ 20°, where the plane of elevation is observable); the model
    still runs on every frame.
    """
    if not blocks:
        raise ValueError("nothing to evaluate: no labelled frames")
    err = np.concatenate([p - b.y for p, b in zip(predictions, blocks, strict=True)])
    labels = np.concatenate([b.segment for b in blocks])
    if min_angle:
        truth = np.concatenate([b.y for b in blocks])
        keep = np.ones(err.shape[0], dtype=bool)
        for name, low in min_angle.items():
            keep &= truth[:, angles.index(name)] >= low
        if not keep.any():
            raise ValueError(f"no frame satisfies {min_angle}")
        err, labels = err[keep], labels[keep]
    result = error_stats(err, angles)
    result["per_segment"] = {
        str(name): error_stats(err[labels == name], angles)
        for name in sorted({str(v) for v in labels if v})
    }
    if min_angle:
        result["min_angle"] = dict(min_angle)
    return result


def evaluate(est: TrainedEstimator, blocks: list[Block],
             min_angle: dict[str, float] | None = None) -> dict:
    """Run the estimator on every block and score it (see :func:`evaluate_predictions`)."""
    return evaluate_predictions(blocks, est.predict(blocks), est.target.angles, min_angle)
