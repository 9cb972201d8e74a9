"""The calibrated suit profile: the workflow's model written as TOML the emulator can load.

A calibrated suit is not a tendon geometry: it is the calibrated static map (Legendre
polynomial of the arm direction or the joint angles) plus the effect terms the workflow
added, with their fitted parameters. Schema ``exohil-calibrated-suit-profile`` version 1
(docs/discrepancy.md); it sits beside the geometric ``exohil-suit-profile`` (which is
unchanged) and is read by :func:`load_calibrated_profile`. :func:`simulate_calibrated` turns
angles into sensor values with it and :func:`simulate_calibrated_recording` makes a
recording (format v1) from a movement, like :func:`exohil.emulators.simulate.simulate`.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from exohil.emulators.discrepancy.model import (
    Inputs,
    Spec,
    design,
    holding_still,
    joint_speed,
    map_inputs,
    static_of_map_inputs,
    static_terms,
)
from exohil.emulators.discrepancy.stops import Stops
from exohil.emulators.discrepancy.workflow import Outcome
from exohil.emulators.effects import Noise, Signal
from exohil.emulators.protocols import ANGLE_NAMES, MOCAP_RATE_HZ, Trajectory, replayed_motion
from exohil.emulators.suit_profile import (
    PROFILE_SCHEMA,
    ProfileError,
    SuitProfile,
    load_profile,
    read_toml,
)
from exohil.formats.atomic import write_text
from exohil.formats.recording import AngleStream, Recording, SensorStream
from exohil.kinematics import OBSERVABLE_ELEVATION_DEG

CALIBRATED_SCHEMA = "exohil-calibrated-suit-profile"
CALIBRATED_VERSION = 1
LAG_KINDS = ("none", "first_order", "delay", "first_order_delay", "rate_limit")
#: An angle this far (degrees) beyond the calibrated range still counts as inside it
#: (:func:`outside_calibration`): about the reach within which the workflow counts a pose
#: as covered by the calibration (``COVER_RADIUS``, a chord of 0.1, 5.7° of arm direction).
RANGE_TOLERANCE_DEG = 5.0
#: The sensor rates a calibrated profile may hold, Hz. Above: the most any rate option of
#: exohil takes (``harness.cli_types.MAX_RATE_HZ``, which this layer cannot import). Below: the
#: model's time terms (lag time constants of tens of ms, a 0.5 s speed window, 1 s holds)
#: need several frames a second; a rate under 1 Hz (e.g. a hand-edited 1e-9) would simulate
#: no frame of a minute-long movement, and failed there with an unexpected IndexError.
PROFILE_RATE_HZ = (1.0, 100_000.0)


@dataclass(frozen=True)
class CalibratedSuit:
    """A calibrated suit model.

    Attributes:
        name: profile name.
        sensors: sensor names, in column order.
        units: sensor unit.
        joint / angles: the mocap joint and the angle names it is driven by (degrees).
        rate_hz: sample rate the filters (lag, creep) were fitted at, Hz.
        effects: the model's effect terms: those it started with (``--profile``), then those
            the workflow added, in order.
        spec: the model's terms and shape parameters.
        inputs: the static map's scaling, static input coefficients and play thresholds.
        coef: (S, P) coefficients per sensor in design-column order.
        stops: per sensor, its stops (levels ±inf when none; softness 0 for a hard stop).
        noise: (S,) white-noise standard deviation, sensor units.
    """

    name: str
    sensors: tuple[str, ...]
    units: str
    joint: str
    angles: tuple[str, ...]
    rate_hz: float
    effects: tuple[str, ...]
    spec: Spec
    inputs: Inputs
    coef: np.ndarray
    stops: tuple[Stops, ...]
    noise: np.ndarray


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, int | np.integer):
        return str(int(value))
    if isinstance(value, float | np.floating):
        if math.isnan(float(value)):
            raise ValueError("a calibrated profile cannot hold NaN")
        if math.isinf(float(value)):
            return "inf" if value > 0 else "-inf"
        return repr(float(value))
    if isinstance(value, list | tuple | np.ndarray):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise TypeError(f"cannot write {type(value).__name__} to TOML")


def to_toml(data: dict) -> str:
    """TOML text for the profile's layout: top-level keys, then tables (dict values), then
    arrays of tables (lists of dicts)."""
    lines = []
    tables = {k: v for k, v in data.items() if isinstance(v, dict)}
    arrays = {k: v for k, v in data.items()
              if isinstance(v, list) and v and all(isinstance(i, dict) for i in v)}
    for key, value in data.items():
        if key not in tables and key not in arrays:
            lines.append(f"{key} = {_toml_value(value)}")
    for key, table in tables.items():
        lines += ["", f"[{key}]"] + [f"{k} = {_toml_value(v)}" for k, v in table.items()]
    for key, items in arrays.items():
        for item in items:
            lines += ["", f"[[{key}]]"] + [f"{k} = {_toml_value(v)}" for k, v in item.items()]
    return "\n".join(lines) + "\n"


def profile_dict(suit: CalibratedSuit, description: str = "") -> dict:
    """The profile as plain data in the TOML layout."""
    spec, inputs = suit.spec, suit.inputs
    return {
        "schema": CALIBRATED_SCHEMA,
        "version": CALIBRATED_VERSION,
        "name": suit.name,
        "description": description,
        "units": suit.units,
        "joint": suit.joint,
        "angles": list(suit.angles),
        "rate_hz": suit.rate_hz,
        "effects": list(suit.effects),
        "static_map": {
            "inputs": inputs.input_kind,
            "angle_lo_deg": inputs.angle_lo.tolist(),
            "angle_hi_deg": inputs.angle_hi.tolist(),
            "input_degree": inputs.static_degree,
            "input_local": inputs.static_local,
            "degree": spec.degree,
            "local": spec.local,
            "local_centres": (inputs.centres.tolist()
                              if spec.local or inputs.static_local else []),
            "time_span_s": list(inputs.t_span),
            "segments": inputs.segments.T.tolist(),
        },
        "terms": {
            "hysteresis": spec.hysteresis,
            "hysteresis_degree": spec.hysteresis_degree,
            "hysteresis_on_angles": spec.hysteresis_angles,
            "creep_tau_s": list(spec.creep_tau_s),
            "creep_quadratic": spec.creep_quadratic,
            "creep_build_recover_s": list(spec.creep_asym_s),
            "creep_hold_grow_recover_s": list(spec.creep_hold_s),
            "lag_kind": spec.lag_kind or "none",
            "lag_s": spec.lag_s,
            "lag_delay_s": spec.lag_delay_s,
            "lag_rates_per_s": list(spec.lag_rates),
            "lag_sensors": [suit.sensors[j] for j in spec.lag_sensors],
            "drift_degree": spec.drift_degree,
            "drift_piecewise": spec.drift_piecewise,
            "saturation": spec.saturation,
        },
        "sensor": [
            {"name": name,
             "input_coef": suit.inputs.static_coef[:, j].tolist(),
             "play_thresholds": suit.inputs.thresholds[j].tolist(),
             "static_centre": float(suit.inputs.centre[j]),
             "stops": [suit.stops[j].lo, suit.stops[j].hi],
             "stop_softness": [suit.stops[j].soft_lo, suit.stops[j].soft_hi],
             "stop_shape": [suit.stops[j].shape_lo, suit.stops[j].shape_hi],
             "coef": suit.coef[j].tolist(),
             "noise_sigma": float(suit.noise[j])}
            for j, name in enumerate(suit.sensors)
        ],
    }


def write_calibrated_profile(path: str | Path, suit: CalibratedSuit, description: str = "",
                             ) -> None:
    """Write ``suit`` as TOML (temporary name, renamed when complete)."""
    write_text(path, to_toml(profile_dict(suit, description)))


def _stops(sensor: dict) -> Stops:
    """A sensor table's stops; ``stop_softness`` is optional (hard stops, the first form), and
    so is ``stop_shape`` (tanh knees, the second form)."""
    lo, hi = (float(v) for v in sensor["stops"])
    soft_lo, soft_hi = (float(v) for v in sensor.get("stop_softness", (0.0, 0.0)))
    shape_lo, shape_hi = (str(v) for v in sensor.get("stop_shape", ("tanh", "tanh")))
    if soft_lo < 0 or soft_hi < 0 or lo > hi:
        raise ValueError(f"stops {[lo, hi]} with softness {[soft_lo, soft_hi]}")
    return Stops(lo, hi, soft_lo, soft_hi, shape_lo, shape_hi)


def _lag_kind(name: object) -> str:
    """The ``lag_kind`` term as :class:`Spec` holds it (``none`` → empty)."""
    if name not in LAG_KINDS:
        raise ValueError(f"lag_kind {name!r} is not one of {', '.join(LAG_KINDS)}")
    return "" if name == "none" else str(name)


def _centres(rows: list) -> np.ndarray:
    """The local basis's centres (K, 3) from their rows in the profile (unit vectors of the
    arm direction; none in profiles written before the local basis, or without it)."""
    if not rows:
        return np.zeros((0, 3))
    if any(not isinstance(row, list) or len(row) != 3 for row in rows):
        raise ValueError("local_centres must be rows of three numbers, each a unit vector")
    centres = np.asarray(rows, dtype=np.float64)
    if not np.allclose(np.linalg.norm(centres, axis=1), 1.0, atol=1e-6):
        raise ValueError("local_centres must be rows of three numbers, each a unit vector")
    return centres


def _segments(rows: list, input_kind: str) -> np.ndarray:
    """The static map's straight runs (P₂, K) from their rows in the profile (one list of
    P₂ coefficients per run; none in profiles written before runs were fitted)."""
    n_inputs = 6 if input_kind == "arm_axes" else 0
    p2 = (n_inputs + 1) * (n_inputs + 2) // 2
    if not rows:
        return np.zeros((p2, 0))
    if n_inputs == 0:
        raise ValueError(f"{input_kind!r} inputs have no straight runs (segments)")
    widths = sorted({len(row) for row in rows})
    if widths != [p2]:
        raise ValueError(f"segments need {p2} coefficients each for {input_kind!r} inputs, "
                         f"not {', '.join(map(str, widths))}")
    return np.asarray(rows, dtype=np.float64).T


def _lag_sensors(names: list, sensors: list[str]) -> tuple[int, ...]:
    """The columns of the sensors a low-pass or delay acts on (none listed: every sensor)."""
    unknown = [n for n in names if n not in sensors]
    if unknown:
        raise ValueError(f"lag_sensors {unknown} are not among the sensors {sensors}")
    return tuple(sorted({sensors.index(n) for n in names}))


def load_calibrated_profile(path: str | Path) -> CalibratedSuit:
    """Read a calibrated suit profile; one :class:`ProfileError` line on any problem."""
    path = Path(path)
    data = read_toml(path, "calibrated suit profile")
    if data.get("schema") != CALIBRATED_SCHEMA:
        raise ProfileError(f"{path}: not a calibrated suit profile (schema "
                           f"{CALIBRATED_SCHEMA!r} version {CALIBRATED_VERSION})")
    version = data.get("version")
    if type(version) is not int or version != CALIBRATED_VERSION:  # TOML's true == 1 == 1.0
        raise ProfileError(f"{path}: calibrated suit profile version {data.get('version')!r}; "
                           f"this exohil reads version {CALIBRATED_VERSION}")
    try:
        sm, terms, sensors = data["static_map"], data["terms"], data["sensor"]
        spec = Spec(degree=int(sm["degree"]), local=bool(sm.get("local", False)),
                    hysteresis=bool(terms["hysteresis"]),
                    hysteresis_degree=int(terms.get("hysteresis_degree", 1)),
                    hysteresis_angles=bool(terms.get("hysteresis_on_angles", False)),
                    creep_tau_s=tuple(float(v) for v in terms["creep_tau_s"]),
                    creep_quadratic=bool(terms.get("creep_quadratic", False)),
                    creep_asym_s=tuple(float(v) for v in terms["creep_build_recover_s"]),
                    creep_hold_s=tuple(float(v) for v in
                                       terms.get("creep_hold_grow_recover_s", ())),
                    lag_kind=_lag_kind(terms["lag_kind"]), lag_s=float(terms["lag_s"]),
                    lag_delay_s=float(terms.get("lag_delay_s", 0.0)),
                    lag_rates=tuple(float(v) for v in terms.get("lag_rates_per_s", ())),
                    lag_sensors=_lag_sensors(terms.get("lag_sensors", []),
                                             [str(s["name"]) for s in sensors]),
                    drift_degree=int(terms["drift_degree"]),
                    drift_piecewise=bool(terms.get("drift_piecewise", False)),
                    saturation=bool(terms["saturation"]))
        if spec.hysteresis_degree < 1:
            raise ValueError(f"hysteresis_degree must be 1 or more, not {spec.hysteresis_degree}")
        centred = spec.creep_quadratic or spec.hysteresis_degree > 1  # terms about the centre
        if spec.lag_kind == "rate_limit" and (
                len(spec.lag_rates) != len(sensors) or not all(r > 0 for r in spec.lag_rates)):
            raise ValueError(f"a rate_limit lag needs a positive lag_rates_per_s per sensor "
                             f"({len(sensors)}), not {list(spec.lag_rates)}")
        inputs = Inputs(u=np.empty((0, 0)), input_kind=str(sm["inputs"]),
                        angle_lo=np.asarray(sm["angle_lo_deg"], dtype=np.float64),
                        angle_hi=np.asarray(sm["angle_hi_deg"], dtype=np.float64),
                        static=np.empty(0),
                        static_coef=np.column_stack([s["input_coef"] for s in sensors]),
                        static_degree=int(sm["input_degree"]),
                        static_local=bool(sm.get("input_local", False)),
                        centres=_centres(sm.get("local_centres", [])),
                        thresholds=np.asarray([s["play_thresholds"] for s in sensors]),
                        t_norm=np.empty(0),
                        t_span=(float(sm["time_span_s"][0]), float(sm["time_span_s"][1])),
                        centre=np.asarray([float(s["static_centre"] if centred
                                                 else s.get("static_centre", 0.0))
                                           for s in sensors]),
                        segments=_segments(sm.get("segments", []), str(sm["inputs"])))
        if (spec.local or inputs.static_local) and (
                inputs.input_kind != "arm_direction" or not inputs.centres.size):
            raise ValueError("a static map with the local basis needs arm_direction inputs "
                             "and local_centres")
        counts = {s["name"]: len(s["coef"]) for s in sensors}
        if len(set(counts.values())) > 1:
            raise ValueError(f"sensors have different numbers of coef: {counts}")
        suit = CalibratedSuit(
            name=str(data["name"]), sensors=tuple(s["name"] for s in sensors),
            units=str(data["units"]), joint=str(data["joint"]),
            angles=tuple(str(a) for a in data["angles"]), rate_hz=float(data["rate_hz"]),
            effects=tuple(data["effects"]), spec=spec, inputs=inputs,
            coef=np.asarray([s["coef"] for s in sensors], dtype=np.float64),
            stops=tuple(_stops(s) for s in sensors),
            noise=np.asarray([s["noise_sigma"] for s in sensors], dtype=np.float64))
        _check_numbers(suit)
        _check_coef_counts(suit)
        return suit
    except KeyError as exc:
        raise ProfileError(f"{path}: malformed calibrated suit profile: no {exc} "
                           "(docs/discrepancy.md, Calibrated suit profile)") from exc
    except (TypeError, ValueError, IndexError) as exc:
        raise ProfileError(f"{path}: malformed calibrated suit profile: {exc}") from exc


def load_any_profile(path: str | Path) -> SuitProfile | CalibratedSuit:
    """A suit profile of either schema, by its ``schema`` key: a calibrated one
    (:func:`load_calibrated_profile`) or a geometric one
    (:func:`~exohil.emulators.suit_profile.load_profile`); one :class:`ProfileError` line on
    any problem."""
    path = Path(path)
    schema = read_toml(path, "suit profile").get("schema")
    if schema == CALIBRATED_SCHEMA:
        return load_calibrated_profile(path)
    if schema != PROFILE_SCHEMA:
        raise ProfileError(f"{path}: 'schema' must be \"{PROFILE_SCHEMA}\" (a geometric suit "
                           f"profile) or \"{CALIBRATED_SCHEMA}\" (one `exohil discrepancy` "
                           f"wrote), got {schema!r}")
    return load_profile(path)


def _inputs(suit: CalibratedSuit, t: np.ndarray, angles_deg: np.ndarray) -> Inputs:
    """The model's inputs for angles (N, A) in degrees (``suit.angles`` order) at times t."""
    u, _ = map_inputs(angles_deg, suit.angles, suit.inputs.angle_lo, suit.inputs.angle_hi)
    t0, t1 = suit.inputs.t_span
    inputs = Inputs(u=u, input_kind=suit.inputs.input_kind, angle_lo=suit.inputs.angle_lo,
                    angle_hi=suit.inputs.angle_hi, angles=angles_deg, angle_names=suit.angles,
                    static=np.empty(0),
                    static_coef=suit.inputs.static_coef,
                    static_degree=suit.inputs.static_degree,
                    static_local=suit.inputs.static_local, centres=suit.inputs.centres,
                    thresholds=suit.inputs.thresholds,
                    t_norm=np.clip(2.0 * (t - t0) / (t1 - t0) - 1.0, -1.0, 1.0), t_span=(t0, t1),
                    centre=suit.inputs.centre, segments=suit.inputs.segments,
                    still=holding_still(joint_speed(angles_deg, suit.angles, suit.rate_hz)))
    inputs.static = static_of_map_inputs(inputs, u)
    return inputs


