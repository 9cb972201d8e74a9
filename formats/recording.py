"""Recording format v1: the in-memory model of a recording (see docs/recording-format.md).

A recording holds one sensor stream (``/suit/sensors``: tendon path lengths in mm on the
device clock, ~250 Hz, sequence numbers whose gaps mean dropped frames) and any number of
motion-capture streams (``/mocap/<joint>``: joint angles in degrees, ~120 Hz), plus the
``exohil.recording`` metadata record. Times are seconds; both clocks are assumed to share
an origin unless a lag/clock-offset effect says otherwise.

Writing MCAP files lives in :mod:`exohil.formats.recording_writer`, reading them in
:mod:`exohil.formats.recording_reader`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

FORMAT_NAME = "exohil-recording"
FORMAT_VERSION = 1
SENSOR_TOPIC = "/suit/sensors"
MOCAP_PREFIX = "/mocap/"


@dataclass
class SensorStream:
    """Sensor frames in arrival order.

    Attributes:
        seq: (N,) int64 sequence numbers as sent by the device (monotonic, unwrapped).
        t: (N,) float64 device-clock time of each frame, seconds.
        values: (N, S) float64 sensor values, in ``Recording.sensor_units`` (mm by default).
    """

    seq: np.ndarray
    t: np.ndarray
    values: np.ndarray

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def rate_from_times(self) -> float:
        """The frame rate the timestamps give: sequence span over time span, Hz (frames
        missing from the sequence count); NaN with under two frames or no time span."""
        span = float(self.t[-1] - self.t[0]) if len(self) >= 2 else 0.0
        return float(self.seq[-1] - self.seq[0]) / span if span > 0 else float("nan")


@dataclass
class AngleStream:
    """One joint's motion-capture angles.

    Attributes:
        t: (M,) float64 seconds.
        names: angle field names in column order, e.g. ("elv_angle", "shoulder_elv").
        angles: (M, A) float64 degrees.
    """

    t: np.ndarray
    names: tuple[str, ...]
    angles: np.ndarray

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def column(self, name: str) -> np.ndarray:
        """The (M,) series of one angle field, degrees."""
        return self.angles[:, self.names.index(name)]


@dataclass
class Segment:
    """A labelled time span (e.g. one movement of a protocol), seconds on the sensor clock."""

    name: str
    t0: float
    t1: float


@dataclass
class Recording:
    """A whole recording.

    Attributes:
        sensor_names: names of the sensor columns in order (e.g. F, SF, SR, R).
        sensors: the sensor stream.
        mocap: joint name (the topic suffix, e.g. "shoulder") → angle stream.
        sensor_units: unit of the sensor values ("mm" for tendon lengths; other tools may
            write other units, e.g. normalised resistance for textile strain sensors).
        sensor_rate_hz / mocap_rate_hz: nominal rates from the metadata.
        segments: labelled spans (movement types); empty when the writer gave none.
        metadata: the full ``exohil.recording`` metadata as str → str, as stored.
    """

    sensor_names: tuple[str, ...]
    sensors: SensorStream
    mocap: dict[str, AngleStream] = field(default_factory=dict)
    sensor_units: str = "mm"
    sensor_rate_hz: float = 250.0
    mocap_rate_hz: float = 120.0
    segments: list[Segment] = field(default_factory=list)
    metadata: dict[str, str] = field(default_factory=dict)


def cut_recording(rec: Recording, start_s: float, stop_s: float) -> Recording:
    """The part of ``rec`` from ``start_s`` to ``stop_s`` (seconds after its first sensor
    frame, or after its first mocap sample when it has no sensor frames, as an imported
    ``.mot`` has none; start included, stop excluded): its sensor frames, the motion capture
    samples in the same span of the shared clock, and the segments clipped to it (those left
    empty dropped). Times, sequence numbers and metadata are kept as they were, so the part
    lines up with the whole. Raises ValueError for an empty recording, an empty span, or a
    span that holds no frame (no sample, without sensors).
    """
    if not stop_s > start_s:
        raise ValueError(f"empty span: start {start_s:g} s, stop {stop_s:g} s")
    mocap_starts = [float(stream.t[0]) for stream in rec.mocap.values() if len(stream)]
    if len(rec.sensors):
        first, last, what = float(rec.sensors.t[0]), float(rec.sensors.t[-1]), "sensor frames"
    elif mocap_starts:
        first = min(mocap_starts)
        last = max(float(stream.t[-1]) for stream in rec.mocap.values() if len(stream))
        what = "mocap samples"
    else:
        raise ValueError("the recording has no sensor frame or mocap sample to cut")
    lo, hi = first + start_s, first + stop_s
    keep = (rec.sensors.t >= lo) & (rec.sensors.t < hi)
    mocap = {}
    for joint, stream in rec.mocap.items():
        m = (stream.t >= lo) & (stream.t < hi)
        mocap[joint] = AngleStream(stream.t[m], stream.names, stream.angles[m])
    if not (keep.any() if len(rec.sensors) else any(len(s) for s in mocap.values())):
        stop = "the end" if stop_s == float("inf") else f"{stop_s:g} s"
        raise ValueError(f"no {what} from {start_s:g} s to {stop} (the recording "
                         f"spans {last - first:.3f} s after its first {what[:-1]})")
    segments = [Segment(s.name, max(s.t0, lo), min(s.t1, hi)) for s in rec.segments
                if min(s.t1, hi) > max(s.t0, lo)]
    sensors = SensorStream(rec.sensors.seq[keep], rec.sensors.t[keep], rec.sensors.values[keep])
    return Recording(rec.sensor_names, sensors, mocap, rec.sensor_units, rec.sensor_rate_hz,
                     rec.mocap_rate_hz, segments, dict(rec.metadata))
