"""Recordings with exactly one hidden effect, to test that the workflow names it.

Each case: a seeded random shoulder movement (minimum-jerk moves at 20–120 °/s, holds of
0.3–5 s, partial reversals; or real motion from OpenSim ``.mot`` files), a perturbed suit
geometry (tendon anchors moved by up to 15 mm, cap radius 45–65 mm, per-sensor gains 0.7–1.4
and offsets, 3–5 tendons), one effect (:func:`apply_hidden_effect`) and always white noise
(0.15 mm). Two families per effect: ``lib``
uses :mod:`exohil.emulators.effects`; ``alt`` is written here independently with another
model family (backlash play or Bouc–Wen hysteresis, two-time-constant creep, tanh saturation,
pure delay or second-order lag, exponential warm-up or sinusoidal drift), so the tests do not
only check the workflow against its own equations. A third family, ``other``, is kept out of
the suite's default and used to probe generality (docs/discrepancy-results.md): a Preisach ensemble
of relays, creep with a power-law memory, a stop at the *upper* end that approaches its
asymptote exponentially, a low-pass behind a transport delay, and a random-walk offset.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, replace

import numpy as np
from scipy.signal import fftconvolve, lfilter

from exohil.emulators.discrepancy.workers import parallel_map
from exohil.emulators.discrepancy.workflow import run
from exohil.emulators.effects import Creep, Drift, Hysteresis, Lag, Noise, Saturation, Signal
from exohil.emulators.protocols import ANGLE_NAMES, MOCAP_RATE_HZ, Trajectory, mot_trajectory
from exohil.emulators.suit_geometry import SuitGeometry, Tendon
from exohil.emulators.suit_profile import load_default_profile
from exohil.formats.recording import AngleStream, Recording, SensorStream

SENSOR_RATE_HZ = 250.0
NOISE_MM = 0.15
KINDS = ("clean", "hysteresis", "creep", "saturation", "lag", "drift")
FAMILIES = ("lib", "alt", "other")


def random_trajectory(seed: int, duration_s: float, axial_deg: float = 0.0) -> Trajectory:
    """Random reaching: targets in −40 ≤ θ ≤ 90°, 0 ≤ φ ≤ 95°, speeds 20–120 °/s, holds
    0.3–5 s, one in three elevations with a partial reversal on the way. With ``axial_deg``
    each move also turns the axial rotation ψ to a random value within ±``axial_deg``
    (drawn from a second stream, so θ and φ are those of ``axial_deg`` = 0)."""
    rng = np.random.default_rng(seed)
    t, poses = [0.0], [(0.0, 5.0)]
    while t[-1] < duration_s:
        theta, phi = rng.uniform(-40, 90), rng.uniform(0, 95)
        last = poses[-1]
        speed = rng.uniform(20, 120)
        if rng.random() < 0.33 and phi > last[1] + 30:
            mid = last[1] + (phi - last[1]) * rng.uniform(0.5, 0.8)
            back = mid - rng.uniform(8, 20)
            for target in ((theta, mid), (theta, back)):
                dist = max(abs(target[0] - poses[-1][0]), abs(target[1] - poses[-1][1]))
                t.append(t[-1] + max(0.4, dist / speed))
                poses.append(target)
        dist = max(abs(theta - poses[-1][0]), abs(phi - poses[-1][1]))
        t.append(t[-1] + max(0.4, dist / speed))
        poses.append((theta, phi))
        t.append(t[-1] + rng.uniform(0.3, 5.0))
        poses.append((theta, phi))
    psi = np.zeros(len(poses))
    if axial_deg:
        turns = np.random.default_rng([seed, 1]).uniform(-axial_deg, axial_deg, len(poses))
        for i in range(1, len(poses)):  # a hold keeps the rotation it arrived with
            psi[i] = psi[i - 1] if poses[i] == poses[i - 1] else turns[i]
    knots = np.column_stack([np.asarray(poses), psi])
    return Trajectory(knot_t=np.asarray(t), knot_deg=knots, interpolation="minimum_jerk",
                      duration_s=float(duration_s), source=f"hidden random seed={seed}")


def random_geometry(seed: int) -> tuple[SuitGeometry, np.ndarray, np.ndarray]:
    """A perturbed default suit: 3–5 tendons, anchors moved by ≤ 15 mm, cap 45–65 mm.

    Returns the geometry, per-sensor gains and offsets (mm) applied to its lengths.
    """
    rng = np.random.default_rng(seed + 7919)
    base = load_default_profile().geometry
    n = int(rng.integers(3, 6))
    picks = [base.tendons[i % len(base.tendons)] for i in rng.permutation(max(n, 4))[:n]]
    radius = float(rng.uniform(45, 65))
    tendons = []
    for k, tendon in enumerate(picks):
        thorax = tendon.thorax_points_mm + rng.uniform(-15, 15, tendon.thorax_points_mm.shape)
        humerus = tendon.humerus_points_mm + rng.uniform(-15, 15, tendon.humerus_points_mm.shape)
        # keep arm points outside the cap whatever the orientation
        norms = np.linalg.norm(humerus, axis=1, keepdims=True)
        humerus = np.where(norms < radius + 10, humerus * (radius + 10) / norms, humerus)
        tendons.append(Tendon(name=f"T{k}", thorax_points_mm=thorax, humerus_points_mm=humerus))
    geometry = SuitGeometry(cap_centre_mm=np.zeros(3), cap_radius_mm=radius,
                            tendons=tuple(tendons))
    geometry.validate()
    return geometry, rng.uniform(0.7, 1.4, n), rng.uniform(-200, 200, n)


def _backlash(x: np.ndarray, half_width: np.ndarray) -> np.ndarray:
    """One play operator per sensor (a rate-independent backlash loop), centred."""
    out = np.empty_like(x)
    out[0] = x[0]
    for i in range(1, x.shape[0]):
        out[i] = np.minimum(np.maximum(out[i - 1], x[i] - half_width), x[i] + half_width)
    return out


def _bouc_wen(x: np.ndarray, amplitude: np.ndarray, travel: np.ndarray) -> np.ndarray:
    """Bouc–Wen hysteretic state h (mm): dh = (dx − |dx|·h/|h|·|h/A| ...) in its common
    first-order form dh = (dx − β|dx|h − γ dx|h|)/…; here β = γ = 1/(2A) scaled so the loop
    half-width is ``amplitude`` and it saturates after about ``travel`` of input."""
    out = np.zeros_like(x)
    h = np.zeros(x.shape[1])
    k = amplitude / travel
    for i in range(1, x.shape[0]):
        dx = x[i] - x[i - 1]
        h = h + k * dx - (np.abs(dx) * h + dx * np.abs(h)) / (2.0 * travel)
        out[i] = h
    return out


def _preisach(x: np.ndarray, width: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """x plus a Preisach ensemble per sensor: 60 relays centred over the 5–95 % range of the
    reading, each switching ±(1–5 % of that range) from its centre; the ensemble's mean
    state, −1…1, scaled to ± ``width`` (mm)."""
    out = x.copy()
    for j in range(x.shape[1]):
        lo, hi = np.quantile(x[:, j], [0.05, 0.95])
        centre = rng.uniform(lo, hi, 60)
        half = rng.uniform(0.01, 0.05, 60) * (hi - lo)
        up, down = centre + half, centre - half
        state = -np.ones(60)
        for i, v in enumerate(x[:, j]):
            state = np.where(v > up, 1.0, np.where(v < down, -1.0, state))
            out[i, j] += width[j] * state.mean()
    return out


def _power_law_creep(x: np.ndarray, gain: np.ndarray, rate_hz: float) -> np.ndarray:
    """x plus ``gain`` times the stretch since the first frame remembered with weights
    ∝ t^−0.7 over the last 60 s (a spectrum of relaxation times, not one or two)."""
    kernel = np.arange(1, int(60 * rate_hz)) ** -0.7
    kernel /= kernel.sum()
    stretch = x - x[0]
    memory = np.column_stack([fftconvolve(stretch[:, j], np.r_[0.0, kernel])[: len(x)]
                              for j in range(x.shape[1])])
    return x + gain * memory


def _other_effect(kind: str, magnitude: float, x: np.ndarray, t: np.ndarray,
                  rng: np.random.Generator) -> np.ndarray:
    """The ``other`` family's version of ``kind`` applied to the ideal readings x (N, S)."""
    s = x.shape[1]
    if kind == "hysteresis":
        return _preisach(x, magnitude * np.asarray(rng.uniform(1.5, 2.5, s)), rng)
    if kind == "creep":
        gain = magnitude * rng.uniform(0.05, 0.08, s) * rng.choice([-1.0, 1.0], s)
        return _power_law_creep(x, gain, SENSOR_RATE_HZ)
    if kind == "saturation":  # beyond the knee: knee + r·(1 − exp(−(x − knee)/r))
        knee = np.quantile(x, 1.0 - 0.15 * magnitude, axis=0)
        reach = 0.4 * (x.max(axis=0) - knee)
        return np.where(x > knee, knee + reach * (1.0 - np.exp(-(x - knee) / reach)), x)
    if kind == "lag":  # a 30 ms low-pass, then 20 ms of transport delay (× magnitude)
        a = 1.0 - np.exp(-1.0 / (SENSOR_RATE_HZ * 0.03 * magnitude))
        smooth = lfilter([a], [1.0, a - 1.0], x - x[0], axis=0) + x[0]
        return np.column_stack([np.interp(t - 0.02 * magnitude, t, smooth[:, j])
                                for j in range(s)])
    if kind == "drift":  # a random walk, 0.25 mm/√s (× magnitude)
        steps = rng.normal(0.0, 0.25 * magnitude / np.sqrt(SENSOR_RATE_HZ), x.shape)
        return x + np.cumsum(steps, axis=0)
    raise ValueError(f"unknown hidden effect {kind!r}")