def _check_numbers(suit: CalibratedSuit) -> None:
    """ValueError naming the first number the suit cannot be simulated with: a rate that is
    not a number of Hz in :data:`PROFILE_RATE_HZ`, a nan or inf among the map's numbers
    (every reading would be NaN, found only when the recording is written), a noise sigma
    below 0."""
    lo, hi = PROFILE_RATE_HZ
    if not lo <= suit.rate_hz <= hi:  # also false for nan
        raise ValueError(f"rate_hz must be a positive number of Hz from {lo:g} to {hi:g} "
                         f"(a sensor's sampling rate), not {suit.rate_hz!r}")
    numbers = {"coef": suit.coef, "input_coef": suit.inputs.static_coef,
               "play_thresholds": suit.inputs.thresholds, "static_centre": suit.inputs.centre,
               "angle_lo_deg": suit.inputs.angle_lo, "angle_hi_deg": suit.inputs.angle_hi,
               "time_span_s": np.asarray(suit.inputs.t_span), "noise_sigma": suit.noise}
    for key, values in numbers.items():
        if not np.isfinite(values).all():
            raise ValueError(f"{key} must be finite numbers")
    if (suit.noise < 0).any():
        raise ValueError(f"noise_sigma must be >= 0, not {suit.noise.tolist()}")
    spec = suit.spec
    for key, times in (("lag_s", (spec.lag_s,)), ("lag_delay_s", (spec.lag_delay_s,)),
                       ("creep_tau_s", spec.creep_tau_s),
                       ("creep_build_recover_s", spec.creep_asym_s),
                       ("creep_hold_grow_recover_s", spec.creep_hold_s)):
        if not all(0 <= v < math.inf for v in times):
            raise ValueError(f"{key} must be times >= 0 s, not {list(times)}")


