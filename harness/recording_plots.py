"""Figures of a recording: sensor-vs-angle hysteresis loops and stacked time series.

Matplotlib is imported inside the functions with the Agg backend (files only, no display).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from exohil.formats.alignment import angles_at_sensor_times
from exohil.formats.errors import RecordingError
from exohil.formats.recording import Recording

if TYPE_CHECKING:
    from matplotlib.figure import Figure

STILL_DEG_PER_S = 2.0
"""Angular speed below which a sample counts as neither rising nor falling, deg/s."""
SMOOTH_S = 0.1
"""Moving-average window applied to the angle before taking its direction, seconds."""


@dataclass(frozen=True)
class TimeWindow:
    """Sensor-clock spans to keep, seconds: [t0, t1] pairs (an empty list keeps everything)."""

    spans: tuple[tuple[float, float], ...] = ()

    def mask(self, t: np.ndarray) -> np.ndarray:
        """(N,) bool: which times fall in any span."""
        if not self.spans:
            return np.ones(t.shape, dtype=bool)
        keep = np.zeros(t.shape, dtype=bool)
        for t0, t1 in self.spans:
            keep |= (t >= t0) & (t <= t1)
        return keep


def time_window(
    rec: Recording, segment: str | None, t0: float | None, t1: float | None
) -> TimeWindow:
    """The spans of the named segment(s), intersected with [t0, t1] when given."""
    low = -np.inf if t0 is None else t0
    high = np.inf if t1 is None else t1
    if segment is None:
        return TimeWindow(((low, high),)) if (t0 is not None or t1 is not None) else TimeWindow()
    spans = [(max(s.t0, low), min(s.t1, high)) for s in rec.segments if s.name == segment]
    if not spans:
        names = sorted({s.name for s in rec.segments})
        raise RecordingError(f"no segment named {segment!r} (segments: {names or 'none'})")
    return TimeWindow(tuple(spans))


def motion_direction(t: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """(N,) +1 rising, −1 falling, 0 still (|dθ/dt| < STILL_DEG_PER_S) after smoothing.

    ``t`` seconds, ``angle`` degrees; NaN angles give 0. Frames that share a time (the
    format allows it) take the median step between the others.
    """
    steps = np.diff(t)
    steps = steps[steps > 0]
    if t.size < 3 or not steps.size:
        return np.zeros(t.shape, dtype=np.int8)
    step = float(np.median(steps))
    width = max(1, int(round(SMOOTH_S / step)))
    kernel = np.ones(width) / width
    padded = np.pad(np.nan_to_num(angle), (width // 2, width - 1 - width // 2), mode="edge")
    smooth = np.convolve(padded, kernel, mode="valid")
    dt = np.gradient(t)
    speed = np.gradient(smooth) / np.where(dt > 0, dt, step)
    direction = np.where(speed > STILL_DEG_PER_S, 1, np.where(speed < -STILL_DEG_PER_S, -1, 0))
    direction[~np.isfinite(angle)] = 0
    return direction.astype(np.int8)


def plot_hysteresis(
    rec: Recording,
    sensor: str,
    *,
    joint: str = "shoulder",
    angle: str = "shoulder_elv",
    window: TimeWindow | None = None,
    title: str = "",
) -> Figure:
    """Sensor value against the mocap angle at sensor times, coloured by motion direction
    (rising / falling angle), so loading and unloading branches of a loop separate."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    column = _sensor_column(rec, sensor)
    angles = angles_at_sensor_times(rec, joint, [angle])[:, 0]
    window = window or TimeWindow()
    keep = window.mask(rec.sensors.t) & np.isfinite(angles)
    if not np.any(keep):
        streams = {"sensor frames": rec.sensors.t, f"/mocap/{joint}": rec.mocap[joint].t}
        if window.spans:
            raise RecordingError("no sensor frames with mocap in the chosen time window"
                                 + _spans_text(streams))
        # no window: the motion capture does not overlap the sensors (or holds no sample)
        raise RecordingError(f"no sensor frame lies within the /mocap/{joint} samples of "
                             f"{angle} (" + ", ".join(
                                 f"{name} {t[0]:.3f} → {t[-1]:.3f} s" if len(t)
                                 else f"{name}: none" for name, t in streams.items()) + ")")
    t, x, y = rec.sensors.t[keep], angles[keep], rec.sensors.values[keep, column]
    direction = motion_direction(t, x)
    figure = Figure(figsize=(7.0, 5.0), dpi=120, layout="constrained")
    axes = figure.add_subplot()
    styles = ((0, "#b0b0b0", "still"), (1, "#d62728", "rising"), (-1, "#1f77b4", "falling"))
    for value, colour, label in styles:
        chosen = direction == value
        if np.any(chosen):
            axes.scatter(
                x[chosen], y[chosen], s=3, color=colour, label=f"{angle} {label}",
                alpha=0.6 if value else 0.3, linewidths=0, rasterized=True,
            )
    axes.set_xlabel(f"{angle} (deg, /mocap/{joint} at sensor times)")
    axes.set_ylabel(f"{sensor} ({rec.sensor_units})")
    axes.set_title(title or f"{sensor} vs {angle}: hysteresis")
    axes.grid(True, alpha=0.3)
    axes.legend(markerscale=4, loc="best")
    return figure