def apply_hidden_effect(kind: str, family: str, magnitude: float, signal: Signal,
                        rng: np.random.Generator) -> Signal:
    """One hidden effect. ``magnitude`` ∈ {1, 2}: small and large. Small is chosen so the
    effect's residual after calibrating the static map is about twice the 0.15 mm noise:
    a held-out gap can only halve when the effect stands that far above the noise floor."""
    x, t = signal.values, signal.t
    s = x.shape[1]
    if family not in FAMILIES:
        raise ValueError(f"unknown family {family!r}; known: {', '.join(FAMILIES)}")
    if family == "other" and kind != "clean":
        return signal.with_values(_other_effect(kind, magnitude, x, t, rng))
    if kind == "hysteresis":
        width = magnitude * np.asarray(rng.uniform(1.5, 2.5, s))  # full loop width, mm
        if family == "lib":
            return Hysteresis(width_mm=width.tolist(), span_mm=float(rng.uniform(8, 25)),
                              operators=4).apply(signal, rng)
        if rng.random() < 0.5:
            return signal.with_values(_backlash(x, width / 2.0))
        return signal.with_values(x + _bouc_wen(x, width / 2.0,
                                                np.asarray(rng.uniform(5, 15, s))))
    if kind == "lag":
        tau = magnitude * rng.uniform(0.02, 0.035)
        if family == "lib":
            return Lag(tau_s=tau).apply(signal, rng)
        if rng.random() < 0.5:  # pure transport delay
            return signal.with_values(np.column_stack(
                [np.interp(t - tau, t, x[:, j]) for j in range(s)]))
        out = x.copy()  # second-order: two first-order stages of tau/2 (explicit recursion)
        for _ in range(2):
            a = 1.0 - np.exp(-(1.0 / SENSOR_RATE_HZ) / (tau / 2.0))
            y = out.copy()
            for i in range(1, y.shape[0]):
                y[i] = y[i - 1] + a * (out[i] - y[i - 1])
            out = y
        return signal.with_values(out)
    if kind == "creep":
        gain = magnitude * rng.uniform(0.05, 0.08) * rng.choice([-1.0, 1.0], s)
        if family == "lib":
            return Creep(gain=gain.tolist(), tau_build_s=float(rng.uniform(5, 20)),
                         tau_recover_s=float(rng.uniform(15, 40))).apply(signal, rng)
        out = x.copy()  # two Kelvin-Voigt elements: fast and slow, half the gain each
        stretch = x - x[0]
        for tau in (rng.uniform(1.5, 4), rng.uniform(20, 60)):
            a = 1.0 - np.exp(-(1.0 / SENSOR_RATE_HZ) / tau)
            c = np.zeros(s)
            for i in range(x.shape[0]):
                c = c + a * (0.5 * gain * stretch[i] - c)
                out[i] += c
        return signal.with_values(out)
    if kind == "saturation":
        frac = 0.1 * magnitude
        lo = np.quantile(x, frac, axis=0)
        if family == "lib":
            return Saturation(lower_mm=lo.tolist()).apply(signal, rng)
        soft = 0.3 * (lo - x.min(axis=0)) + 1e-9  # tanh compression below the knee
        below = x < lo
        out = np.where(below, lo - soft * np.tanh((lo - x) / soft), x)
        return signal.with_values(out)
    if kind == "drift":
        duration = t[-1] - t[0]
        total = magnitude * rng.uniform(1.5, 3.0, s) * rng.choice([-1.0, 1.0], s)  # mm
        if family == "lib":
            return Drift(rate_mm_per_s=(total / duration).tolist(),
                         walk_mm_per_sqrt_s=0.02).apply(signal, rng)
        if rng.random() < 0.5:  # warm-up: exponential approach
            tau = duration * rng.uniform(0.2, 0.5)
            return signal.with_values(x + total * (1 - np.exp(-(t - t[0]) / tau))[:, None])
        phase = rng.uniform(0, 2 * np.pi)
        wave = np.sin(2 * np.pi * (t - t[0]) / (2.0 * duration) + phase) - np.sin(phase)
        return signal.with_values(x + total * wave[:, None])
    if kind == "clean":
        return signal
    raise ValueError(f"unknown hidden effect {kind!r}")


