"""Whether a model's input readings lie where it was trained.

A checkpoint keeps each sensor's mean and standard deviation over its training frames (its
normalisation); a calibrated checkpoint also keeps those of its calibration frames
(``info["calibration"]``, :func:`input_statistics`). A reading many standard deviations from
all of them lies beyond anything the model learnt from, and its estimates there are
extrapolation, however precise they look: the bundled ENNet on another lab's suit
(``../shared/samples/``, tendons of 183–463 mm against its 419–646 mm, 3–12 standard
deviations below the mean) points the arm 153° wrong, and nothing but the accuracy said so.
:class:`CoverageTally` counts the frames with a reading that far out, block by block, so the
same figure comes from a recording (``exohil evaluate``, the conformance suite's compatibility
check) and from a device as it streams (``exohil run``).
"""

from __future__ import annotations

from collections.abc import Iterable
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


def input_statistics(blocks: Iterable[Block]) -> dict[str, list[float]]:
    """``{"input_mean": [...], "input_std": [...]}``: each sensor's mean and standard
    deviation over the blocks' finite frames (what a calibrated checkpoint keeps)."""
    x = np.concatenate([b.x for b in blocks])
    x = x[np.all(np.isfinite(x), axis=1)]
    return {"input_mean": x.mean(axis=0).tolist(), "input_std": x.std(axis=0).tolist()}


def trained_inputs(est: TrainedEstimator) -> list[tuple[np.ndarray, np.ndarray]]:
    """(mean, std) per sensor of every set of frames ``est`` was trained on: its
    normalisation, then the calibration frames of each calibration, newest first."""
    found = [(np.asarray(est.norm.x_mean, dtype=np.float64),
              np.asarray(est.norm.x_std, dtype=np.float64))]
    info: Any = est.info
    while isinstance(info, dict):
        calibration = info.get("calibration")
        if isinstance(calibration, dict) and "input_mean" in calibration:
            mean = np.asarray(calibration["input_mean"], dtype=np.float64)
            std = np.asarray(calibration["input_std"], dtype=np.float64)
            if mean.shape == found[0][0].shape and std.shape == mean.shape and np.all(std > 0):
                found.append((mean, std))
        info = info.get("base_info")
    return found


class CoverageTally:
    """Frames whose readings lie outside a model's training data, added block by block.

    Each frame is measured against the set of training frames (:func:`trained_inputs`) it
    lies closest to: in training standard deviations from that set's mean, its largest
    over the sensors. It is outside when even that exceeds :data:`OUTSIDE_SIGMAS`. Frames with
    a non-finite reading are not counted.
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
        self.outside = 0  #: of those, the frames with a reading outside
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
        z = np.stack([(values - mean) / std for mean, std in self._sets])  # (K, N, S)
        nearest = np.argmin(np.abs(z).max(axis=2), axis=0)
        z = z[nearest, np.arange(n)]
        self.frames += n
        self.outside += int(np.count_nonzero(np.abs(z).max(axis=1) > OUTSIDE_SIGMAS))
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
        text = (f"{self.outside_percent:.1f}% of {self.frames} frames read more than "
                f"{OUTSIDE_SIGMAS:g} standard deviations from the readings the model was "
                "trained on")
        return text + (f" (furthest: {furthest})" if furthest else "")

    def warning(self) -> str | None:
        """What to tell a user when the share outside reaches the warning level, else None."""
        if not self.warns:
            return None
        return (f"{self.note()}: its estimates there are extrapolation. Another suit, "
                "donning or sensor unit, or movements beyond its training or calibration "
                "data? Calibrate it on a recording that covers them (exohil calibrate, "
                "docs/calibration.md)")

    def to_dict(self) -> dict[str, Any]:
        """The JSON form: frames, percent outside, the bound and each sensor's extremes."""
        share = self.outside_percent
        return {"frames": self.frames, "outside_bound_sigmas": OUTSIDE_SIGMAS,
                "outside_percent": None if share is None else round(share, 3),
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