def _check_coef_counts(suit: CalibratedSuit) -> None:
    """ValueError unless ``input_coef`` has one term per column of the static input's basis
    and each sensor one coefficient per column of its model (a design of two frames at the
    neutral pose gives the counts)."""
    neutral = np.zeros((2, len(suit.angles)))
    u, _ = map_inputs(neutral, suit.angles, suit.inputs.angle_lo, suit.inputs.angle_hi)
    n_terms = static_terms(u, suit.inputs.static_degree, suit.inputs.segments,
                           suit.inputs.centres if suit.inputs.static_local else None).shape[1]
    if suit.inputs.static_coef.shape[0] != n_terms:
        runs = suit.inputs.segments.shape[1]
        raise ValueError(f"input_coef has {suit.inputs.static_coef.shape[0]} terms per "
                         f"sensor; the degree-{suit.inputs.static_degree} basis "
                         f"{f'with {runs} straight runs ' if runs else ''}of "
                         f"{', '.join(suit.angles)} has {n_terms}")
    inputs = _inputs(suit, np.arange(2) / suit.rate_hz, neutral)
    for j, name in enumerate(suit.sensors):
        x = design(suit.rate_hz, inputs, suit.spec, j)
        width = x.shared.shape[1] + x.own.shape[1]
        if suit.coef[j].shape != (width,):
            raise ValueError(f"sensor {name} has {suit.coef[j].size} coef; its model "
                             f"({', '.join(suit.effects) or 'static map only'}) has {width}")


