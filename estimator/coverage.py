"""Whether a model's input readings lie where it was trained.

A checkpoint keeps each sensor's mean and standard deviation over its training frames (its
normalisation); one trained or calibrated since 2026-12-03 also keeps where its training
frames and each calibration's frames lie as a whole (:func:`input_statistics`: a whitening
and the largest Mahalanobis distance of any of them). A frame is outside a set of training
frames when some sensor reads more than :data:`OUTSIDE_SIGMAS` standard deviations from its
mean, or when the frame as a whole lies farther out than any of them did: readings each
within their range whose combination the model never saw (a movement it was not trained
on). Estimates there are extrapolation, however precise they look: the bundled ENNet on
another lab's suit (``../shared/samples/``, tendons of 183–463 mm against its 419–646 mm,
3–12 standard deviations below the mean) points the arm 153° wrong, and nothing but the
accuracy said so. :class:`CoverageTally` counts the frames outside every set, block by
block, so the same figure comes from a recording (``exohil evaluate``, the conformance
suite's compatibility check) and from a device as it streams (``exohil run``).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from exohil.estimator.dataset import Block
from exohil.estimator.trained import TrainedEstimator

#: A reading further than this many training standard deviations from the training mean is
#: outside the training data. The bundled models' own training and held-out recordings reach
#: 3.1; a movement that spans its training range evenly reaches 1.7 (uniform) or 1.4 (a sine).
OUTSIDE_SIGMAS = 4.0
#: The share of frames outside (%) from which a warning is given and the conformance suite's
#: compatibility check fails: a few frames beyond a training extreme are a wider movement,
#: one in a hundred is another suit, donning or unit.
OUTSIDE_SHARE_PERCENT = 1.0


#: Eigenvalues of the readings' covariance are floored at this share of the largest before
#: whitening, so that a direction the training frames never moved in (a dead or duplicated
#: sensor) counts by its spread at that floor instead of dividing by zero.
EIGEN_FLOOR = 1e-6


def input_statistics(blocks: Iterable[Block]) -> dict[str, Any]:
    """Where the blocks' finite frames lie, as a checkpoint keeps it: each sensor's mean and
    standard deviation (``input_mean``, ``input_std``), a whitening matrix W (S × S) under
    which their covariance is the identity (``input_whitening``, rows: the input) and the
    largest Mahalanobis distance ‖(x − mean)·W‖ of any of them (``input_reach``)."""
    x = np.concatenate([b.x for b in blocks])
    x = x[np.all(np.isfinite(x), axis=1)]
    mean = x.mean(axis=0)
    eigenvalues, vectors = np.linalg.eigh(np.atleast_2d(np.cov(x, rowvar=False)))
    floor = max(float(eigenvalues.max()), np.finfo(float).tiny) * EIGEN_FLOOR
    whitening = vectors / np.sqrt(np.maximum(eigenvalues, floor))
    reach = float(np.sqrt((((x - mean) @ whitening) ** 2).sum(axis=1)).max())
    return {"input_mean": mean.tolist(), "input_std": x.std(axis=0).tolist(),
            "input_whitening": whitening.tolist(), "input_reach": reach}


@dataclass(frozen=True)
class TrainedInputs:
    """Where one set of training frames lies (:func:`input_statistics`); ``whitening`` and
    ``reach`` are None for a checkpoint that does not keep them (written before
    2026-12-03: its normalisation only)."""

    mean: np.ndarray
    std: np.ndarray
    whitening: np.ndarray | None = None
    reach: float | None = None

    @classmethod
    def kept(cls, stats: dict, n_sensors: int) -> TrainedInputs | None:
        """The set a checkpoint keeps in ``stats`` (None where it keeps none that fits)."""
        try:
            mean = np.asarray(stats["input_mean"], dtype=np.float64)
            std = np.asarray(stats["input_std"], dtype=np.float64)
        except (KeyError, TypeError, ValueError):
            return None
        if mean.shape != (n_sensors,) or std.shape != mean.shape or not np.all(std > 0):
            return None
        whitening, reach = stats.get("input_whitening"), stats.get("input_reach")
        if whitening is None or reach is None:
            return cls(mean, std)
        whitening = np.asarray(whitening, dtype=np.float64)
        if whitening.shape != (n_sensors, n_sensors) or not float(reach) > 0:
            return cls(mean, std)
        return cls(mean, std, whitening, float(reach))

    def scores(self, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, S) readings in standard deviations from the mean, and (N,) how far out each
        frame is: the larger of its largest |z| over :data:`OUTSIDE_SIGMAS` and its
        Mahalanobis distance over the reach; above 1 is outside."""
        z = (values - self.mean) / self.std
        score = np.abs(z).max(axis=1) / OUTSIDE_SIGMAS
        if self.whitening is not None and self.reach is not None:
            distance = np.sqrt((((values - self.mean) @ self.whitening) ** 2).sum(axis=1))
            score = np.maximum(score, distance / self.reach)
        return z, score