@dataclass(frozen=True)
class Case:
    """One hidden-effect case: the effect (``clean`` for none), its family and magnitude.

    ``motion``: OpenSim ``.mot`` files of real shoulder motion (:func:`mot_trajectory`,
    joined in order) to drive the suit instead of the seeded random movement; the
    recording then lasts as long as they do and ``duration_s`` is not used.
    """

    kind: str
    family: str
    magnitude: int
    seed: int
    duration_s: float = 60.0
    motion: tuple[str, ...] = ()

    @property
    def label(self) -> str:
        return f"{self.kind}/{self.family}/m{self.magnitude}/s{self.seed}"


def suit_lengths(trajectory: Trajectory, geometry: SuitGeometry, gains: np.ndarray,
                 offsets: np.ndarray) -> Signal:
    """The suit's ideal sensor signal (mm) at 250 Hz along ``trajectory``: path lengths times
    ``gains`` plus ``offsets``, per sensor."""
    t = trajectory.frame_times(SENSOR_RATE_HZ)
    ang = np.deg2rad(trajectory.sample(t))
    lengths = geometry.path_lengths(ang[:, 0], ang[:, 1], ang[:, 2]) * gains + offsets
    return Signal.from_values(t, lengths)


def suit_recording(trajectory: Trajectory, geometry: SuitGeometry, signal: Signal,
                   metadata: dict[str, str]) -> Recording:
    """A recording of ``signal`` (every frame received) with ``trajectory``'s exact angles as
    the shoulder mocap at 120 Hz."""
    t_mocap = trajectory.frame_times(MOCAP_RATE_HZ)
    mocap = AngleStream(t=t_mocap, names=ANGLE_NAMES, angles=trajectory.sample(t_mocap))
    return Recording(
        sensor_names=geometry.sensor_names,
        sensors=SensorStream(seq=np.arange(signal.t.shape[0]), t=signal.t,
                             values=signal.values),
        mocap={"shoulder": mocap}, sensor_units="mm", sensor_rate_hz=SENSOR_RATE_HZ,
        mocap_rate_hz=MOCAP_RATE_HZ, metadata=metadata)