def simulate_calibrated(suit: CalibratedSuit, t: np.ndarray, angles_deg: np.ndarray,
                        ) -> np.ndarray:
    """Noise-free sensor values (N, S) in ``suit.units`` for angles (N, A) in degrees (in
    ``suit.angles`` order) sampled uniformly at ``suit.rate_hz`` at times ``t`` (s)."""
    inputs = _inputs(suit, t, angles_deg)
    out = np.empty((t.shape[0], len(suit.sensors)))
    for j in range(len(suit.sensors)):
        out[:, j] = suit.stops[j].apply(design(suit.rate_hz, inputs, suit.spec, j)
                                        .times(suit.coef[j]))
    return out


def _shoulder_angles(suit: CalibratedSuit, trajectory: Trajectory, t: np.ndarray
                     ) -> np.ndarray:
    """(N, A) the angles ``suit`` is driven by, in its order, of a shoulder ``trajectory``
    sampled at times t (s), degrees; ProfileError where the suit is driven by others."""
    missing = [a for a in suit.angles if a not in ANGLE_NAMES]
    if missing:
        raise ProfileError(f"profile {suit.name!r} is driven by {missing}, which a shoulder "
                           "trajectory does not have")
    return trajectory.sample(t)[:, [ANGLE_NAMES.index(a) for a in suit.angles]]