def trained_inputs(est: TrainedEstimator) -> list[TrainedInputs]:
    """Every set of frames ``est`` was trained on: its training frames (``info
    ["training_inputs"]``, of the first checkpoint in a chain of calibrations; else its
    normalisation), then the calibration frames of each calibration, newest first."""
    n = len(est.sensor_names)
    training = TrainedInputs(np.asarray(est.norm.x_mean, dtype=np.float64),
                             np.asarray(est.norm.x_std, dtype=np.float64))
    calibrations = []
    info: Any = est.info
    while isinstance(info, dict):
        kept = TrainedInputs.kept(info.get("training_inputs") or {}, n)
        if kept is not None:
            training = kept
        calibration = info.get("calibration")
        kept = TrainedInputs.kept(calibration, n) if isinstance(calibration, dict) else None
        if kept is not None:
            calibrations.append(kept)
        info = info.get("base_info")
    return [training, *calibrations]


class CoverageTally:
    """Frames whose readings lie outside a model's training data, added block by block.

    Each frame is measured against the set of training frames (:func:`trained_inputs`) it
    lies closest to (:meth:`TrainedInputs.scores`) and is outside when it lies outside even
    that one. Frames with a non-finite reading are not counted.
    """

    def __init__(self, est: TrainedEstimator, *, raw: bool = True) -> None:
        """``raw``: the readings come as the device sends them, one stream in order, and
        the tally removes the model's rest offset itself as its engine does (for a model
        with ``offset_frames``); False: they are already as the model sees them (a
        :class:`~exohil.estimator.dataset.Block`'s ``x``)."""
        self.sensor_names = est.sensor_names
        self._sets = trained_inputs(est)
        self._offset_frames = est.offset_frames if raw else 0
        self._base_sum = np.zeros(len(self.sensor_names))
        self._base_count = 0
        self.frames = 0  #: frames with every reading finite
        self.outside = 0  #: of those, the frames outside
        #: the largest score of a frame (TrainedInputs.scores, against its nearest set)
        self.furthest = 0.0
        self._low = np.full(len(self.sensor_names), np.inf)
        self._high = np.full(len(self.sensor_names), -np.inf)

    def add(self, values: np.ndarray) -> None:
        """Count (N, S) readings in the model's sensor units."""
        values = np.asarray(values, dtype=np.float64)
        values = values[np.all(np.isfinite(values), axis=1)]
        n = values.shape[0]
        if not n:
            return
        if self._offset_frames:
            values = values - self._rest_offset(values)
        zs, per_set = zip(*(inputs.scores(values) for inputs in self._sets), strict=True)
        scores = np.stack(per_set)  # (K, N)
        nearest = np.argmin(scores, axis=0)
        rows = np.arange(n)
        z, score = np.stack(zs)[nearest, rows], scores[nearest, rows]
        self.frames += n
        self.outside += int(np.count_nonzero(score > 1.0))
        self.furthest = max(self.furthest, float(score.max()))
        self._low = np.minimum(self._low, z.min(axis=0))
        self._high = np.maximum(self._high, z.max(axis=0))

    def _rest_offset(self, values: np.ndarray) -> np.ndarray:
        """(N, S) causal rest offset of the stream's next ``values``: the mean of its first
        ``offset_frames`` frames so far (:func:`exohil.estimator.dataset.initial_baseline`)."""
        head = values[:max(0, self._offset_frames - self._base_count)]
        if head.shape[0]:
            sums = self._base_sum + np.cumsum(head, axis=0)
            counts = self._base_count + np.arange(1, head.shape[0] + 1)
            self._base_sum, self._base_count = sums[-1], int(counts[-1])
            offset = np.empty_like(values)
            offset[:head.shape[0]] = sums / counts[:, None]
            offset[head.shape[0]:] = offset[head.shape[0] - 1]
            return offset
        return np.broadcast_to(self._base_sum / self._base_count, values.shape)

    @property
    def outside_percent(self) -> float | None:
        """The share of counted frames outside, %; None before any frame."""
        return 100.0 * self.outside / self.frames if self.frames else None

    @property
    def warns(self) -> bool:
        """Whether the share outside reaches :data:`OUTSIDE_SHARE_PERCENT`."""
        share = self.outside_percent
        return share is not None and share >= OUTSIDE_SHARE_PERCENT

    def extremes(self) -> dict[str, tuple[float, float]]:
        """Sensor → (lowest, highest) reading, in training standard deviations from the
        mean of the training frames nearest each frame; empty before any frame."""
        if not self.frames:
            return {}
        return {name: (float(lo), float(hi))
                for name, lo, hi in zip(self.sensor_names, self._low, self._high, strict=True)}

    def note(self) -> str:
        """One clause: how many frames lie outside and which sensors reach furthest."""
        if not self.frames:
            return "no frame with finite readings"
        far = sorted(((max(-lo, hi), name, lo if -lo > hi else hi)
                      for name, (lo, hi) in self.extremes().items()), reverse=True)
        furthest = ", ".join(f"{name} {z:+.1f}σ" for size, name, z in far
                             if size > OUTSIDE_SIGMAS)
        sensors = f"; sensors beyond {OUTSIDE_SIGMAS:g}σ: {furthest}" if furthest else ""
        return (f"{self.outside_percent:.1f}% of {self.frames} frames lie outside the readings "
                f"the model was trained on (up to {self.furthest:.1f}× as far out as they reach"
                f"{sensors})")

    def warning(self) -> str | None:
        """What to tell a user when the share outside reaches the warning level, else None."""
        if not self.warns:
            return None
        return (f"{self.note()}: its estimates there are extrapolation. Another suit, "
                "donning or sensor unit, or movements its training or calibration data did "
                "not hold? Calibrate it on a recording that covers them (exohil calibrate, "
                "docs/calibration.md)")

    def to_dict(self) -> dict[str, Any]:
        """The JSON form: frames, percent outside, the bound and each sensor's extremes."""
        share = self.outside_percent
        return {"frames": self.frames, "outside_bound_sigmas": OUTSIDE_SIGMAS,
                "outside_percent": None if share is None else round(share, 3),
                "furthest": round(self.furthest, 3) if self.frames else None,
                "extremes_sigmas": {name: [round(lo, 2), round(hi, 2)]
                                    for name, (lo, hi) in self.extremes().items()}}


def block_coverage(est: TrainedEstimator, blocks: Iterable[Block]) -> CoverageTally:
    """The tally of ``est``'s training coverage over blocks of frames as it sees them."""
    tally = CoverageTally(est, raw=False)
    for block in blocks:
        tally.add(block.x)
    return tally


def stream_coverage(est: TrainedEstimator, values: np.ndarray) -> CoverageTally:
    """The tally of ``est``'s training coverage over one stream of raw (N, S) readings, in
    the order the device sent them (a recording's sensor frames)."""
    tally = CoverageTally(est)
    tally.add(values)
    return tally