def plot_timeseries(
    rec: Recording,
    sensors: Sequence[str] = (),
    *,
    window: TimeWindow | None = None,
    title: str = "",
) -> Figure:
    """Two stacked axes sharing time: sensor values (top) and all mocap angles (bottom)."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    window = window or TimeWindow()
    keep = window.mask(rec.sensors.t)
    if not keep.any() and not any(window.mask(s.t).any() for s in rec.mocap.values()):
        raise RecordingError("no sensor frame or mocap sample in the chosen time window"
                             + _spans_text({"sensor frames": rec.sensors.t,
                                            **{f"/mocap/{j}": s.t for j, s in rec.mocap.items()}}))
    figure = Figure(figsize=(10.0, 6.0), dpi=120, layout="constrained")
    top, bottom = figure.subplots(2, 1, sharex=True)
    for name in sensors or rec.sensor_names:
        column = _sensor_column(rec, name)
        top.plot(rec.sensors.t[keep], rec.sensors.values[keep, column], lw=0.8, label=name)
    if not rec.sensor_names:
        top.text(0.5, 0.5, "no sensors (mocap-only recording)", transform=top.transAxes,
                 ha="center", va="center", color="grey")
    top.set_ylabel(f"sensor ({rec.sensor_units})")
    for joint, stream in rec.mocap.items():
        inside = window.mask(stream.t)
        for k, name in enumerate(stream.names):
            bottom.plot(stream.t[inside], stream.angles[inside, k], lw=0.8, label=f"{joint} {name}")
    bottom.set_ylabel("angle (deg)")
    bottom.set_xlabel("time (s)")
    for axes in (top, bottom):
        axes.grid(True, alpha=0.3)
        if axes.get_legend_handles_labels()[0]:
            axes.legend(loc="upper right", fontsize="small")
    top.set_title(title or "sensors and angles")
    return figure


def _sensor_column(rec: Recording, sensor: str) -> int:
    if sensor not in rec.sensor_names:
        raise RecordingError(f"no sensor {sensor!r} (sensors: {','.join(rec.sensor_names)})")
    return rec.sensor_names.index(sensor)


def _spans_text(streams: dict[str, np.ndarray]) -> str:
    """Where each stream's times lie, for an empty window: the window is on the recording's
    own clock (a part cut from 10 s on starts at 10 s, not at 0)."""
    spans = [f"{name} {t[0]:.3f} → {t[-1]:.3f} s" for name, t in streams.items() if len(t)]
    return f" (the window is on the recording's clock: {', '.join(spans)})" if spans else ""
