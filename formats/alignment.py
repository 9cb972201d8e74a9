"""Aligning motion capture with sensor frames (the two streams run at different rates)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from exohil.formats.errors import RecordingError
from exohil.formats.recording import Recording

#: Motion-capture samples further apart than this many median intervals are a dropout.
MOCAP_GAP_INTERVALS = 4.0


def mocap_step(t_mocap: np.ndarray) -> float:
    """The motion capture's sampling interval, s: the median spacing of its distinct
    times (inf with fewer than two)."""
    spacing = np.diff(t_mocap)
    steps = spacing[spacing > 0]  # repeated timestamps are not the sampling interval
    return float(np.median(steps)) if len(steps) else np.inf


def in_mocap_gap(t: np.ndarray, t_mocap: np.ndarray) -> np.ndarray:
    """(N,) bool: times that fall in a motion-capture dropout.

    A dropout is a stretch between consecutive mocap samples longer than
    ``MOCAP_GAP_INTERVALS`` median intervals (markers lost, a paused tracker). The format
    stores no NaN, so a time gap is how a file marks lost markers; the angles interpolated
    across it are a straight line the arm never drew, so frames there have no ground truth.

    Args:
        t: (N,) s, times; t_mocap: (M,) s, sorted mocap times, M ≥ 2.
    """
    spacing = np.diff(t_mocap)
    limit = MOCAP_GAP_INTERVALS * mocap_step(t_mocap)
    after = np.clip(np.searchsorted(t_mocap, t, side="right"), 1, len(t_mocap) - 1)
    return (spacing[after - 1] > limit) & (t > t_mocap[after - 1]) & (t < t_mocap[after])


def angles_at_sensor_times(
    rec: Recording, joint: str = "shoulder", names: Sequence[str] | None = None
) -> np.ndarray:
    """Mocap angles linearly interpolated at each sensor frame time; see :func:`angles_at`.

    Returns:
        (N, A) float64 degrees, N = sensor frames, A = len(names).
    """
    return angles_at(rec, rec.sensors.t, joint, names)


def angles_at(
    rec: Recording, t: np.ndarray, joint: str = "shoulder", names: Sequence[str] | None = None
) -> np.ndarray:
    """Mocap angles linearly interpolated at times ``t`` (s, the sensor/device clock).

    Both clocks are taken as sharing an origin (seconds). Times before the first or after the
    last mocap sample, and inside a dropout (:func:`in_mocap_gap`), get NaN, so callers can
    drop them explicitly.

    Args:
        rec: the recording.
        t: (N,) times, s.
        joint: mocap joint (topic suffix), e.g. "shoulder".
        names: angle fields in the wanted column order (default: all, in stream order).

    Returns:
        (N, A) float64 degrees, A = len(names).

    Raises:
        RecordingError: unknown joint or angle name.
    """
    if joint not in rec.mocap:
        raise RecordingError(f"recording has no mocap joint {joint!r} (has {sorted(rec.mocap)})")
    stream = rec.mocap[joint]
    wanted = tuple(stream.names if names is None else names)
    missing = [name for name in wanted if name not in stream.names]
    if missing:
        raise RecordingError(f"mocap joint {joint!r} has no angle(s) {missing} ({stream.names})")
    t_sensor = np.asarray(t, dtype=np.float64)
    out = np.full((t_sensor.size, len(wanted)), np.nan)
    if len(stream) == 0 or t_sensor.size == 0:
        return out
    order = np.argsort(stream.t, kind="stable")
    t_mocap = np.asarray(stream.t, dtype=np.float64)[order]
    inside = (t_sensor >= t_mocap[0]) & (t_sensor <= t_mocap[-1])
    if len(t_mocap) > 1:
        inside &= ~in_mocap_gap(t_sensor, t_mocap)
    for k, name in enumerate(wanted):
        column = stream.column(name)[order]
        out[inside, k] = np.interp(t_sensor[inside], t_mocap, column)
    return out
