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
    blocks: list[Block], predictions: list[np.ndarray], angles: tuple[str, ...]
) -> dict:
    """Metrics of given predictions (degrees) against the blocks' targets."""
    if not blocks:
        raise ValueError("nothing to evaluate: no labelled frames")
    err = np.concatenate([p - b.y for p, b in zip(predictions, blocks, strict=True)])
    labels = np.concatenate([b.segment for b in blocks])
    result = error_stats(err, angles)
    result["per_segment"] = {
        str(name): error_stats(err[labels == name], angles)
        for name in sorted({str(v) for v in labels if v})
    }
    return result


def evaluate(est: TrainedEstimator, blocks: list[Block]) -> dict:
    """Run the estimator on every block and score it."""
    return evaluate_predictions(blocks, est.predict(blocks), est.target.angles)
