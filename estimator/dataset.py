"""Recordings → aligned estimator data: sensor frames paired with target angles.

A :class:`Block` is a run of consecutive received sensor frames with the target
angles interpolated at the sensor times. Every model sees the data as blocks; a window never
crosses a block boundary, so a split made of whole blocks can never leak a window between train,
validation and test (see :mod:`exohil.estimator.splits`).

Units: sensor values stay in the recording's unit (mm for tendon lengths); angles are degrees;
times are seconds on the sensor clock.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from exohil.formats.alignment import in_mocap_gap
from exohil.formats.errors import InputError
from exohil.formats.recording import Recording

#: Default targets for the shoulder suit: MoBL-ARMS elv_angle (θ) and shoulder_elv (φ).
SHOULDER_JOINT = "shoulder"
SHOULDER_ANGLES = ("elv_angle", "shoulder_elv")


class DatasetError(InputError, ValueError):
    """A recording cannot provide the requested sensors or angles."""


@dataclass(frozen=True)
class TargetSpec:
    """Which mocap joint and which of its angle fields a model estimates."""

    joint: str
    angles: tuple[str, ...]

    @property
    def labels(self) -> tuple[str, ...]:
        """Output names used in metrics and checkpoints, e.g. ``shoulder/elv_angle``."""
        return tuple(f"{self.joint}/{a}" for a in self.angles)


@dataclass
class Block:
    """Consecutive sensor frames with their targets.

    Attributes:
        x: (N, S) float64 sensor values (recording units, after any offset removal).
        y: (N, A) float64 target angles, degrees.
        t: (N,) float64 sensor-clock time, seconds.
        segment: (N,) object array of movement labels ("" outside any segment).
        source: a name for the recording the block came from.
    """

    x: np.ndarray
    y: np.ndarray
    t: np.ndarray
    segment: np.ndarray
    source: str = ""

    def __len__(self) -> int:
        return int(self.x.shape[0])

    def slice(self, start: int, stop: int) -> Block:
        """The frames ``start:stop`` as a new block (same source)."""
        return Block(
            self.x[start:stop],
            self.y[start:stop],
            self.t[start:stop],
            self.segment[start:stop],
            self.source,
        )


def _require_mocap(rec: Recording) -> None:
    """DatasetError for a recording without motion capture: there is no truth to learn."""
    if not rec.mocap:
        raise DatasetError("the recording has no motion capture (no /mocap/<joint> stream), "
                           "and training, evaluating or calibrating a model needs the true "
                           "angles: record the trial with motion capture (or a goniometer)")


def default_target(rec: Recording) -> TargetSpec:
    """The shoulder θ/φ pair when present, else every angle of the recording's only joint."""
    _require_mocap(rec)
    shoulder = rec.mocap.get(SHOULDER_JOINT)
    if shoulder is not None and all(a in shoulder.names for a in SHOULDER_ANGLES):
        return TargetSpec(SHOULDER_JOINT, SHOULDER_ANGLES)
    if len(rec.mocap) == 1:
        joint, stream = next(iter(rec.mocap.items()))
        return TargetSpec(joint, tuple(stream.names))
    raise DatasetError(
        "cannot choose target angles: the recording has mocap joints "
        f"{sorted(rec.mocap) or 'none'}; pass --joint (and --angles)"
    )


def resolve_target(rec: Recording, joint: str | None, angles: tuple[str, ...] | None) -> TargetSpec:
    """Target from explicit ``joint``/``angles`` (either may be None → defaults)."""
    _require_mocap(rec)
    if joint is None and not angles:
        return default_target(rec)
    if joint is None:
        joint = default_target(rec).joint
    stream = rec.mocap.get(joint)
    if stream is None:
        raise DatasetError(f"joint {joint!r} not in recording (has {sorted(rec.mocap)})")
    chosen = tuple(angles) if angles else tuple(stream.names)
    missing = [a for a in chosen if a not in stream.names]
    if missing:
        raise DatasetError(f"angles {missing} not in joint {joint!r} (has {list(stream.names)})")
    return TargetSpec(joint, chosen)