def _sensor_stream(suit: CalibratedSuit, t: np.ndarray, angles_deg: np.ndarray, seed: int,
                   noise: bool) -> SensorStream:
    """The calibrated suit's sensor frames at times ``t`` (uniform at its rate) for
    ``angles_deg`` (:func:`simulate_calibrated`), with its white noise drawn from ``seed``
    (none with ``noise`` False), numbered from 0."""
    clean = Signal.from_values(t, simulate_calibrated(suit, t, angles_deg))
    sigma = suit.noise if noise else np.zeros_like(suit.noise)
    noisy = Noise(sigma_mm=sigma.tolist()).apply(clean, np.random.default_rng(seed))
    return SensorStream(seq=np.arange(t.shape[0]), t=t, values=noisy.values)


def simulate_calibrated_recording(trajectory: Trajectory, suit: CalibratedSuit,
                                  seed: int, noise: bool = True) -> Recording:
    """A recording of the calibrated suit following a shoulder ``trajectory``: sensors at the
    profile's rate with its white noise (none with ``noise`` False), exact angles on
    ``/mocap/shoulder`` at 120 Hz."""
    t = trajectory.frame_times(suit.rate_hz)
    t_mocap = trajectory.frame_times(MOCAP_RATE_HZ)
    return Recording(
        sensor_names=suit.sensors,
        sensors=_sensor_stream(suit, t, _shoulder_angles(suit, trajectory, t), seed, noise),
        mocap={"shoulder": AngleStream(t=t_mocap, names=ANGLE_NAMES,
                                       angles=trajectory.sample(t_mocap))},
        sensor_units=suit.units, sensor_rate_hz=suit.rate_hz, mocap_rate_hz=MOCAP_RATE_HZ,
        segments=list(trajectory.segments),
        metadata={"generator": "exohil.emulators.discrepancy.profile", "seed": str(int(seed)),
                  "trajectory": trajectory.source, "suit_profile": suit.name})


