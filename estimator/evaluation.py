"""Accuracy metrics in degrees: per angle RMSE, MAE and max |error|, overall and per movement.

The JSON layout (``exohil evaluate --json``)::

    {"accuracy": {"accuracy.rmse.<angle>": deg, "accuracy.direction_rmse": deg, ...},
     "rmse": {"<angle>": deg, ...}, "mae": {...}, "max": {...}, "frames": N,
     "per_segment": {"<movement>": {"rmse": {...}, "mae": {...}, "max": {...}, "frames": n}}}

``accuracy`` is exohil's one accuracy definition (:func:`accuracy_measurements`: for a shoulder
model, RMSE per angle where the true elevation is at least 20° and the arm-direction RMSE over
every frame), the figures to compare models by. ``rmse``/``mae``/``max`` are over every scored
frame (all frames, or those ``min_angle`` keeps), θ included where the arm hangs and θ is
undefined.

Every frame of every block is scored (windows are edge-padded at block starts, see
:mod:`exohil.estimator.windows`). Frames outside any labelled segment count towards the overall
figures only.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from exohil.estimator.dataset import Block
from exohil.estimator.trained import TrainedEstimator
from exohil.formats.measurement import Limit, Measurement
from exohil.kinematics import OBSERVABLE_ELEVATION_DEG, humerus_direction

#: Angles that wrap around (deg): an estimate of −179° for a true 179° is 2° off, not 358°.
CIRCULAR_ANGLES = ("elv_angle",)


def angle_errors(estimates: np.ndarray, truth: np.ndarray, angles: Sequence[str]) -> np.ndarray:
    """Estimate − truth (N, A), degrees, with the circular angles' errors wrapped into
    [−180°, 180°)."""
    err = estimates - truth
    for j, name in enumerate(angles):
        if name in CIRCULAR_ANGLES:
            err[:, j] = (err[:, j] + 180.0) % 360.0 - 180.0
    return err


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
    if [p.shape for p in predictions] != [b.y.shape for b in blocks]:
        raise ValueError("one prediction per block, shaped like its targets, is needed")
    predicted = np.concatenate(predictions)
    truth = np.concatenate([b.y for b in blocks])
    err = angle_errors(predicted, truth, angles)
    labels = np.concatenate([b.segment for b in blocks])
    accuracy = {m.name: m.value for m in accuracy_measurements(predicted, truth, angles)}
    if min_angle:
        keep = np.ones(err.shape[0], dtype=bool)
        for name, low in min_angle.items():
            keep &= truth[:, angles.index(name)] >= low
        if not keep.any():
            raise ValueError(f"no frame satisfies {min_angle}")
        err, labels = err[keep], labels[keep]
    result = {"accuracy": accuracy, **error_stats(err, angles)}
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


def arm_direction_error_deg(theta_est, phi_est, theta_true, phi_true) -> np.ndarray:
    """Angle (deg) between the estimated and the true humerus axis, per frame; well defined
    at every pose, including the arm hanging where θ is not. Inputs in degrees."""
    a = humerus_direction(np.deg2rad(theta_est), np.deg2rad(phi_est))
    b = humerus_direction(np.deg2rad(theta_true), np.deg2rad(phi_true))
    cos = np.clip(np.sum(a * b, axis=-1), -1.0, 1.0)
    return np.rad2deg(np.arccos(cos))


class AccuracyTally:
    """Streaming form of :func:`accuracy_measurements`: sums of squared errors and counts,
    added block by block (:meth:`add`), so a run of any length is scored in fixed memory.
    One :meth:`add` of all frames gives exactly :func:`accuracy_measurements`'s values; more
    blocks give the same up to the rounding of their sums."""

    def __init__(self, angles: Sequence[str]) -> None:
        self.angles = tuple(angles)
        self.shoulder = "elv_angle" in self.angles and "shoulder_elv" in self.angles
        self.scored = 0  #: frames with finite truth and estimate
        self.kept = 0  #: of those, the ones each angle is scored on (elevation >= 20 deg)
        self.squares = np.zeros(len(self.angles))  #: Σ error² per angle over ``kept``, deg²
        self.direction_squares = 0.0  #: Σ arm-direction error² over ``scored``, deg²

    def add(self, estimates: np.ndarray, truth: np.ndarray) -> None:
        """Score more frames: (N, A) estimates and truth, degrees, columns in ``angles``
        order; frames whose truth or estimate is not finite are not scored."""
        ok = np.all(np.isfinite(truth), axis=1) & np.all(np.isfinite(estimates), axis=1)
        est, true = estimates[ok], truth[ok]
        self.scored += int(ok.sum())
        keep = np.ones(true.shape[0], dtype=bool)
        if self.shoulder:
            keep = true[:, self.angles.index("shoulder_elv")] >= OBSERVABLE_ELEVATION_DEG
        self.kept += int(keep.sum())
        err = angle_errors(est[keep], true[keep], self.angles)
        self.squares += np.sum(err**2, axis=0)
        if self.shoulder and true.shape[0]:
            th, ph = self.angles.index("elv_angle"), self.angles.index("shoulder_elv")
            err = arm_direction_error_deg(est[:, th], est[:, ph], true[:, th], true[:, ph])
            self.direction_squares += float(np.sum(err**2))

    def measurements(self, limits: Mapping[str, Limit] | None = None) -> list[Measurement]:
        """The measurements of :func:`accuracy_measurements` over every frame added."""
        limits = limits or {}
        out = [Measurement.judge("accuracy.frames_scored", self.scored, "count",
                                 limits.get("accuracy.frames_scored"))]
        note = "all frames"
        if self.shoulder:
            note = (f"{self.kept} frames where elevation >= {OBSERVABLE_ELEVATION_DEG:g} deg "
                    "(the plane of elevation is undefined with the arm hanging)")
        for j, name in enumerate(self.angles):
            key = f"accuracy.rmse.{name}"
            if not self.kept:
                out.append(Measurement.skipped(key, "deg", "no frame to score", limits.get(key)))
                continue
            rmse = float(np.sqrt(self.squares[j] / self.kept))
            out.append(Measurement.judge(key, rmse, "deg", limits.get(key), note))
        if self.shoulder:
            key = "accuracy.direction_rmse"
            if not self.scored:
                out.append(Measurement.skipped(key, "deg", "no frame to score", limits.get(key)))
            else:
                out.append(Measurement.judge(
                    key, float(np.sqrt(self.direction_squares / self.scored)), "deg",
                    limits.get(key), f"{self.scored} frames, every pose"))
        return out


def accuracy_measurements(estimates: np.ndarray, truth: np.ndarray, angles: Sequence[str],
                          limits: Mapping[str, Limit] | None = None) -> list[Measurement]:
    """exohil's one accuracy definition, as measurements (degrees).

    For a shoulder model (angles include ``elv_angle`` and ``shoulder_elv``):
    ``accuracy.rmse.<angle>`` over the frames whose true elevation is at least
    :data:`OBSERVABLE_ELEVATION_DEG`, and ``accuracy.direction_rmse``, the RMSE of the angle
    between estimated and true humerus axis over all frames. For other joints: the RMSE per
    angle over all frames. Frames whose truth is not finite are not scored. ``limits`` maps a
    measurement name to its limit. A stream of frames is scored block by block with
    :class:`AccuracyTally`, which this is one block of.

    Args:
        estimates / truth: (N, A) degrees, columns in ``angles`` order.
    """
    tally = AccuracyTally(angles)
    tally.add(estimates, truth)
    return tally.measurements(limits)