def initial_baseline(x: np.ndarray, frames: int) -> np.ndarray:
    """Causal per-frame rest offset: mean of the first ``min(i+1, frames)`` frames, (N, S).

    Frame i only uses frames 0..i, so a streaming engine computes the same value live.
    """
    n = x.shape[0]
    k = min(frames, n)
    running = np.cumsum(x[:k], axis=0) / np.arange(1, k + 1)[:, None]
    out = np.empty_like(x)
    out[:k] = running
    out[k:] = running[k - 1] if k else 0.0
    return out


def segment_labels(rec: Recording, t: np.ndarray) -> np.ndarray:
    """Movement label of every sensor time (first matching segment; "" if none)."""
    labels = np.full(t.shape[0], "", dtype=object)
    for seg in reversed(rec.segments):
        labels[(t >= seg.t0) & (t <= seg.t1)] = seg.name
    return labels


def recording_blocks(
    rec: Recording,
    target: TargetSpec,
    *,
    offset_frames: int = 0,
    source: str = "",
) -> list[Block]:
    """Split a recording into blocks of consecutive, fully labelled sensor frames.

    Target angles are linearly interpolated at the sensor times; sensor frames outside the
    mocap time range, inside a mocap dropout (samples more than
    :data:`~exohil.formats.alignment.MOCAP_GAP_INTERVALS` intervals apart) or where a
    target is NaN are dropped and end a block. Frames lost on the
    link (gaps in the sequence numbers) do not: a streaming estimator simply sees the next
    frame, and so does the window here. With ``offset_frames > 0`` the
    causal initial baseline (:func:`initial_baseline`, computed over the whole recording) is
    subtracted from every sensor first: the per-donning offset handling.
    """
    stream = rec.mocap.get(target.joint)
    if stream is None:
        raise DatasetError(f"{source or 'recording'}: no mocap joint {target.joint!r}")
    if rec.sensors.values.ndim != 2 or len(rec.sensors) == 0:
        raise DatasetError(f"{source or 'recording'}: no sensor frames")
    t = np.asarray(rec.sensors.t, dtype=np.float64)
    x = np.asarray(rec.sensors.values, dtype=np.float64)
    if offset_frames > 0:
        x = x - initial_baseline(x, offset_frames)
    y = np.empty((t.shape[0], len(target.angles)))
    order = np.argsort(stream.t, kind="stable")
    mt = np.asarray(stream.t, dtype=np.float64)[order]
    for j, name in enumerate(target.angles):
        col = np.asarray(stream.column(name), dtype=np.float64)[order]
        ok = np.isfinite(col)
        if ok.sum() < 2:
            raise DatasetError(f"{source or 'recording'}: angle {name!r} has no data")
        y[:, j] = np.interp(t, mt[ok], col[ok])
        # frames inside a NaN gap of this angle are unlabelled
        gap_idx = np.searchsorted(mt, t)
        inside = (gap_idx > 0) & (gap_idx < mt.shape[0])
        bad = np.zeros(t.shape[0], dtype=bool)
        bad[inside] = ~(ok[gap_idx[inside] - 1] & ok[gap_idx[inside]])
        y[bad, j] = np.nan
    valid = (t >= mt[0]) & (t <= mt[-1]) & np.all(np.isfinite(y), axis=1)
    valid &= ~in_mocap_gap(t, mt)  # interpolated across a dropout: a line never drawn
    valid &= np.all(np.isfinite(x), axis=1)
    breaks = np.ones(t.shape[0], dtype=bool)
    breaks[1:] = ~valid[:-1]
    labels = segment_labels(rec, t)
    blocks: list[Block] = []
    starts = np.flatnonzero(breaks & valid)
    stops = np.append(np.flatnonzero(~valid | breaks), t.shape[0])
    for s in starts:
        e = int(stops[np.searchsorted(stops, s, side="right")])
        blocks.append(Block(x[s:e], y[s:e], t[s:e], labels[s:e], source))
    return blocks


def check_sensors(rec: Recording, expected: tuple[str, ...], source: str = "") -> None:
    """Raise DatasetError unless the recording has exactly the expected sensor columns."""
    got = tuple(rec.sensor_names)
    if got != tuple(expected):
        raise DatasetError(
            f"{source or 'recording'} has sensors {list(got)} ({len(got)}), the model expects "
            f"{list(expected)} ({len(expected)})"
        )