def make_recording(case: Case) -> Recording:
    """The recording of ``case`` (sensors at 250 Hz, mocap at 120 Hz, exact angles)."""
    trajectory = (mot_trajectory(case.motion) if case.motion
                  else random_trajectory(case.seed, case.duration_s))
    geometry, gains, offsets = random_geometry(case.seed)
    rng = np.random.default_rng([case.seed, KINDS.index(case.kind), case.magnitude,
                                 FAMILIES.index(case.family)])
    signal = apply_hidden_effect(case.kind, case.family, case.magnitude,
                                 suit_lengths(trajectory, geometry, gains, offsets), rng)
    signal = Noise(sigma_mm=NOISE_MM).apply(signal, rng)
    return suit_recording(trajectory, geometry, signal,
                          {"generator": "exohil.emulators.discrepancy.hidden",
                           "case": case.label})


def angle_noise_recording(seed: int, noise_deg: float, duration_s: float = 90.0
                          ) -> Recording:
    """A clean suit (random geometry and movement of ``seed``, sensor noise ``NOISE_MM``)
    whose motion capture holds white noise of ``noise_deg`` (°, SD per sample) on every
    angle: a tracker's jitter, which the suit never felt. One seed draws the same sensor
    noise and the same angle noise pattern, scaled, at every ``noise_deg``."""
    trajectory = random_trajectory(seed, duration_s)
    geometry, gains, offsets = random_geometry(seed)
    rng = np.random.default_rng([seed, len(KINDS)])  # no hidden-effect case's stream
    signal = Noise(sigma_mm=NOISE_MM).apply(suit_lengths(trajectory, geometry, gains, offsets),
                                            rng)
    rec = suit_recording(trajectory, geometry, signal,
                         {"generator": "exohil.emulators.discrepancy.hidden",
                          "case": f"angle-noise/{noise_deg:g}deg/s{seed}"})
    stream = rec.mocap["shoulder"]
    jitter = noise_deg * rng.standard_normal(stream.angles.shape)
    return replace(rec, mocap={"shoulder": replace(stream, angles=stream.angles + jitter)})


