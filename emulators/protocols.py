"""Movements that drive the simulated suit: the paper's protocol, a calibration recording's
and real recorded motion.

A :class:`Trajectory` gives the MoBL-ARMS shoulder angles (θ = elv_angle, φ = shoulder_elv,
ψ = shoulder_rot, degrees) at any time, plus labelled :class:`Segment` spans (seconds on the
trajectory's clock, which is the motion-capture clock).

* :func:`paper_protocol` — the movements of Varghese et al. Table III with their exact
  motion-capture frame counts at 120 Hz (29,551 frames ≈ 246.3 s), seeded: point-to-point
  minimum-jerk moves with holds, partial reversals and several amplitudes and speeds.
* :func:`calibration_protocol` — what a new wearer does for a calibration recording (60 s by
  default): the same kinds of movement, briefly, within the paper protocol's range.
* :func:`mot_trajectory` — real shoulder motion from OpenSim ``.mot`` IK results (e.g. the
  shoulder-ik data set), several trials concatenated with smooth bridges.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import numpy as np
from scipy.interpolate import PchipInterpolator

from exohil.emulators.seeding import keyed_rng
from exohil.formats.opensim_mot import read_mot
from exohil.formats.recording import Recording, Segment
from exohil.kinematics import isb_to_ms

ANGLE_NAMES = ("elv_angle", "shoulder_elv", "shoulder_rot")
MOCAP_RATE_HZ = 120.0

#: Varghese et al. Table III: movement label → motion-capture frames at 120 Hz.
PAPER_MOVEMENT_FRAMES: dict[str, int] = {
    "flexion_extension": 3037,
    "abduction_adduction": 3630,
    "azimuth_fixed_elevation_varied": 5814,
    "elevation_fixed_azimuth_varied": 6757,
    "random": 10313,
}


def minimum_jerk(tau: np.ndarray) -> np.ndarray:
    """Normalised minimum-jerk position profile 10τ³ − 15τ⁴ + 6τ⁵ for τ in [0, 1]."""
    tau = np.clip(tau, 0.0, 1.0)
    return tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)


@dataclass
class Trajectory:
    """Shoulder angles as knots plus an interpolation rule.

    Attributes:
        knot_t: (K,) increasing knot times, s, starting at 0.
        knot_deg: (K, 3) θ, φ, ψ at the knots, degrees.
        interpolation: "minimum_jerk" (rest-to-rest minimum-jerk move between consecutive
            knots) or "pchip" (shape-preserving cubic through dense samples).
        duration_s: length of the trajectory, s (≥ the last knot; the last pose holds).
        segments: labelled spans, s.
        source: short provenance text (e.g. "paper_protocol seed=7").
    """

    knot_t: np.ndarray
    knot_deg: np.ndarray
    interpolation: str
    duration_s: float
    segments: list[Segment] = field(default_factory=list)
    source: str = ""

    def __post_init__(self) -> None:
        if self.interpolation not in ("minimum_jerk", "pchip"):
            raise ValueError(f"unknown interpolation {self.interpolation!r}")
        self.knot_t = np.asarray(self.knot_t, dtype=np.float64)
        self.knot_deg = np.asarray(self.knot_deg, dtype=np.float64)
        if self.knot_t.ndim != 1 or self.knot_deg.shape != (self.knot_t.shape[0], 3) \
                or self.knot_t.shape[0] < 2:
            raise ValueError("a trajectory needs at least two knots of (θ, φ, ψ): knot_t (K,), "
                             f"knot_deg (K, 3); got {self.knot_t.shape}, {self.knot_deg.shape}")
        if not (np.isfinite(self.knot_t).all() and np.isfinite(self.knot_deg).all()):
            raise ValueError("knot times and angles must be finite")
        if np.any(np.diff(self.knot_t) <= 0):
            raise ValueError("knot times must increase")
        if not 0 < self.duration_s < math.inf:
            raise ValueError(f"duration_s must be a finite number of seconds > 0, got "
                             f"{self.duration_s!r}")

    def sample(self, t: np.ndarray) -> np.ndarray:
        """(N, 3) θ, φ, ψ in degrees at times ``t`` (s); clamps outside the knots."""
        t = np.clip(np.asarray(t, dtype=np.float64), self.knot_t[0], self.knot_t[-1])
        if self.interpolation == "pchip":
            return PchipInterpolator(self.knot_t, self.knot_deg, axis=0)(t)
        i = np.clip(np.searchsorted(self.knot_t, t, side="right") - 1, 0, len(self.knot_t) - 2)
        t0, t1 = self.knot_t[i], self.knot_t[i + 1]
        s = minimum_jerk((t - t0) / (t1 - t0))[:, None]
        return self.knot_deg[i] + (self.knot_deg[i + 1] - self.knot_deg[i]) * s

    def frame_times(self, rate_hz: float) -> np.ndarray:
        """Frame times k / rate_hz for the ``round(duration_s · rate_hz)`` frames, s."""
        return np.arange(int(round(self.duration_s * rate_hz))) / rate_hz


class _Path:
    """Builds a rest-to-rest minimum-jerk knot sequence, one step at a time (degrees, s)."""

    def __init__(self, theta: float, phi: float) -> None:
        self.durations: list[float] = []
        self.poses: list[tuple[float, float]] = [(theta, phi)]

    def move(self, theta: float, phi: float, duration_s: float) -> None:
        self.durations.append(duration_s)
        self.poses.append((theta, phi))

    def move_at(self, theta: float, phi: float, speed_deg_s: float) -> None:
        """Move at a mean angular speed (deg/s) over the larger of the two angle changes."""
        last_theta, last_phi = self.poses[-1]
        distance = max(abs(theta - last_theta), abs(phi - last_phi))
        self.move(theta, phi, _move_time(distance, speed_deg_s))

    def hold(self, duration_s: float) -> None:
        self.move(*self.poses[-1], duration_s)

    def elevate(self, theta: float, amplitude: float, rng: np.random.Generator,
                hold_s: float, speed_deg_s: float) -> None:
        """Raise the arm in plane θ to ``amplitude`` and lower it, sometimes with a partial
        reversal on the way up (a minor hysteresis loop)."""
        start_phi = self.poses[-1][1]
        if amplitude > 45 and rng.random() < 0.35:
            mid = amplitude * rng.uniform(0.5, 0.75)
            back = mid - rng.uniform(10.0, 25.0)
            self.move(theta, mid, _move_time(mid - start_phi, speed_deg_s))
            self.move(theta, back, _move_time(mid - back, speed_deg_s))
        self.move(theta, amplitude, _move_time(amplitude - self.poses[-1][1], speed_deg_s))
        self.hold(hold_s)
        self.move(theta, start_phi, _move_time(amplitude - start_phi, speed_deg_s))


def _move_time(distance_deg: float, speed_deg_s: float) -> float:
    """Duration of a minimum-jerk move of ``distance_deg`` at mean speed ``speed_deg_s``."""
    return max(0.4, abs(distance_deg) / speed_deg_s)


def _flexion_extension(path: _Path, rng: np.random.Generator, span_s: float,
                       flexion_deg: Sequence[float] = (90.0, 60.0, 80.0, 45.0),
                       extension_deg: Sequence[float] = (60.0, 40.0, 50.0, 30.0)) -> None:
    """One flexion (θ = 90°) then one extension (θ = −90°) per repetition, to about the
    given elevations (up to 5 % / 10 % less)."""
    for flexion, extension in zip(flexion_deg, extension_deg, strict=True):
        speed = rng.uniform(35.0, 90.0)
        path.move(90.0, 0.0, 1.0)  # change plane while the arm hangs
        path.elevate(90.0, flexion * rng.uniform(0.95, 1.0), rng,
                     hold_s=rng.uniform(0.3, 2.0), speed_deg_s=speed)
        path.move(-90.0, 0.0, 1.0)
        path.elevate(-90.0, extension * rng.uniform(0.9, 1.0), rng,
                     hold_s=rng.uniform(0.3, 1.5), speed_deg_s=speed)


def _abduction_adduction(path: _Path, rng: np.random.Generator, span_s: float,
                         elevations_deg: Sequence[float] = (90.0, 70.0, 90.0, 50.0),
                         holds_s: Sequence[float] = (1.0, 0.5, 4.0, 0.3)) -> None:
    """Abductions (θ = 0°) to about the given elevations (up to 5 % less), each held at the
    top for about its hold (±20 %)."""
    path.move(0.0, 0.0, 0.5)
    for elevation, hold in zip(elevations_deg, holds_s, strict=True):
        path.elevate(0.0, elevation * rng.uniform(0.95, 1.0), rng,
                     hold_s=hold * rng.uniform(0.8, 1.2),
                     speed_deg_s=rng.uniform(30.0, 90.0))
        path.hold(rng.uniform(0.3, 1.0))


def _azimuth_fixed(path: _Path, rng: np.random.Generator, span_s: float) -> None:
    for theta in (-40.0, 0.0, 30.0, 60.0, 90.0):
        path.move(theta, 0.0, 0.6)
        for _ in range(2):
            path.elevate(theta, rng.uniform(60.0, 90.0), rng, hold_s=rng.uniform(0.3, 2.5),
                         speed_deg_s=rng.uniform(30.0, 80.0))
            path.hold(rng.uniform(0.2, 0.8))


#: Elevations (deg) of the fixed-elevation sweeps of the plane of elevation, in the order
#: swept: where the plane is observable (at φ near 0 moving θ moves nothing, so a sweep there
#: would not be data). The extremes come first, so that the end of the movement, which a
#: within-recording split holds out for testing, stays inside the range its start covered
#: (no other movement reaches 120°).
SWEEP_ELEVATIONS_DEG = (30.0, 120.0, 50.0, 90.0, 70.0)


#: The planes of elevation (deg) a sweep at fixed elevation runs between.
SWEEP_PLANE_DEG = (-40.0, 90.0)


def _sweep_plane(path: _Path, rng: np.random.Generator, phi: float, speed_deg_s: float,
                 sweeps: int) -> None:
    """From hanging: raise the arm in the frontal plane (θ = 0) to ``phi``, sweep the plane
    of elevation ``sweeps`` times over :data:`SWEEP_PLANE_DEG` and back, return and lower."""
    path.move(0.0, 0.0, 1.0)  # the plane turns while the arm hangs
    path.move_at(0.0, phi, 45.0)
    for _ in range(sweeps):
        path.move_at(SWEEP_PLANE_DEG[0], phi, speed_deg_s)
        path.hold(rng.uniform(0.2, 1.5))
        path.move_at(SWEEP_PLANE_DEG[1], phi, speed_deg_s)
        path.hold(rng.uniform(0.2, 1.5))
    path.move_at(0.0, phi, speed_deg_s)
    path.move_at(0.0, 0.0, 45.0)
    path.hold(rng.uniform(0.3, 1.0))


def _elevation_fixed(path: _Path, rng: np.random.Generator, span_s: float) -> None:
    for phi in SWEEP_ELEVATIONS_DEG:
        _sweep_plane(path, rng, phi, rng.uniform(35.0, 80.0), sweeps=2)


#: Where random reaching aims: planes of elevation θ and elevations φ, degrees.
RANDOM_THETA_DEG = (-40.0, 90.0)
RANDOM_PHI_DEG = (0.0, 90.0)


def _random_movements(path: _Path, rng: np.random.Generator, span_s: float,
                      speed_deg_s: tuple[float, float] = (30.0, 100.0),
                      hold_s: tuple[float, float] = (0.3, 4.0),
                      reserve_s: float = 3.0) -> None:
    """Random targets at random mean speeds in ``speed_deg_s``, about a third of them held
    for a time in ``hold_s``, until ``span_s`` − ``reserve_s`` is filled; ends lowering the
    arm."""
    first = len(path.durations)
    while sum(path.durations[first:]) < span_s - reserve_s:
        path.move_at(rng.uniform(*RANDOM_THETA_DEG), rng.uniform(*RANDOM_PHI_DEG),
                     rng.uniform(*speed_deg_s))
        if rng.random() < 0.35:
            path.hold(rng.uniform(*hold_s))
    path.move_at(path.poses[-1][0], 0.0, 60.0)


_PAPER_BUILDERS = {
    "flexion_extension": _flexion_extension,
    "abduction_adduction": _abduction_adduction,
    "azimuth_fixed_elevation_varied": _azimuth_fixed,
    "elevation_fixed_azimuth_varied": _elevation_fixed,
    "random": _random_movements,
}


Builder = Callable[[_Path, np.random.Generator, float], None]


def _assemble(movements: Sequence[tuple[str, float, Builder]], rng: np.random.Generator,
              start: tuple[float, float], source: str) -> Trajectory:
    """Movements one after another, each (label, span in s, builder) time-scaled to fill
    exactly its span and labelled with it; ψ = 0."""
    path = _Path(*start)
    durations: list[float] = []
    segments = []
    end = 0.0
    for label, span, build in movements:
        first = len(path.durations)
        build(path, rng, span)
        steps = np.asarray(path.durations[first:])
        durations.extend((steps * (span / steps.sum())).tolist())
        segments.append(Segment(label, end, end + span))
        end += span
    knot_t = np.concatenate([[0.0], np.cumsum(durations)])
    knot_t[-1] = end  # exact end despite rounding in the cumulative sum
    deg = np.column_stack([np.asarray(path.poses), np.zeros(len(path.poses))])
    return Trajectory(knot_t, deg, "minimum_jerk", end, segments, source=source)


def paper_protocol(seed: int) -> Trajectory:
    """The Table III protocol, seeded; each movement spans exactly its frame count at 120 Hz.

    Each movement starts and ends with the arm hanging (φ = 0; the plane of elevation changes
    only while it hangs) and its steps are time-scaled to fill frames / 120 s; ψ = 0.
    """
    rng = np.random.default_rng(np.random.SeedSequence(int(seed)))
    movements = [(label, frames / MOCAP_RATE_HZ, _PAPER_BUILDERS[label])
                 for label, frames in PAPER_MOVEMENT_FRAMES.items()]
    return _assemble(movements, rng, (90.0, 0.0), f"paper_protocol seed={int(seed)}")


#: The calibration protocol's movements, in order: label → (span in s of the full version, 60 s
#: with two repetitions of each movement; span of the short version, 36 s with one). A
#: recording of ``duration_s`` uses the full version from :data:`CALIBRATION_FULL_FROM_S` on,
#: the short one below, with every span (and so every speed and hold) scaled to fill it.
CALIBRATION_MOVEMENT_S: dict[str, tuple[float, float]] = {
    "stand_start": (3.0, 2.0),
    "flexion_extension": (16.0, 9.0),
    "abduction_adduction": (12.0, 7.0),
    "elevation_fixed_azimuth_varied": (14.0, 9.0),
    "random_slow": (7.0, 4.0),
    "random_fast": (5.0, 3.0),
    "stand_end": (3.0, 2.0),
}
#: Shortest and longest calibration recordings, s: beyond these the scaled speeds and holds
#: leave the range of the paper protocol's.
CALIBRATION_DURATION_S = (30.0, 120.0)
#: Recordings at least this long (s) get the full version (two repetitions of each movement).
CALIBRATION_FULL_FROM_S = 50.0
#: The elevation (deg) of the calibration protocol's plane sweeps is drawn from this range.
CALIBRATION_SWEEP_ELEVATION_DEG = (60.0, 90.0)


def _stand(path: _Path, rng: np.random.Generator, span_s: float) -> None:
    path.hold(span_s)


def _calibration_builders(reps: int) -> dict[str, Builder]:
    """The calibration movements with ``reps`` (1 or 2) repetitions each."""

    def sweeps(path: _Path, rng: np.random.Generator, span_s: float) -> None:
        phi = rng.uniform(*CALIBRATION_SWEEP_ELEVATION_DEG)
        _sweep_plane(path, rng, phi, rng.uniform(45.0, 80.0), sweeps=reps)

    return {
        "stand_start": _stand,
        "flexion_extension": partial(_flexion_extension, flexion_deg=(120.0, 90.0)[:reps],
                                     extension_deg=(45.0, 30.0)[:reps]),
        "abduction_adduction": partial(_abduction_adduction,
                                       elevations_deg=(120.0, 90.0)[:reps],
                                       holds_s=(0.5, 3.0) if reps == 2 else (2.5,)),
        "elevation_fixed_azimuth_varied": sweeps,
        "random_slow": partial(_random_movements, speed_deg_s=(30.0, 50.0), hold_s=(0.5, 2.0),
                               reserve_s=2.0),
        "random_fast": partial(_random_movements, speed_deg_s=(70.0, 100.0),
                               hold_s=(0.2, 0.8), reserve_s=1.5),
        "stand_end": _stand,
    }


def calibration_protocol(seed: int, duration_s: float = 60.0) -> Trajectory:
    """What a wearer does for a calibration recording (docs/suit-model.md, "Calibration
    protocol"): the usual movements, briefly, seeded, ``duration_s`` long (30..120 s).

    Standing with the arm hanging; flexion to ≈ 120° and 90° with extensions to ≈ 45° and
    30°; abduction to ≈ 120° and to ≈ 90° with a ≈ 3 s hold; two sweeps of the plane of
    elevation between −40° and 90° at one elevation of 60–90°; random reaching, slow
    (30–50°/s) then fast (70–100°/s), within −40° ≤ θ ≤ 90°, 0 ≤ φ ≤ 90°; standing again.
    Below :data:`CALIBRATION_FULL_FROM_S` one repetition of each (flexion ≈ 120°, extension
    ≈ 45°, abduction ≈ 120° held ≈ 2.5 s, one sweep). Every movement starts and ends with the
    arm hanging; planes and elevations stay within what :func:`paper_protocol` covers. Spans
    are :data:`CALIBRATION_MOVEMENT_S` scaled to ``duration_s``, each movement time-scaled to
    fill its span exactly; ψ = 0.
    """
    low, high = CALIBRATION_DURATION_S
    if not low <= duration_s <= high:  # also refuses NaN
        raise ValueError(f"calibration protocol duration must be {low:g}..{high:g} s, "
                         f"got {duration_s!r}")
    full = duration_s >= CALIBRATION_FULL_FROM_S
    spans = {label: pair[0 if full else 1] for label, pair in CALIBRATION_MOVEMENT_S.items()}
    builders = _calibration_builders(2 if full else 1)
    scale = duration_s / sum(spans.values())
    movements = [(label, span * scale, builders[label]) for label, span in spans.items()]
    rng = keyed_rng(int(seed), "calibration_protocol", 0)
    return _assemble(movements, rng, (0.0, 0.0),
                     f"calibration_protocol seed={int(seed)} duration_s={duration_s:g}")


def mot_trajectory(paths: Sequence[str | Path], bridge_s: float = 1.0) -> Trajectory:
    """Real shoulder motion from OpenSim ``.mot`` files, concatenated in the given order.

    Uses ``plane_elv`` → θ and ``shoulder_elv`` → φ as stored, and the MoBL-ARMS axial
    rotation ψ = ``axial_rot`` + ``plane_elv`` (the coupled convention of
    :func:`exohil.kinematics.shoulder.isb_to_ms`, treating the model's Y-X-Y shoulder angles as
    ISB angles) minus its value at the trial's first frame (the suit is donned in that pose).
    In the thoracoscapular model these angles are glenohumeral, not humerothoracic (see the
    data set's SOURCE.md); they are used as if humerothoracic. Consecutive trials are joined by
    a ``bridge_s`` gap that the shape-preserving interpolation fills smoothly.
    """
    if not paths:
        raise ValueError("mot_trajectory needs at least one .mot file")
    times, angles, segments = [], [], []
    start = 0.0
    for path in paths:
        mot = read_mot(path)
        missing = [c for c in ("plane_elv", "shoulder_elv", "axial_rot") if c not in mot.columns]
        if missing:
            raise ValueError(f"{path}: missing column(s) {', '.join(missing)}")
        to_rad = np.deg2rad if mot.in_degrees else np.asarray
        isb = np.column_stack([to_rad(mot.columns["plane_elv"]),
                               -to_rad(mot.columns["shoulder_elv"]),
                               to_rad(mot.columns["axial_rot"])])
        ms = np.rad2deg(isb_to_ms(isb))
        ms[:, 2] = np.rad2deg(np.unwrap(np.deg2rad(ms[:, 2])))
        ms[:, 2] -= ms[0, 2]
        t = mot.time - mot.time[0]
        times.append(start + t)
        angles.append(ms)
        segments.append(Segment(Path(path).stem, start, start + float(t[-1])))
        start += float(t[-1]) + bridge_s
    knot_t = np.concatenate(times)
    return Trajectory(knot_t, np.concatenate(angles), "pchip", float(knot_t[-1]), segments,
                      source="mot:" + ",".join(Path(p).name for p in paths))


def replayed_motion(rec: Recording, joint: str, angles: Sequence[str], name: str
                    ) -> tuple[np.ndarray, np.ndarray, list[Segment]]:
    """The motion capture of ``rec``'s ``joint`` to replay, on ``rec``'s clock: the times
    (M,) of its samples where every one of ``angles`` is finite (s), those angles (M, A) in
    degrees in the order given, and ``rec``'s segments cut to their span (empty ones
    dropped). ValueError (naming ``name``) without such a stream, or with fewer than two
    samples."""
    stream = rec.mocap.get(joint)
    if stream is None:
        held = ", ".join(f"/mocap/{j}" for j in rec.mocap) or "no motion capture"
        raise ValueError(f"{name}: no /mocap/{joint} stream to replay (it holds {held})")
    missing = [a for a in angles if a not in stream.names]
    if missing:
        raise ValueError(f"{name}: /mocap/{joint} has no {', '.join(missing)} (it has "
                         f"{', '.join(stream.names)})")
    values = stream.angles[:, [stream.names.index(a) for a in angles]]
    kept = np.all(np.isfinite(values), axis=1) & np.isfinite(stream.t)
    t = stream.t[kept]
    if t.shape[0] < 2 or not t[-1] > t[0]:
        raise ValueError(f"{name}: /mocap/{joint} holds {t.shape[0]} sample(s) with every "
                         f"one of {', '.join(angles)} finite; a replay needs two or more "
                         "spanning some time")
    first, last = float(t[0]), float(t[-1])
    segments = [Segment(s.name, max(s.t0, first), min(s.t1, last))
                for s in rec.segments if s.t1 > first and s.t0 < last]
    return t, values[kept], segments


def replay_trajectory(rec: Recording, name: str) -> Trajectory:
    """The shoulder motion captured in ``rec`` (``/mocap/shoulder``: θ, φ, ψ, degrees) as a
    trajectory from 0 s at its first sample, through every sample (shape-preserving, so
    across a dropout too), with ``rec``'s segments on that clock; ``source`` names ``name``
    and where on its clock the replay starts. ValueError where ``rec`` holds no such
    motion."""
    t, angles, segments = replayed_motion(rec, "shoulder", ANGLE_NAMES, name)
    t0 = float(t[0])
    return Trajectory(t - t0, angles, "pchip", float(t[-1] - t0),
                      [Segment(s.name, s.t0 - t0, s.t1 - t0) for s in segments],
                      source=f"replay:{name} from {t0:.6g} s")