def replay_calibrated_recording(measured: Recording, suit: CalibratedSuit, seed: int,
                                name: str, noise: bool = True) -> Recording:
    """A recording of the calibrated suit following the motion capture of ``measured``, a
    recording of any joint (``name`` names it in messages), on ``measured``'s clock (the
    clock the suit's drift was fitted on, where it has one): ``suit``'s angles on
    ``/mocap/<suit.joint>`` at the samples where all are finite, linearly interpolated
    (across a dropout too) to sensor frames at the profile's rate from the first of them,
    with its white noise (none with ``noise`` False); the angles replayed as recorded, and
    ``measured``'s segments within their span. ValueError where ``measured`` holds no such
    motion."""
    t_mocap, angles_mocap, segments = replayed_motion(measured, suit.joint, suit.angles, name)
    t0 = float(t_mocap[0])
    span = float(t_mocap[-1]) - t0
    t = t0 + np.arange(int(math.floor(span * suit.rate_hz)) + 1) / suit.rate_hz
    angles = np.column_stack([np.interp(t, t_mocap, a) for a in angles_mocap.T])
    return Recording(
        sensor_names=suit.sensors,
        sensors=_sensor_stream(suit, t, angles, seed, noise),
        mocap={suit.joint: AngleStream(t=t_mocap, names=suit.angles, angles=angles_mocap)},
        sensor_units=suit.units, sensor_rate_hz=suit.rate_hz,
        mocap_rate_hz=measured.mocap_rate_hz, segments=segments,
        metadata={"generator": "exohil.emulators.discrepancy.profile", "seed": str(int(seed)),
                  "trajectory": f"replay:{name}", "suit_profile": suit.name})