def stamped_late(rec: Recording, late_s: float) -> Recording:
    """``rec`` with every motion-capture stream's times moved by ``late_s`` seconds: stamped
    late (the readings run ahead of it) where positive, early where negative. A clock
    offset between the two, which the workflow reads back (method step 2); the sensors and
    the angles are as they were."""
    return replace(rec, mocap={joint: replace(stream, t=stream.t + late_s)
                               for joint, stream in rec.mocap.items()})


def cases(seeds: range, magnitudes: tuple[int, ...] = (1, 2), duration_s: float = 60.0,
          families: tuple[str, ...] = ("lib", "alt"), motion: tuple[str, ...] = ()
          ) -> list[Case]:
    """Every effect × family × magnitude × seed, plus one clean control per (seed, magnitude)
    and family so that clean cases are as many as one effect's (``motion``: see
    :class:`Case`)."""
    out = []
    for seed in seeds:
        for magnitude in magnitudes:
            for family in families:
                for kind in KINDS:
                    out.append(Case(kind, family, magnitude, seed, duration_s, motion))
    return out


def first_effect(summary: dict) -> str:
    """The first named effect, or ``clean`` when nothing was named."""
    return summary["effects"][0] if summary["effects"] else "clean"



def run_case(case: Case) -> dict:
    """The workflow's ``discrepancy.json`` summary on ``case``'s recording."""
    return run(make_recording(case), case.label).summary


def run_cases(selected: Iterable[Case], workers: int | None = None
              ) -> Iterator[tuple[Case, dict]]:
    """``(case, summary)`` for every case, in order, as each completes (:func:`parallel_map`)."""
    return parallel_map(run_case, selected, workers)
