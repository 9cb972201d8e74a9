"""The calibrated suit model: a static map from the angles to each sensor plus effect terms.

Every model here is linear in its coefficients once a few shape parameters (time constants,
delays, knots) are fixed, so fitting is a ridge least-squares solve per sensor and blocked
cross-validation costs one Gram matrix per block (fold fit = total − held-out block;
``folds.py``). The signal operators of the effect terms are in ``filters.py``.

For sensor j with static prediction ŝⱼ (a polynomial of the angles, fitted first and then
held fixed as the *input* of the history-dependent terms) the model is

    yⱼ = stops( Lag( B(angles)·β + H(ŝⱼ)·w + C(ŝⱼ)·c ) + D(t)·d , lowerⱼ, upperⱼ )

* B: Legendre-product polynomial of the normalised angles (total degree chosen by held-out
  error): geometry, routing, gains, offsets and units in one calibrated map; for an arm
  direction it may instead be a cubic plus compact functions on the sphere (``local``),
  and with axial rotation it ends with the lengths of straight tendon runs.
* H (``hysteresis``): Prandtl–Ishlinskii basis, ŝ − play_r(ŝ) for play operators of thresholds
  r spread over the sensor's range; any weighted sum is a rate-independent loop. A named loop
  may also take powers of each play's output (:func:`hysteresis_columns`): a loop whose
  width changes with the level, as a Preisach operator's does. Or the plays act on each
  joint angle instead, weighted by ŝ's slope in it (:func:`angle_play_columns`): a loop in
  the pose, as a sleeve that slips on the limb makes, which ŝ need not show.
* C (``creep``): ŝ low-passed with time constants of seconds to tens of seconds (slow
  relaxation toward the current stretch), an asymmetric build/recover state, or states
  that flow toward the stretch only while the joint holds still and recover while it
  moves (:func:`creep_hold_columns`).
* Lag (``lag``): first-order low-pass (time constant τ), a pure delay, or the low-pass
  followed by a delay, applied to every pose-driven column, so the fitted map is the map of
  the lagged response; or a rate limit (a slew-rate limit: the reading follows at most at
  Lⱼ units/s), the column R_Lⱼ(ŝⱼ) − ŝⱼ, zero except while the pose moves faster than the
  sensor can follow and until it has caught up.
* D (``drift``): Legendre polynomials of time: a slow offset independent of pose (degree 1–3
  while candidates are compared; a named drift may take a higher degree, at most one per
  5 s of recording, chosen on held-out blocks).
* Stops (``saturation``): at an end of its range the sensor stops following the pose: a hard
  stop (it sits on a plateau while the joint moves; the map is fitted through the plateau as
  a censored reading, which bounds it there, and clipped at its level) or a soft knee (the
  reading bends toward an asymptote, a tanh or an exponential approach; the map is fitted
  through the knee by Gauss–Newton). Which, and where, is chosen on held-out blocks
  (``stops.py``).
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.signal import savgol_filter

from exohil.emulators.discrepancy.data import N_BLOCKS, Trial, true_runs
from exohil.emulators.discrepancy.filters import apply_lag, low_pass, play, rate_limit
from exohil.emulators.discrepancy.folds import (
    FIT_RATE_HZ,
    RIDGE,
    Design,
    Ridge,
    block_mse,
    fit_coefs,
    fold_coefs,
    fold_products,
    reduce,
)
from exohil.emulators.discrepancy.stops import (
    NO_STOPS,
    Stops,
    choose_stops,
    fit_with_stops,
)
from exohil.emulators.discrepancy.workers import forked_map
from exohil.emulators.effects import Creep, Signal
from exohil.kinematics import ms_to_matrix

#: Coverage radius in the static map's input space (unit arm vector or scaled angles).
COVER_RADIUS = 0.1
#: Below this angular speed (deg/s, :func:`joint_speed`) the joint is holding still.
STILL_DEG_S = 2.0
#: A joint still by ``STILL_DEG_S`` stays still until its speed passes this, deg/s.
MOVING_DEG_S = 2.0 * STILL_DEG_S
#: The joint's speed is the slope of a straight line fitted over this window, s. Over
#: 0.5 s, 0.1° of white angle noise sampled at 100 Hz moves each rate by about 0.1 °/s
#: (a slope's error σ·√(12 / (n·W²)), n samples in W), well below ``STILL_DEG_S``; a
#: frame-to-frame difference after a 0.05 s low-pass moved it by several °/s and split
#: every hold of a real mocap into pieces shorter than a second.
SPEED_WINDOW_S = 0.5
#: Play-operator thresholds as fractions of the sensor's range (p1–p99).
PLAY_FRACTIONS = (0.005, 0.015, 0.04, 0.1, 0.25)
#: The step of the central differences that give ŝ's slope in each angle, degrees
#: (:func:`angle_play_columns`): small against the bends of a map over tens of degrees,
#: far above rounding.
STATIC_SLOPE_STEP_DEG = 0.5
#: The static map's local basis (offered beside the polynomials for an arm direction): a
#: Fibonacci lattice of this many centres on the unit sphere, of which those within
#: ``LOCAL_KEEP`` spacings of some recorded direction are kept, each the centre of a compact
#: Wendland function reaching ``LOCAL_REACH`` spacings (chord distance), beside a
#: polynomial of degree ``LOCAL_DEGREE``. A polynomial on the sphere follows slow,
#: direction-wide structure; where a tendon starts or stops wrapping, its length bends over
#: a few tens of degrees, which a local function follows without an oscillating high degree.
LOCAL_CENTRES = 400
LOCAL_KEEP = 2.5
LOCAL_REACH = 3.75
LOCAL_DEGREE = 3
#: Frames whose local functions are formed at once (:func:`local_terms`).
LOCAL_ROWS = 4096
#: Ridges of the local functions tried (chosen on the held-out blocks), each relative to the
#: functions' mean energy in the fold and the same for all of them: a function that only a
#: few fitted frames reach is held near zero instead of given whatever coefficient those
#: frames ask for, which a ridge relative to its own energy would allow.
LOCAL_RIDGES = (1e-5, 1e-4, 1e-3)
#: Relative ridges of the polynomial beside the local functions.
LOCAL_STATIC_RIDGES = (1e-10,)
#: Relative ridges of the static map tried with each degree (chosen on the held-out blocks):
#: the Legendre products of a unit arm vector are nearly collinear over the poses a recording
#: visits, so even a small ridge biases the map between poses and a smaller one can interpolate
#: better (or, at a higher degree, worse).
STATIC_RIDGES = (1e-10, 1e-9, 1e-8, RIDGE)
#: Lags whose lagged columns are kept (:func:`lagged_term`): the model's and the one being
#: tried against it.
KEPT_LAGS = 2


@dataclass(frozen=True)
class Spec:
    """Which effect terms a model has and their shape parameters.

    Attributes:
        degree: total degree of the static polynomial.
        local: the static map also has the local basis (:func:`local_terms`).
        local_ridge: the local functions' ridge (:class:`~.folds.Ridge`).
        hysteresis: play-operator term on.
        hysteresis_degree: the degree of the hysteresis term in each play operator's output
            (:func:`hysteresis_columns`): 1, a Prandtl–Ishlinskii loop of the same width at
            every level; higher, a loop whose width changes with the level.
        hysteresis_angles: the play operators act on the joint's angles, not on ŝ
            (:func:`angle_play_columns`; degree 1 only).
        creep_tau_s: time constants of the creep low-passes, s (empty = none).
        creep_quadratic: each low-pass also of (ŝ − centre)², a driver that is not
            proportional to the stretch (a fabric whose load stiffens, or eases, with it).
        creep_asym_s: (build, recover) time constants of an asymmetric creep state, s
            (empty = none): builds while the stretch grows, recovers more slowly.
        creep_hold_s: (grow, recover) time constants of a creep that flows only while the
            joint holds still and recovers while it moves, s (empty = none;
            :func:`creep_hold_columns`).
        lag_kind: "" (none), "first_order", "delay", "first_order_delay" (a low-pass
            followed by a delay) or "rate_limit".
        lag_s: the lag's time constant (first order, with or without a delay) or delay, s.
        lag_delay_s: the delay after the low-pass of ``first_order_delay``, s.
        lag_rates: per sensor, the most a ``rate_limit`` reading changes per second, sensor
            units/s.
        lag_sensors: the sensors (columns) a low-pass or delay acts on, ascending; empty:
            every sensor. One string potentiometer's filter, or one tendon's sticky sheath,
            lags that sensor alone.
        drift_degree: how many functions of time the drift has (0 = no drift): the degree
            of a Legendre polynomial of time or, with ``drift_piecewise``, the intervals of a
            piecewise-linear function of time (evenly spaced knots).
        drift_piecewise: the drift is piecewise linear (it follows a step or a wandering
            offset locally, where a polynomial spreads its error over the whole recording).
        saturation: stops at the ends of the sensors' ranges (hard or soft, :class:`~.stops.Stops`).
        stops: the stops per sensor, once chosen (empty: choose them in every fit).
        output_curve: a smooth transfer curve per sensor (:func:`curve_columns`). Not an
            effect and never kept in a model: the static alternative a stop must beat to be
            named (a reading that bends over its whole range is calibration, not a stop).
        ridge: relative ridge of the static map's columns.
    """

    degree: int = 3
    local: bool = False
    local_ridge: float = LOCAL_RIDGES[0]
    hysteresis: bool = False
    hysteresis_degree: int = 1
    hysteresis_angles: bool = False
    creep_tau_s: tuple[float, ...] = ()
    creep_quadratic: bool = False
    creep_asym_s: tuple[float, ...] = ()
    creep_hold_s: tuple[float, ...] = ()
    lag_kind: str = ""
    lag_s: float = 0.0
    lag_delay_s: float = 0.0
    lag_rates: tuple[float, ...] = ()
    lag_sensors: tuple[int, ...] = ()
    drift_degree: int = 0
    drift_piecewise: bool = False
    saturation: bool = False
    stops: tuple[Stops, ...] = ()
    output_curve: bool = False
    ridge: float = RIDGE

    def effects(self) -> set[str]:
        """The vocabulary names of the effect terms that are on."""
        on = {"hysteresis": self.hysteresis,
              "creep": bool(self.creep_tau_s or self.creep_asym_s or self.creep_hold_s),
              "lag": bool(self.lag_kind), "drift": self.drift_degree > 0,
              "saturation": self.saturation}
        return {name for name, flag in on.items() if flag}

    def reads_static(self) -> bool:
        """Some effect term is driven by the static prediction ŝ (:func:`with_static_of`)."""
        return bool(self.hysteresis or self.creep_tau_s or self.creep_asym_s
                    or self.creep_hold_s or self.output_curve or self.lag_kind == "rate_limit")

    def without_lag(self) -> Spec:
        """The same model without its lag term (of any kind)."""
        return replace(self, lag_kind="", lag_s=0.0, lag_delay_s=0.0, lag_rates=(),
                       lag_sensors=())

    def for_sensor(self, j: int) -> Spec:
        """The model of sensor j: without the low-pass or delay where it does not act on j."""
        if self.lag_kind in ("", "rate_limit") or not self.lag_sensors or j in self.lag_sensors:
            return self
        return self.without_lag()

    def columns(self, n_static: int, n_play: int, n_angles: int) -> dict[str, slice]:
        """Where each effect term's coefficients sit in a sensor's coefficient vector, after
        ``n_static`` static columns (``n_play``: the hysteresis term's play operators on each
        of its inputs; ``n_angles``: the joint's angles)."""
        loop = n_play * (n_angles if self.hysteresis_angles else self.hysteresis_degree)
        out, at = {}, n_static
        for kind, width in (("hysteresis", loop if self.hysteresis else 0),
                            ("creep", len(self.creep_tau_s) * (2 if self.creep_quadratic else 1)
                             + (1 if self.creep_asym_s else 0)
                             + (2 if self.creep_hold_s else 0)),
                            ("lag", 1 if self.lag_kind == "rate_limit" else 0),
                            ("drift", self.drift_degree)):
            out[kind] = slice(at, at + width)
            at += width
        return out

    def drift_term(self) -> tuple[int, bool]:
        """The drift term's count and basis (to tell whether a refit changed it)."""
        return self.drift_degree, self.drift_piecewise

    def lag_term(self) -> tuple:
        """The lag term's model and parameters (to tell whether a refit changed it)."""
        return self.lag_kind, self.lag_s, self.lag_delay_s, self.lag_rates, self.lag_sensors

    def rate_limits(self) -> list[float | None]:
        """The rate limits per sensor for JSON: null where a sensor has none (+inf)."""
        return [r if math.isfinite(r) else None for r in self.lag_rates]

    def config(self) -> dict:
        """The model's terms and their shape parameters, for JSON (a candidate's
        evidence)."""
        return {"degree": self.degree, "local": self.local,
                **({"local_ridge": self.local_ridge} if self.local else {}),
                "hysteresis": self.hysteresis, "hysteresis_degree": self.hysteresis_degree,
                "hysteresis_angles": self.hysteresis_angles,
                "creep_tau_s": list(self.creep_tau_s), "creep_quadratic": self.creep_quadratic,
                "creep_asym_s": list(self.creep_asym_s),
                "creep_hold_s": list(self.creep_hold_s),
                "lag": self.lag_kind,
                "lag_s": self.lag_s, "lag_delay_s": self.lag_delay_s,
                "lag_rates": self.rate_limits(), "lag_sensors": list(self.lag_sensors),
                "drift_degree": self.drift_degree, "drift_piecewise": self.drift_piecewise,
                "saturation": self.saturation, "ridge": self.ridge}


def legendre_products(u: np.ndarray, degree: int) -> tuple[np.ndarray, list[tuple[int, ...]]]:
    """Products of Legendre polynomials Pₖ(uᵢ) of total degree ≤ ``degree``.

    Args:
        u: (N, A) inputs scaled to about [−1, 1].
        degree: maximum total degree.

    Returns:
        (N, P) basis (the first column is the constant 1) and the P exponent tuples.
    """
    n, a = u.shape
    per_angle = []
    for i in range(a):
        cols = [np.ones(n), u[:, i].copy()]
        for k in range(1, degree):
            cols.append(((2 * k + 1) * u[:, i] * cols[k] - k * cols[k - 1]) / (k + 1))
        per_angle.append(cols)
    exponents = [e for total in range(degree + 1)
                 for e in itertools.product(range(total + 1), repeat=a) if sum(e) == total]
    basis = np.empty((n, len(exponents)))
    for p, e in enumerate(exponents):
        col = np.ones(n)
        for i, k in enumerate(e):
            if k:
                col = col * per_angle[i][k]
        basis[:, p] = col
    return basis, exponents


@dataclass
class Inputs:
    """Quantities fixed for a whole run: normalised angles, static input ŝ, caches.

    Attributes:
        u: (N, U) inputs of the static map (see :func:`map_inputs`).
        input_kind: "arm_direction", "arm_axes" or "angles".
        angles: (N, A) the joint's angles, degrees (input of the plays on the angles).
        angle_names: their names (:func:`map_inputs`).
        angle_lo / angle_hi: (A,) degrees, the scaling range.
        static: (N, S) static prediction ŝ (input of the hysteresis and creep terms).
        static_coef: (P, S) its coefficients on the degree-``static_degree`` basis.
        static_degree: degree of that basis.
        static_local: that basis has the local functions.
        centres: (K, 3) centres of the local basis's functions (unit vectors; (0, 3): the
            map's inputs are not an arm direction, and no local basis is offered).
        thresholds: (S, K) play thresholds, sensor units.
        t_norm: (N,) time scaled to [−1, 1] over the recording.
        t_span: (t₀, t₁) s, the scaling range of time.
        centre: (S,) the middle of ŝ's range (p1–p99), sensor units: where the quadratic
            creep driver (ŝ − centre)² is centred, so that it is not nearly ŝ itself.
        segments: (P₂, K) the quadratics Q of the straight runs found (see
            :func:`fit_segments`), on the degree-2 products of ``u``; the static basis ends
            with their lengths √Q. (P₂, 0) or empty: none.
        segment_sensors: the sensor (column) each run was found on.
        still: (N,) bool, the joint holds still (:func:`holding_still`); empty where no
            term needs it yet.
    """

    u: np.ndarray
    input_kind: str
    angle_lo: np.ndarray
    angle_hi: np.ndarray
    static: np.ndarray
    static_coef: np.ndarray
    static_degree: int
    thresholds: np.ndarray
    t_norm: np.ndarray
    t_span: tuple[float, float]
    centre: np.ndarray = field(default_factory=lambda: np.zeros(0))
    angles: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    angle_names: tuple[str, ...] = ()
    segments: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    segment_sensors: tuple[int, ...] = ()
    static_local: bool = False
    centres: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    still: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    cache: dict = field(default_factory=dict)


def scale_angles(angles: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Angles (deg) to [−1, 1] over [lo, hi] (a constant angle maps to 0)."""
    half = np.where(hi > lo, (hi - lo) / 2.0, 1.0)
    return (angles - (hi + lo) / 2.0) / half


def map_inputs(angles: np.ndarray, angle_names: tuple[str, ...], lo: np.ndarray,
               hi: np.ndarray) -> tuple[np.ndarray, str]:
    """The static map's inputs and their kind.

    For a shoulder recorded as MoBL-ARMS angles (``elv_angle``, ``shoulder_elv``, optionally
    ``shoulder_rot``) the inputs are the humerus axis in the thorax frame (a unit vector:
    smooth everywhere, no singularity when the arm hangs and θ is undefined), plus the
    humerus x axis when the axial rotation moves. Any other joint uses its angles scaled to
    [−1, 1] over their recorded range.
    """
    names = list(angle_names)
    if "elv_angle" in names and "shoulder_elv" in names:
        theta = np.deg2rad(angles[:, names.index("elv_angle")])
        phi = np.deg2rad(angles[:, names.index("shoulder_elv")])
        psi = (np.deg2rad(angles[:, names.index("shoulder_rot")]) if "shoulder_rot" in names
               else np.zeros_like(theta))
        rot = ms_to_matrix(theta, phi, psi)
        if "shoulder_rot" in names:
            return np.hstack([rot[:, :, 1], rot[:, :, 0]]), "arm_axes"
        return rot[:, :, 1], "arm_direction"
    return scale_angles(angles, lo, hi), "angles"


def joint_speed(angles: np.ndarray, angle_names: tuple[str, ...], rate_hz: float
                ) -> np.ndarray:
    """(N,) the joint's angular speed at each of the frames ``angles`` (N, A, degrees,
    sampled at ``rate_hz``) holds, deg/s.

    For a shoulder in MoBL-ARMS angles, the speed of the humerus axis (the arm direction)
    and, when the axial rotation moves, of the whole humerus frame (‖ω‖² = ½ Σᵢ ‖ėᵢ‖² over
    its three axes): the rate of the plane of elevation θ means nothing with the arm
    hanging, where mocap noise sends it anywhere. For any other joint, the norm of its
    angles' rates. Each rate is the slope of a least-squares line over ``SPEED_WINDOW_S``
    (a Savitzky–Golay derivative), so the mocap's noise does not read as motion.
    """
    n = angles.shape[0]
    window = min(max(3, int(round(SPEED_WINDOW_S * rate_hz)) | 1), n - 1 + n % 2)
    if window < 3:
        return np.zeros(n)
    u, kind = map_inputs(angles, angle_names, np.min(angles, axis=0), np.max(angles, axis=0))
    if kind == "angles":  # in degrees, not scaled
        u = angles
    elif kind == "arm_axes":  # the humerus y and x axes; z completes the frame
        u = np.hstack([u, np.cross(u[:, 3:], u[:, :3])])
    speed = np.linalg.norm(savgol_filter(u, window, 1, deriv=1, delta=1.0 / rate_hz, axis=0),
                           axis=1)
    if kind == "angles":
        return speed
    return np.rad2deg(speed * (math.sqrt(0.5) if kind == "arm_axes" else 1.0))


def holding_still(speed: np.ndarray) -> np.ndarray:
    """(N,) bool: the joint holds still. A frame is still below ``STILL_DEG_S``, and so is
    every frame of a run below ``MOVING_DEG_S`` that reaches a still frame (a two-threshold
    switch, as a debounced button): a held arm sways, and its sway's peaks would split a
    hold into pieces too short to count; a movement passes the upper threshold."""
    still = np.zeros(speed.shape[0], dtype=bool)
    for start, stop in true_runs(speed < MOVING_DEG_S):
        if np.any(speed[start:stop] < STILL_DEG_S):
            still[start:stop] = True
    return still


def trial_motion(trial: Trial) -> tuple[np.ndarray, np.ndarray]:
    """The joint's speed (N,) deg/s and whether it holds still (N,) bool at each frame of
    ``trial``, computed once per trial (cached)."""
    if "joint_motion" not in trial.cache:
        speed = joint_speed(trial.angles, trial.angle_names, trial.rate_hz)
        trial.cache["joint_motion"] = (speed, holding_still(speed))
    return trial.cache["joint_motion"]


def segment_lengths(u: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """(N, K) the lengths √Q(u) of the straight runs ``segments`` (P₂, K) describes, up to
    each run's scale (a Q below zero, outside the poses it was fitted on, reads 0)."""
    if segments.size == 0:
        return np.zeros((u.shape[0], 0))
    return np.sqrt(np.maximum(legendre_products(u, 2)[0] @ segments, 0.0))


def fibonacci_sphere(n: int) -> np.ndarray:
    """(n, 3) unit vectors spread evenly over the sphere (a Fibonacci lattice)."""
    i = np.arange(n) + 0.5
    polar = np.arccos(1.0 - 2.0 * i / n)
    azimuth = np.pi * (1.0 + 5.0**0.5) * i
    return np.column_stack([np.cos(azimuth) * np.sin(polar), np.sin(azimuth) * np.sin(polar),
                            np.cos(polar)])


def _chord(u: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """(N, K) chord distances between unit vectors u (N, 3) and ``centres`` (K, 3)."""
    return _chord_of_cos(u @ centres.T)


def _chord_of_cos(cos: np.ndarray) -> np.ndarray:
    """The chord distance √(2 − 2·cos) between unit vectors whose cosine is ``cos``."""
    return np.sqrt(np.maximum(2.0 - 2.0 * cos, 0.0))


def local_centres(u: np.ndarray) -> np.ndarray:
    """(K, 3) the lattice points (``LOCAL_CENTRES`` on the sphere) within ``LOCAL_KEEP``
    spacings of some arm direction in u (N, 3); a point far from every pose would only
    carry a coefficient no frame pins down."""
    lattice = fibonacci_sphere(LOCAL_CENTRES)
    spacing = np.sqrt(4.0 * np.pi / LOCAL_CENTRES)
    sample = u[:: max(1, u.shape[0] // 20000)]
    near = np.zeros(LOCAL_CENTRES, dtype=bool)
    for part in np.array_split(sample, max(1, sample.shape[0] // 2000)):
        near |= (_chord(part, lattice) < LOCAL_KEEP * spacing).any(axis=0)
    return lattice[near]


def local_terms(u: np.ndarray, centres: np.ndarray, out: np.ndarray | None = None
                ) -> np.ndarray:
    """(N, K) the local basis: the compact Wendland function (1 − r)⁴(4r + 1) of each
    centre, r its chord distance from u (N, 3) in units of ``LOCAL_REACH`` lattice spacings
    (zero beyond); written into ``out`` (N, K; a view of a wider design) where given."""
    reach = LOCAL_REACH * np.sqrt(4.0 * np.pi / LOCAL_CENTRES)
    if out is None:
        out = np.empty((u.shape[0], centres.shape[0]))
    # a fifth of the pairs on a four-minute trial are near; the rest stay zero. The chord
    # (:func:`_chord_of_cos`) is formed only where the cosine is near enough (by a margin
    # for rounding), and decides; a few thousand rows at a time stay in cache: a third of
    # the time of every chord formed at once (0.36 s a call, 13 calls before step 2 of a
    # four-minute recording whose clock is moved)
    near_cos = 1.0 - 0.5 * reach**2 - 1e-9
    rows = min(LOCAL_ROWS, u.shape[0])
    cos, chunk = np.empty((rows, centres.shape[0])), np.empty((rows, centres.shape[0]))
    for start in range(0, u.shape[0], LOCAL_ROWS):
        part = u[start:start + LOCAL_ROWS]
        here, values = cos[:part.shape[0]], chunk[:part.shape[0]]
        np.matmul(part, centres.T, out=here)
        near = np.flatnonzero(here > near_cos)
        chord = _chord_of_cos(here.ravel()[near])
        inside = chord < reach
        r = chord[inside] / reach
        values.fill(0.0)
        values.ravel()[near[inside]] = (1.0 - r) ** 4 * (4.0 * r + 1.0)
        out[start:start + part.shape[0]] = values
    return out


def static_terms(u: np.ndarray, degree: int, segments: np.ndarray,
                 centres: np.ndarray | None = None) -> np.ndarray:
    """(N, P) the static map's basis: Legendre products of ``u`` up to ``degree``, the local
    functions of ``centres`` when given (:func:`local_terms`), then the lengths of the
    straight runs ``segments`` (:func:`fit_segments`). Each part is written into the one
    array (joining them copied the basis again: 62 ms a call with local functions on a
    four-minute recording, in the main process before every static map)."""
    polynomial = legendre_products(u, degree)[0]
    runs = segment_lengths(u, segments)
    n_local = centres.shape[0] if centres is not None else 0
    out = np.empty((u.shape[0], polynomial.shape[1] + n_local + runs.shape[1]))
    local = slice(polynomial.shape[1], polynomial.shape[1] + n_local)
    out[:, :local.start] = polynomial
    if centres is not None and n_local:
        local_terms(u, centres, out[:, local])
    out[:, local.stop:] = runs
    return out


#: First element of the cache keys of :func:`static_basis` (which does not depend on ŝ, so
#: :func:`with_static_of` keeps them).
_BASIS = "B"


def static_basis(inputs: Inputs, degree: int, local: bool = False) -> np.ndarray:
    """The static map's basis over the run's frames (cached per degree and local basis)."""
    key = (_BASIS, degree, local)
    if key not in inputs.cache:
        inputs.cache[key] = static_terms(inputs.u, degree, inputs.segments,
                                         inputs.centres if local else None)
    return inputs.cache[key]


def coefficient_slices(inputs: Inputs, spec: Spec) -> dict[str, slice]:
    """Where each effect term of ``spec`` sits in a sensor's coefficient vector
    (:meth:`Spec.columns`) with these inputs' static basis, plays and angles."""
    n_static = static_basis(inputs, spec.degree, spec.local).shape[1]
    return spec.columns(n_static, inputs.thresholds.shape[1], inputs.angles.shape[1])


def fit_segments(trial: Trial, u: np.ndarray, input_kind: str,
                 ) -> tuple[np.ndarray, tuple[int, ...]]:
    """The straight tendon runs across the shoulder that the readings show, as (P₂, K)
    quadratics Q on the degree-2 Legendre products of the arm axes ``u``, and the sensor
    each was found on.

    A run from a point a fixed on the thorax to a point b fixed on the humerus (the GH
    centre c may move with the elevation) is |a − c − R·b| long; its square is linear in the
    humerus axes, in their products and in cos φ, so a quadratic Q(u) of the map's inputs.
    A reading y = offset ± gain·L therefore has (y − offset)² = gain²·Q(u): for a given
    offset, Q is one linear least-squares fit, and (y − offset)² = y² − 2·offset·y +
    offset² makes it three fits for every offset. The offset lies beyond the readings' range
    (a length is positive); the one whose offset ± √Q follows y best is kept
    (:func:`_segment_offset`). A polynomial of the axes follows √Q badly where the run is
    short (under the arm); the column √Q follows it exactly.

    A sensor's run is kept only if Q is positive on every valid frame: a length is; a Q that
    is not is no straight run (a path wrapped over the shoulder, a clamp), and √max(Q, 0)
    would be flat there: a ready-made stop that would take a saturation into the static
    map. Fitted once, on every valid frame (the static map itself is refitted per fold:
    what Q sees of a held-out block lowers the held-out gap by under 1 % where measured,
    docs/discrepancy-method.md, step 2, Straight runs).

    Only with the axial rotation recorded (``arm_axes``): without it a point off the
    humerus axis moves with a rotation the inputs do not hold, so its run's square is no
    quadratic of the humerus axis alone, and a curve bent to a soft stop instead took the
    stop's place (docs/discrepancy-method.md, step 2); other joints' angles give no such quadratic.
    """
    p2 = legendre_products(u[:1], 2)[0].shape[1]
    if input_kind != "arm_axes":
        return np.zeros((p2, 0)), ()
    step = max(1, int(round(trial.rate_hz / FIT_RATE_HZ)))
    rows = np.flatnonzero(trial.valid)[::step]
    quad = legendre_products(u[rows], 2)[0]
    every = legendre_products(u[trial.valid], 2)[0]
    kept: list[np.ndarray] = []
    found: list[int] = []
    for j in range(trial.n_sensors):
        y = trial.y[rows, j]
        spread = float(np.std(y))
        if spread == 0.0:
            continue
        z = (y - float(np.mean(y))) / spread
        # Q(offset) = A − 2·offset·B + offset²·C, from three fits on the same design
        abc = np.linalg.lstsq(quad, np.column_stack([z**2, z, np.ones_like(z)]),
                              rcond=None)[0]
        q = _segment_offset(z, quad, abc)
        if np.min(every @ q) > 0.0:
            kept.append(q)
            found.append(j)
    return (np.column_stack(kept) if kept else np.zeros((p2, 0))), tuple(found)


def _segment_offset(z: np.ndarray, quad: np.ndarray, abc: np.ndarray) -> np.ndarray:
    """The Q of the offset (beyond either end of the standardised readings z, 10⁻³ to 10³
    of their spread away, on a log grid refined once) whose offset ± √Q follows z with the
    smallest RMS (whether that Q is a length, positive everywhere, the caller checks)."""
    def q_of(offset: float) -> np.ndarray:
        return abc[:, 0] - 2.0 * offset * abc[:, 1] + offset**2 * abc[:, 2]

    def misfit(offset: float, sign: float) -> float:
        root = np.sqrt(np.maximum(quad @ q_of(offset), 0.0))
        return float(np.mean((z - offset - sign * root) ** 2))

    best = (np.inf, 0.0)  # (misfit, offset)
    for sign, edge in ((1.0, float(np.min(z))), (-1.0, float(np.max(z)))):
        away = np.geomspace(1e-3, 1e3, 61)
        for _ in range(2):  # the grid, then a finer one around its best
            errs = [misfit(edge - sign * d, sign) for d in away]
            k = int(np.argmin(errs))
            if errs[k] < best[0]:
                best = (errs[k], edge - sign * float(away[k]))
            away = np.geomspace(away[max(k - 1, 0)], away[min(k + 1, away.size - 1)], 21)
    return q_of(best[1])


def half_spread(thresholds: np.ndarray) -> np.ndarray:
    """(...) half the p1–p99 spread of ŝ, from the play thresholds (..., K) placed on it
    (:data:`PLAY_FRACTIONS` of the spread)."""
    return thresholds[..., 0] / PLAY_FRACTIONS[0] / 2.0


def level(inputs: Inputs, x: np.ndarray) -> np.ndarray:
    """z = (x − centre) / half the p1–p99 spread of ŝ, per sensor, for levels x (N, S, ...)
    in sensor units: −1…1 over the middle of ŝ's range."""
    extra = (1,) * (x.ndim - 2)
    return ((x - inputs.centre.reshape(-1, *extra))
            / half_spread(inputs.thresholds).reshape(-1, *extra))


def hysteresis_columns(inputs: Inputs, degree: int = 1) -> np.ndarray:
    """(N, S, K·degree) the hysteresis basis of every sensor: first the Prandtl–Ishlinskii
    columns ŝ − p_r(ŝ) of its K play operators p_r, then, for each power m = 2…degree,
    z(ŝ)ᵐ − z(p_r(ŝ))ᵐ with z = (level − centre) / half the p1–p99 spread of ŝ.

    Any Preisach operator is a sum over thresholds r of some function of p_r(ŝ) (Brokate and
    Sprekels, *Hysteresis and Phase Transitions*, 1996, ch. 2), of which Prandtl–Ishlinskii
    keeps the linear part: its loops are as wide at every level. The powers let the width
    change with the level (a Preisach density that is not uniform in its bias, an
    exponential read-out of a loop in strain). Each is zero wherever p_r(ŝ) = ŝ, so no
    column is a static function of ŝ: a transfer curve cannot pass for a loop."""
    key = ("H", degree)
    if key not in inputs.cache:
        if "P" not in inputs.cache:  # the plays, shared by every degree
            inputs.cache["P"] = play(inputs.static, inputs.thresholds)  # (N, S, K)
        played = inputs.cache["P"]
        cols = [inputs.static[:, :, None] - played]
        if degree > 1:
            z_static, z_played = level(inputs, inputs.static)[:, :, None], level(inputs, played)
            cols += [z_static**m - z_played**m for m in range(2, degree + 1)]
        inputs.cache[key] = np.concatenate(cols, axis=2)
    return inputs.cache[key]


def loop_width_terms(thresholds: np.ndarray, degree: int) -> np.ndarray:
    """(degree, K) what each hysteresis column (:func:`hysteresis_columns`) adds to the
    loop's width at the middle of the sensor's range (ŝ = centre), per unit weight: the
    falling branch (each play at ŝ + r) less the rising one (at ŝ − r), after an excursion
    wider than the widest play. ŝ − play is −r falling and +r rising: −2r. A power m of the
    level, z(ŝ)ᵐ − z(play)ᵐ with z(ŝ) = 0 and z(play) = ±δ (δ = r / half the spread), is
    −δᵐ falling and −(−δ)ᵐ rising: 0 for m even, −2δᵐ for m odd."""
    delta = thresholds / half_spread(thresholds)
    rows = [-2.0 * thresholds] + [(-delta) ** m - delta**m for m in range(2, degree + 1)]
    return np.vstack(rows)


def angle_thresholds(inputs: Inputs) -> np.ndarray:
    """(A, K) the half-widths of the plays on the angles, degrees: :data:`PLAY_FRACTIONS` of
    each angle's scaling range (its recorded range)."""
    span = np.maximum(inputs.angle_hi - inputs.angle_lo, 0.0)
    return span[:, None] * np.asarray(PLAY_FRACTIONS)[None, :]


def static_at(inputs: Inputs, angles: np.ndarray) -> np.ndarray:
    """(N, S) the static input ŝ's map at ``angles`` (N, A), degrees
    (:func:`static_of_map_inputs`)."""
    u, _ = map_inputs(angles, inputs.angle_names, inputs.angle_lo, inputs.angle_hi)
    return static_of_map_inputs(inputs, u)


def static_of_map_inputs(inputs: Inputs, u: np.ndarray) -> np.ndarray:
    """(N, S) the static input ŝ's map (its basis and coefficients) at the map inputs ``u``
    (N, U; :func:`map_inputs`)."""
    basis = static_terms(u, inputs.static_degree, inputs.segments,
                         inputs.centres if inputs.static_local else None)
    return basis @ inputs.static_coef


def angle_play_columns(inputs: Inputs) -> np.ndarray:
    """(N, S, A·K) the hysteresis basis of a loop in the pose: for each angle αₐ and each
    play half-width r (:func:`angle_thresholds`), ∂ŝ/∂αₐ · (αₐ − p_r(αₐ)), grouped by angle.

    A sleeve that slips on the limb, or a tendon that sticks in its guide, follows each
    angle with a backlash: the sensor reads the pose the fabric holds, ŝ(p(α)) ≈ ŝ(α) −
    ∂ŝ/∂α · (α − p(α)). Any weighted sum over r is a Prandtl–Ishlinskii loop in each angle,
    read through the map's slope (:func:`static_slopes`). Unlike the plays on ŝ
    (:func:`hysteresis_columns`) it loops where one angle reverses while ŝ goes on one way
    (an axial rotation with the arm raised), and it is as wide in the angle at every pose.
    Each column is zero wherever the play has caught up with its angle, so none is a
    static function of the pose."""
    if "HA" not in inputs.cache:
        lost = inputs.angles[:, :, None] - play(inputs.angles, angle_thresholds(inputs))
        cols = static_slopes(inputs)[:, :, :, None] * lost[:, None, :, :]  # (N, S, A, K)
        inputs.cache["HA"] = cols.reshape(cols.shape[0], cols.shape[1], -1)
    return inputs.cache["HA"]


def static_slopes(inputs: Inputs, workers: int = 1) -> np.ndarray:
    """(N, S, A) ∂ŝ/∂αₐ, sensor units per degree: central differences of ŝ's map
    (:func:`static_at`) of ``STATIC_SLOPE_STEP_DEG`` in each angle (cached). The maps at
    the shifted angles are independent: ``workers`` processes form them
    (:func:`~.workers.forked_map`; the same values in any number)."""
    if "dS" not in inputs.cache:
        angles = inputs.angles
        n_angles = angles.shape[1]
        steps = STATIC_SLOPE_STEP_DEG * np.eye(n_angles)
        maps = forked_map(functools.partial(static_at, inputs),
                          [angles + sign * steps[a] for a in range(n_angles) for sign in (1, -1)],
                          workers)
        slopes = np.empty((angles.shape[0], inputs.static_coef.shape[1], n_angles))
        for a in range(n_angles):
            slopes[:, :, a] = (maps[2 * a] - maps[2 * a + 1]) / (2.0 * STATIC_SLOPE_STEP_DEG)
        inputs.cache["dS"] = slopes
    return inputs.cache["dS"]


def creep_columns(inputs: Inputs, tau_s: float, rate_hz: float) -> np.ndarray:
    """(N, S) ŝ low-passed with ``tau_s`` (the relaxing creep state)."""
    key = ("C", tau_s)
    if key not in inputs.cache:
        inputs.cache[key] = low_pass(inputs.static, tau_s, rate_hz)
    return inputs.cache[key]


def creep_quadratic_columns(inputs: Inputs, tau_s: float, rate_hz: float) -> np.ndarray:
    """(N, S) (ŝ − centre)² low-passed with ``tau_s``, sensor units squared: with
    :func:`creep_columns`, a creep whose driver is any quadratic in the stretch."""
    key = ("CQ", tau_s)
    if key not in inputs.cache:
        inputs.cache[key] = low_pass((inputs.static - inputs.centre) ** 2, tau_s, rate_hz)
    return inputs.cache[key]


def _fit_rate_steps(n: int, rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Frame times t (N,) s and the frames ``at`` where a slow state is stepped: about
    FIT_RATE_HZ, always ending on the last frame."""
    t = np.arange(n) / rate_hz
    at = np.arange(0, n, max(1, int(round(rate_hz / FIT_RATE_HZ))))
    return t, (at if at[-1] == n - 1 else np.append(at, n - 1))


def _every_frame(t: np.ndarray, at: np.ndarray, state: np.ndarray) -> np.ndarray:
    """(N, K) a state stepped at the frames ``at`` (len(at), K), interpolated to every frame."""
    return np.column_stack([np.interp(t, t[at], state[:, j]) for j in range(state.shape[1])])


def creep_asym_columns(inputs: Inputs, build_s: float, recover_s: float,
                       rate_hz: float) -> np.ndarray:
    """(N, S) asymmetric creep state for unit gain: relaxes toward ŝ − ŝ₀ (the stretch since
    the first frame) with ``build_s`` while it grows and ``recover_s`` while it shrinks."""
    key = ("CA", build_s, recover_s)
    if key not in inputs.cache:
        # The state moves over seconds: step it at about FIT_RATE_HZ (exact step-invariant
        # updates over the longer steps) and interpolate back to every frame.
        t, at = _fit_rate_steps(inputs.static.shape[0], rate_hz)
        signal = Signal.from_values(t[at], inputs.static[at])
        crept = Creep(gain=1.0, tau_build_s=build_s, tau_recover_s=recover_s).apply(
            signal, np.random.default_rng(0))
        inputs.cache[key] = _every_frame(t, at, crept.values - inputs.static[at])
    return inputs.cache[key]


def creep_hold_columns(inputs: Inputs, grow_s: float, recover_s: float,
                       rate_hz: float) -> np.ndarray:
    """(N, S + 1) creep states that flow only while the joint holds still (``inputs.still``):
    each rises toward its driver (ŝ of each sensor, then 1, so the load may be any linear
    function of the stretch) with ``grow_s`` while still, and falls back to zero with
    ``recover_s`` while the joint moves. A fabric or tendon that creeps under a held load
    and recovers once it moves again; the state carries over from hold to hold. Column j
    belongs to sensor j, the last to every sensor."""
    key = ("CH", grow_s, recover_s)
    if key not in inputs.cache:
        # The state moves over seconds: step it at about FIT_RATE_HZ (each step still for
        # the share of its frames that are, then moving) and interpolate back to every frame.
        n = inputs.static.shape[0]
        t, at = _fit_rate_steps(n, rate_hz)
        drive = np.column_stack([inputs.static[at], np.ones(at.size)])
        # the share of still frames in each step (at[i−1], at[i]]
        share = np.add.reduceat(inputs.still.astype(np.float64), at) / np.diff(np.append(at, n))
        share = np.concatenate([[0.0], share[:-1]])
        dt = np.diff(t[at], prepend=t[0])
        keep_grow = np.exp(-dt * share / grow_s)
        keep_recover = np.exp(-dt * (1.0 - share) / recover_s)
        state = np.zeros_like(drive)
        c = np.zeros(drive.shape[1])
        for i in range(at.size):
            c = (drive[i] + (c - drive[i]) * keep_grow[i]) * keep_recover[i]
            state[i] = c
        inputs.cache[key] = _every_frame(t, at, state)
    return inputs.cache[key]


def curve_columns(inputs: Inputs) -> np.ndarray:
    """(N, S, 2) z² and z³ of each sensor's static prediction, z = (ŝ − centre) / half its
    p1–p99 spread: with the static map's own ŝ, any cubic transfer curve of the reading."""
    if "Q" not in inputs.cache:
        z = level(inputs, inputs.static)
        inputs.cache["Q"] = np.stack([z**2, z**3], axis=2)
    return inputs.cache["Q"]


def rate_limit_column(inputs: Inputs, j: int, rate: float, rate_hz: float) -> np.ndarray:
    """(N, 1) R_rate(ŝⱼ) − ŝⱼ: how far a reading limited to ``rate`` (units/s) falls behind
    sensor j's static prediction."""
    key = ("R", j, rate)
    if key not in inputs.cache:
        x = inputs.static[:, j]
        inputs.cache[key] = (rate_limit(x, rate, rate_hz) - x)[:, None]
    return inputs.cache[key]


def drift_columns(t_norm: np.ndarray, degree: int, piecewise: bool = False) -> np.ndarray:
    """(N, degree) functions of time scaled to [−1, 1]: the Legendre polynomials
    P₁…P_degree or, ``piecewise``, the linear B-splines ("hats") on ``degree`` even intervals,
    less the first (with the static map's constant they span every piecewise-linear
    function on those knots)."""
    if not piecewise:
        return legendre_products(t_norm[:, None], degree)[0][:, 1:]
    knots = np.linspace(-1.0, 1.0, degree + 1)[1:]
    width = 2.0 / degree
    return np.clip(1.0 - np.abs(t_norm[:, None] - knots[None, :]) / width, 0.0, None)


def design(rate_hz: float, inputs: Inputs, spec: Spec, j: int) -> Design:
    """The design of sensor j for ``spec`` at ``rate_hz`` (before any stop)."""
    spec = spec.for_sensor(j)

    def lagged(columns: Callable[..., np.ndarray], *args: float) -> np.ndarray:
        return lagged_term(inputs, spec, rate_hz, columns, *args)

    own = []
    if spec.hysteresis and spec.hysteresis_angles:
        own.append(lagged(angle_play_columns)[:, j, :])
    elif spec.hysteresis:
        own.append(lagged(hysteresis_columns, spec.hysteresis_degree)[:, j, :])
    for tau in spec.creep_tau_s:
        own.append(lagged(creep_columns, tau, rate_hz)[:, j:j + 1])
    if spec.creep_quadratic:
        for tau in spec.creep_tau_s:
            own.append(lagged(creep_quadratic_columns, tau, rate_hz)[:, j:j + 1])
    if spec.creep_asym_s:
        own.append(lagged(creep_asym_columns, *spec.creep_asym_s, rate_hz)[:, j:j + 1])
    if spec.creep_hold_s:
        own.append(lagged(creep_hold_columns, *spec.creep_hold_s, rate_hz)[:, [j, -1]])
    if spec.output_curve:
        own.append(lagged(curve_columns)[:, j, :])
    if spec.lag_kind == "rate_limit":
        own.append(rate_limit_column(inputs, j, spec.lag_rates[j], rate_hz))
    if spec.drift_degree:
        own.append(drift_columns(inputs.t_norm, spec.drift_degree, spec.drift_piecewise))
    shared = lagged(static_basis, spec.degree, spec.local)  # the same for every sensor
    return Design(shared=shared, own=np.hstack(own) if own else shared[:, :0])


def lagged_term(inputs: Inputs, spec: Spec, rate_hz: float,
                columns: Callable[..., np.ndarray], *args: float) -> np.ndarray:
    """The columns ``columns(inputs, *args)`` (the static basis, or an effect term of every
    sensor, (N, S, ...)) with ``spec``'s lag applied (the lag acts column by column). Kept
    for the last ``KEPT_LAGS`` lags: the candidates and refits of one model share them."""
    if spec.lag_kind in ("", "rate_limit"):
        return columns(inputs, *args)
    lag = (spec.lag_kind, spec.lag_s, spec.lag_delay_s)
    kept: dict[tuple, dict[tuple, np.ndarray]] = inputs.cache.setdefault("lagged_terms", {})
    terms = kept.get(lag)
    if terms is None:
        if len(kept) >= KEPT_LAGS:
            del kept[next(iter(kept))]  # the lag asked for longest ago
        terms = kept[lag] = {}
    key = (columns.__name__, *args)
    if key not in terms:
        terms[key] = apply_lag(columns(inputs, *args), spec.lag_kind, spec.lag_s, rate_hz,
                               spec.lag_delay_s)
    return terms[key]


@dataclass
class Fit:
    """Blocked cross-validation and full-data fit of one model.

    Attributes:
        spec: the model.
        residual: (N, S) held-out residual (measurement − prediction of the fold that did not
            see the frame), sensor units; NaN at frames that are not scored.
        block_mse: (N_BLOCKS,) held-out mean squared residual per block (all sensors); NaN
            for a block with no scored frame.
        coef: per sensor, the (P,) coefficients fitted on all valid frames.
        prediction: (N, S) full-data prediction.
        stops: per sensor, its stops (:class:`~.stops.Stops`; none without the saturation term).
    """

    spec: Spec
    residual: np.ndarray
    block_mse: np.ndarray
    coef: list[np.ndarray]
    prediction: np.ndarray
    stops: list[Stops]

    @property
    def gap(self) -> float:
        """Held-out RMSE over all sensors and valid frames, sensor units."""
        r = self.residual[np.isfinite(self.residual)]
        return float(np.sqrt(np.mean(r**2)))

    def sensor_gap(self) -> np.ndarray:
        """(S,) held-out RMSE per sensor."""
        return np.sqrt(np.nanmean(self.residual**2, axis=0))


def map_ridge(inputs: Inputs, spec: Spec) -> Ridge:
    """The ridge (:class:`~.folds.Ridge`) of a design whose static map is ``spec``'s: its
    constant (the first column of :func:`legendre_products`) unshrunk."""
    n_static = static_basis(inputs, spec.degree, spec.local).shape[1]
    start = math.comb(spec.degree + inputs.u.shape[1], spec.degree)
    count = inputs.centres.shape[0] if spec.local else 0
    return Ridge(n_static=n_static, static=spec.ridge, local=(start, start + count),
                 local_ridge=spec.local_ridge, free_constant=True)


#: One sensor's share of a fit: its fold coefficients ((N_BLOCKS + 1, P): each held-out
#: fold's, then the full-data fit's) and its stops.
SensorPart = tuple[np.ndarray, Stops]


def sensor_part(trial: Trial, inputs: Inputs, spec: Spec, j: int, stop: Stops | None = None
                ) -> SensorPart:
    """Sensor j's share of :func:`fit` of ``spec`` (its stops ``stop`` where
    ``spec.stops`` gives none; see :func:`_sensor_part`). A sensor's share depends on no
    other sensor, so the costly ones (stops chosen on the held-out blocks) may be computed
    apart and handed to :func:`fit`."""
    return _sensor_part(trial, inputs, spec, j, design(trial.rate_hz, inputs, spec, j), stop)


def _sensor_part(trial: Trial, inputs: Inputs, spec: Spec, j: int, x: Design,
                 stop: Stops | None) -> SensorPart:
    """Sensor j's fold coefficients on its design ``x`` and its stops: with the saturation
    term its map bends at ``spec.stops[j]`` when given, else at ``stop``, else at stops
    chosen here (:func:`~.stops.choose_stops`), fitted through them
    (:func:`~.stops.fit_with_stops`); without it, none."""
    y = trial.y[:, j]
    ridge = map_ridge(inputs, spec)  # the static map is the same for every sensor
    if not spec.saturation:
        return fit_coefs(trial, x, y, ridge), NO_STOPS
    red = reduce(trial, x, y)
    plain = fold_coefs(red, red.rows.usable(trial.valid), ridge)
    if spec.stops:
        stop = spec.stops[j]
    elif stop is None:
        stop = choose_stops(trial, y, ridge, j, red, plain)
    return fit_with_stops(trial, y, ridge, stop, float(trial.noise[j]), red, plain), stop


def fit(trial: Trial, inputs: Inputs, spec: Spec, parts: list[SensorPart] | None = None
        ) -> Fit:
    """Held-out residuals and full-data coefficients of ``spec`` for every sensor, from
    each sensor's share (:func:`sensor_part`): ``parts`` where given (computed apart),
    else computed here.

    With the saturation term each sensor's map bends at its stops: ``spec.stops`` when
    given, else chosen (:func:`~.stops.choose_stops`), then fitted (:func:`~.stops.fit_with_stops`).
    """
    designs = [design(trial.rate_hz, inputs, spec, j) for j in range(trial.n_sensors)]
    if parts is None:
        parts = [_sensor_part(trial, inputs, spec, j, x, None) for j, x in enumerate(designs)]
    fold = [c for c, _ in parts]  # per sensor, (N_BLOCKS + 1, P) fold coefficients
    stops = [stop for _, stop in parts]
    held, full = fold_products(trial, designs, fold)
    residual = np.empty_like(trial.y)
    prediction = np.empty_like(trial.y)
    for j, stop in enumerate(stops):
        with np.errstate(invalid="ignore"):  # y may be NaN or inf where invalid, never scored
            residual[:, j] = np.where(trial.scored, trial.y[:, j] - stop.apply(held[:, j]),
                                      np.nan)
        prediction[:, j] = stop.apply(full[:, j])
    coefs = [c[-1] for c in fold]
    return Fit(spec=spec, residual=residual, block_mse=block_mse(trial, residual), coef=coefs,
               prediction=prediction, stops=stops)


def with_static_of(inputs: Inputs, result: Fit) -> Inputs:
    """``inputs`` with ŝ, the input of the history terms, taken from ``result``'s own
    static part: its static map's columns times their full-data coefficients, without its
    lag, stops or effect terms (the reading the model says the suit would give with no
    effect), and the caches that depend on ŝ emptied.

    :func:`make_inputs` fits ŝ to the readings before any effect is known, so where the
    arm spends more time on one branch of a loop at some pose, ŝ takes part of the loop
    in; a play operator or a creep driven by it then reverses and relaxes about a
    reading that is not the suit's (a Prandtl–Ishlinskii loop of 1.5–2.1 mm RMS fitted
    on that ŝ left 0.30 mm held out where its clean control leaves 0.17 mm, and 0.19 mm
    on the ŝ of its own fit; hidden-effect case hysteresis/lib/m2/seed 1000, 90 s)."""
    spec = result.spec
    basis = static_basis(inputs, spec.degree, spec.local)
    coef = np.column_stack([c[:basis.shape[1]] for c in result.coef])
    cache: dict = {key: kept for key, kept in inputs.cache.items()
                   if isinstance(key, tuple) and key[0] == _BASIS}
    cache["lagged_terms"] = {lag: {key: kept for key, kept in terms.items()
                                   if key[0] == static_basis.__name__}
                             for lag, terms in inputs.cache.get("lagged_terms", {}).items()}
    return replace(inputs, static=basis @ coef, static_coef=coef, static_degree=spec.degree,
                   static_local=spec.local, cache=cache)


def restrict_to_coverage(trial: Trial, u: np.ndarray) -> float:
    """Score only held-out frames whose pose the other folds cover.

    A frame counts in the gap when some training frame of its fold lies within
    ``COVER_RADIUS`` of it in the static map's input space (about 6° of arm direction, or
    5 % of an angle's range): the gap then measures what the model gets wrong where it was
    calibrated, not how a polynomial extrapolates to a pose visited once. Sets
    ``trial.scored`` and returns the fraction of valid frames left out.
    """
    from scipy.spatial import cKDTree

    scored = trial.valid.copy()
    step = max(1, int(round(trial.rate_hz / FIT_RATE_HZ)))
    for b in range(N_BLOCKS):
        train = np.flatnonzero(trial.valid & (trial.blocks != b))[::step]
        held = np.flatnonzero(trial.valid & (trial.blocks == b))
        if held.size == 0 or train.size == 0:
            continue
        dist, _ = cKDTree(u[train]).query(u[held], distance_upper_bound=COVER_RADIUS)
        scored[held[~np.isfinite(dist)]] = False
    trial.scored = scored
    return 1.0 - scored.sum() / max(int(trial.valid.sum()), 1)


def drift_kept_heldout(trial: Trial, inputs: Inputs, spec: Spec) -> float:
    """The share of a linear drift's variance that ``spec``'s static map leaves in the
    held-out gap: 1 − R² of time itself predicted held out from the pose by that map, over
    the scored frames.

    Each held-out block is predicted by a map fitted on the other blocks, and a block's
    neighbours in time are in other folds. Where the poses follow time (a session that
    reaches each pose once, in order), the map learns time from the poses next to a block
    and takes a slow drift in as the pose's doing: on the sixth blind generator's rec 29 a
    ramp 5.2 times the noise added 0.70 noise variances to its twin's gap, and the map kept
    1.7 % of a linear drift held out (the fixture's 71 %). A drift, or a creep slower than
    a block, is seen only in what the map cannot follow."""
    x = Design.of(static_basis(inputs, spec.degree, spec.local))
    held, _ = fold_products(trial, [x], [fit_coefs(trial, x, inputs.t_norm,
                                                    map_ridge(inputs, spec))])
    scored = trial.scored
    t = inputs.t_norm[scored]
    spread = float(np.var(t))
    if not spread > 0.0:
        return 1.0
    return float(np.mean((t - held[scored, 0]) ** 2) / spread)


def make_inputs(trial: Trial, static_map: Spec | None = None) -> Inputs:
    """Scale angles and time, place the local basis's centres (an arm direction only) and,
    given ``static_map``, fit its static map (degree, local basis and ridges; its effect
    terms play no part) on all valid frames (the prediction ŝ is the input of the history
    terms) and place the play thresholds. Without it only the scaling and placing are done
    (enough to fit a model with no effect terms)."""
    lo = np.min(trial.angles[trial.valid], axis=0)
    hi = np.max(trial.angles[trial.valid], axis=0)
    t0, t1 = float(trial.t[0]), float(trial.t[-1])
    u, kind = map_inputs(trial.angles, trial.angle_names, lo, hi)
    inputs = Inputs(u=u, input_kind=kind, angle_lo=lo, angle_hi=hi,
                    angles=trial.angles, angle_names=trial.angle_names, static=np.empty(0),
                    static_coef=np.empty(0), static_degree=1,
                    thresholds=np.empty(0), t_norm=2.0 * (trial.t - t0) / (t1 - t0) - 1.0,
                    t_span=(t0, t1))
    inputs.still = trial_motion(trial)[1]
    if "segments" not in trial.cache:
        trial.cache["segments"] = fit_segments(trial, u, kind)
    inputs.segments, inputs.segment_sensors = trial.cache["segments"]
    if kind == "arm_direction":
        if "centres" not in trial.cache:
            trial.cache["centres"] = local_centres(u[trial.valid])
        inputs.centres = trial.cache["centres"]
    if static_map is None:
        return inputs
    inputs.static_degree, inputs.static_local = static_map.degree, static_map.local
    basis = static_basis(inputs, static_map.degree, static_map.local)
    static_ridge = map_ridge(inputs, static_map)
    coef = np.column_stack([fit_coefs(trial, Design.of(basis), trial.y[:, j], static_ridge)[-1]
                            for j in range(trial.n_sensors)])
    inputs.static_coef = coef
    inputs.static = basis @ coef
    p1, p99 = np.quantile(inputs.static[trial.valid], [0.01, 0.99], axis=0)
    inputs.centre = (p1 + p99) / 2.0
    spread = np.where(p99 > p1, p99 - p1, 1.0)
    inputs.thresholds = spread[:, None] * np.asarray(PLAY_FRACTIONS)[None, :]
    return inputs