def outside_calibration(suit: CalibratedSuit, trajectory: Trajectory) -> dict[str, float]:
    """:func:`outside_range` of a shoulder ``trajectory`` sampled at the suit's rate."""
    t = trajectory.frame_times(suit.rate_hz)
    return outside_range(suit, _shoulder_angles(suit, trajectory, t))


def outside_range(suit: CalibratedSuit, angles: np.ndarray) -> dict[str, float]:
    """Per angle the suit is driven by, the share of the frames ``angles`` (N, A; degrees,
    in ``suit.angles`` order) outside the range of that angle the suit was calibrated on,
    where the calibrated map extrapolates, beyond ``RANGE_TOLERANCE_DEG``; only angles with
    such frames. The plane of elevation counts only where the elevation is at least
    :data:`~exohil.kinematics.OBSERVABLE_ELEVATION_DEG` (with the arm hanging it is
    undefined, and any value names the same pose)."""
    lo, hi = suit.inputs.angle_lo, suit.inputs.angle_hi
    outside = (angles < lo - RANGE_TOLERANCE_DEG) | (angles > hi + RANGE_TOLERANCE_DEG)
    if "elv_angle" in suit.angles and "shoulder_elv" in suit.angles:
        hanging = angles[:, suit.angles.index("shoulder_elv")] < OBSERVABLE_ELEVATION_DEG
        outside[hanging, suit.angles.index("elv_angle")] = False
    share = outside.mean(axis=0)
    return {a: float(s) for a, s in zip(suit.angles, share, strict=True) if s > 0}


def calibrated_suit(outcome: Outcome, name: str) -> CalibratedSuit:
    """The final model of a workflow run as a calibrated suit."""
    after, trial = outcome.after, outcome.trial
    return CalibratedSuit(
        name=name, sensors=trial.sensor_names, units=trial.units, joint=trial.joint,
        angles=trial.angle_names, rate_hz=trial.rate_hz,
        effects=tuple(outcome.summary["already_in_model"]) + tuple(outcome.summary["effects"]),
        spec=after.spec, inputs=outcome.inputs,
        coef=np.asarray(after.coef),
        stops=tuple(after.stops),
        noise=np.asarray(outcome.summary["noise_floor_per_sensor"]))
