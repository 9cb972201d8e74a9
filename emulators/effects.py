"""Effect library: the suit's and the wire's nonlinearities as small, composable units.

Every effect is a dataclass whose fields are its physical parameters (units in the names),
applied to a whole :class:`Signal` at once and returning a new one (inputs are never
modified). Parameters marked "per sensor" accept a scalar (all sensors) or a list with one
value per sensor column. Random effects draw only from the ``rng`` they are given; an
:class:`EffectChain` derives that generator from ``(seed, kind, occurrence)`` so that adding,
removing or reordering other effects never reseeds an effect's random stream.

Effects (registry key → class): ``hysteresis`` → :class:`Hysteresis`, ``creep`` →
:class:`Creep`, ``saturation`` → :class:`Saturation`, ``lag`` → :class:`Lag`, ``drift`` →
:class:`Drift`, ``noise`` → :class:`Noise`, ``quantization`` → :class:`Quantization`,
``dropout`` → :class:`Dropout`, ``gain`` → :class:`Gain`. Serialise with :func:`effect_to_dict` /
:func:`effect_from_dict` (``{"kind": "creep", "tau_build_s": 20.0, ...}``).
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np

from exohil.emulators.seeding import keyed_rng

PerSensor = float | list[float]


@dataclass
class Signal:
    """A sensor series on the sensor (device) clock.

    Attributes:
        t: (N,) float64 seconds, sensor clock, increasing.
        values: (N, S) float64 sensor values, mm.
        keep: (N,) bool; False marks a frame that is dropped (never sent).
    """

    t: np.ndarray
    values: np.ndarray
    keep: np.ndarray

    @classmethod
    def from_values(cls, t: np.ndarray, values: np.ndarray) -> Signal:
        """A signal with every frame kept; ``values`` is (N, S) mm or (N,) for one sensor."""
        values = np.asarray(values, dtype=np.float64)
        if values.ndim == 1:
            values = values[:, None]
        t = np.asarray(t, dtype=np.float64)
        if values.ndim != 2 or t.shape != (values.shape[0],):
            raise ValueError(f"t must be (N,) and values (N, S); got {t.shape} and {values.shape}")
        return cls(t=t, values=values, keep=np.ones(t.shape[0], dtype=bool))

    @property
    def n_sensors(self) -> int:
        return int(self.values.shape[1])

    def with_values(self, values: np.ndarray) -> Signal:
        """The same frames with new values."""
        return Signal(t=self.t, values=values, keep=self.keep)


@runtime_checkable
class Effect(Protocol):
    """One nonlinearity: ``name`` is its registry key; ``apply`` returns a new signal."""

    name: str

    def apply(self, signal: Signal, rng: np.random.Generator) -> Signal: ...


def per_sensor(value: Any, n_sensors: int, label: str) -> np.ndarray:
    """A scalar or per-sensor list as an (S,) float64 array; clear error on a length mismatch."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 0:
        return np.full(n_sensors, float(arr))
    if arr.shape != (n_sensors,):
        raise ValueError(f"{label}: expected a number or a list of {n_sensors} values, "
                         f"got {value!r}")
    return arr


def _check(condition: bool, message: str) -> None:
    if not condition:
        raise ValueError(message)


def _all(value: Any, predicate) -> bool:
    return bool(np.all(predicate(np.asarray(value, dtype=np.float64))))


def _sample_period_s(t: np.ndarray) -> float:
    """Nominal sample period (median spacing), seconds; 1.0 for a single frame."""
    return float(np.median(np.diff(t))) if t.shape[0] > 1 else 1.0


#: The most play operators a :class:`Hysteresis` takes: its memory grows with frames ×
#: sensors × operators, and the loop shape is smooth long before this.
MAX_HYSTERESIS_OPERATORS = 64


@dataclass
class Hysteresis:
    """Rate-independent hysteresis of fabric and skin (Prandtl–Ishlinskii play operators).

    After a reversal the output first lags the input, then crosses over to the other branch;
    on the rising branch the reading is ``width_mm / 2`` below the input, on the falling branch
    ``width_mm / 2`` above it, so the loop's full width (falling − rising) after a large
    excursion is exactly ``width_mm``. ``operators`` play operators with thresholds evenly
    spaced up to ``span_mm / 2`` (equal weights) make the crossover gradual: it completes
    after ``span_mm`` of input travel since the last reversal, and minor loops for smaller
    reversals are narrower. The operators start relaxed at the first sample. Depends only on
    the sequence of values (reversal history), never on time or speed.

    Attributes:
        width_mm: full loop width, mm (per sensor, ≥ 0).
        span_mm: input travel after a reversal to reach the other branch, mm (per sensor, > 0).
        operators: number of play operators (1..:data:`MAX_HYSTERESIS_OPERATORS`).
    """

    name: ClassVar[str] = "hysteresis"
    width_mm: PerSensor = 2.0
    span_mm: PerSensor = 10.0
    operators: int = 4

    def __post_init__(self) -> None:
        _check(_all(self.width_mm, lambda v: v >= 0), "hysteresis: width_mm must be >= 0")
        _check(_all(self.span_mm, lambda v: v > 0), "hysteresis: span_mm must be > 0")
        _check(int(self.operators) == self.operators
               and 1 <= self.operators <= MAX_HYSTERESIS_OPERATORS,
               f"hysteresis: operators must be an integer 1..{MAX_HYSTERESIS_OPERATORS}")

    def apply(self, signal: Signal, rng: np.random.Generator) -> Signal:
        x = signal.values
        n, s = x.shape
        width = per_sensor(self.width_mm, s, "hysteresis.width_mm")
        span = per_sensor(self.span_mm, s, "hysteresis.span_mm")
        fractions = np.arange(1, self.operators + 1) / self.operators
        thresholds = (span[:, None] / 2.0) * fractions[None, :]  # (S, K) mm
        if n == 0:
            return signal.with_values(x.copy())
        lower = (x[:, :, None] - thresholds).reshape(n, -1)
        upper = (x[:, :, None] + thresholds).reshape(n, -1)
        play = np.empty_like(lower)
        play[0] = np.repeat(x[0], self.operators)
        for i in range(1, n):  # sequential over time, vectorised over sensors × operators
            np.maximum(play[i - 1], lower[i], out=play[i])
            np.minimum(play[i], upper[i], out=play[i])
        lead = (x[:, :, None] - play.reshape(n, s, -1)) / thresholds  # in [-1, 1]
        return signal.with_values(x - 0.5 * width * lead.mean(axis=2))


@dataclass
class Creep:
    """Viscoelastic creep of fabric and skin under the string pot's constant (~1.9 N) spring.

    A creep displacement ``c`` (mm, added to the reading) relaxes toward ``gain × stretch``,
    where stretch is the reading minus its first sample (mm). While ``|c|`` grows toward the
    target it moves with time constant ``tau_build_s``; while it shrinks (the stretch was
    released) it recovers with ``tau_recover_s`` (usually longer, so some deformation outlives
    the movement). Sustained stretch therefore builds up an offset over seconds to tens of
    seconds; brief excursions barely register.

    Attributes:
        gain: steady-state creep per mm of stretch (dimensionless, per sensor; may be < 0).
        tau_build_s: build-up time constant, s (per sensor, > 0).
        tau_recover_s: recovery time constant, s (per sensor, > 0).
    """

    name: ClassVar[str] = "creep"
    gain: PerSensor = 0.05
    tau_build_s: PerSensor = 20.0
    tau_recover_s: PerSensor = 60.0

    def __post_init__(self) -> None:
        _check(_all(self.tau_build_s, lambda v: v > 0), "creep: tau_build_s must be > 0")
        _check(_all(self.tau_recover_s, lambda v: v > 0), "creep: tau_recover_s must be > 0")

    def apply(self, signal: Signal, rng: np.random.Generator) -> Signal:
        x = signal.values
        n, s = x.shape
        if n == 0:
            return signal.with_values(x.copy())
        gain = per_sensor(self.gain, s, "creep.gain")
        tau_b = per_sensor(self.tau_build_s, s, "creep.tau_build_s")
        tau_r = per_sensor(self.tau_recover_s, s, "creep.tau_recover_s")
        target = gain * (x - x[0])
        dt = np.diff(signal.t, prepend=signal.t[0])[:, None]  # (N, 1) s; 0 for the first frame
        alpha_build = (-np.expm1(-dt / tau_b)).T.tolist()  # per sensor: step fractions
        alpha_recover = (-np.expm1(-dt / tau_r)).T.tolist()
        creep = np.empty_like(x)
        for j in range(s):  # a scalar recurrence per sensor: cheaper in plain floats than numpy
            tgt, a_b, a_r = target[:, j].tolist(), alpha_build[j], alpha_recover[j]
            out = [0.0] * n
            c = 0.0
            for i in range(n):
                d = tgt[i] - c
                growing = abs(tgt[i]) > abs(c) and tgt[i] * c >= 0.0
                c += (a_b[i] if growing else a_r[i]) * d
                out[i] = c
            creep[:, j] = out
        return signal.with_values(x + creep)


@dataclass
class Saturation:
    """Physical stops: the sensor cannot travel below ``lower_mm`` or above ``upper_mm``.

    The paper's prototype had such stops on the termination base. Limits are absolute readings
    in mm (per sensor); ``None`` means no stop on that side.
    """

    name: ClassVar[str] = "saturation"
    lower_mm: PerSensor | None = None
    upper_mm: PerSensor | None = None

    def __post_init__(self) -> None:
        if self.lower_mm is None or self.upper_mm is None:
            return
        lo, hi = np.asarray(self.lower_mm, dtype=np.float64), np.asarray(self.upper_mm,
                                                                          dtype=np.float64)
        if lo.ndim == 0 or hi.ndim == 0 or lo.shape == hi.shape:  # else: apply names the length
            _check(not np.any(lo > hi), "saturation: lower_mm must not exceed upper_mm")

    def apply(self, signal: Signal, rng: np.random.Generator) -> Signal:
        s = signal.n_sensors
        lo = np.full(s, -np.inf) if self.lower_mm is None else per_sensor(
            self.lower_mm, s, "saturation.lower_mm")
        hi = np.full(s, np.inf) if self.upper_mm is None else per_sensor(
            self.upper_mm, s, "saturation.upper_mm")
        if np.any(lo > hi):
            raise ValueError("saturation: lower_mm must not exceed upper_mm")
        return signal.with_values(np.clip(signal.values, lo, hi))


@dataclass
class Lag:
    """Response lag and timing: first-order low-pass, transport delay, clock offset.

    The reading is the tendon length low-pass filtered with time constant ``tau_s`` (string,
    sheath and fabric take time to follow), then delayed by ``delay_s`` (the value sent at time
    t is the filtered length at t − delay_s; before the first sample the first value holds).
    Finally ``clock_offset_s`` is added to the timestamps: the sensor clock runs ahead of the
    motion-capture clock by that much. The filter assumes uniform sampling (median period).

    Attributes:
        tau_s: low-pass time constant, s (per sensor, ≥ 0; 0 = none).
        delay_s: transport delay, s (per sensor, ≥ 0).
        clock_offset_s: sensor clock minus motion-capture clock, s (one value).
    """

    name: ClassVar[str] = "lag"
    tau_s: PerSensor = 0.0
    delay_s: PerSensor = 0.0
    clock_offset_s: float = 0.0

    def __post_init__(self) -> None:
        _check(_all(self.tau_s, lambda v: v >= 0), "lag: tau_s must be >= 0")
        _check(_all(self.delay_s, lambda v: v >= 0), "lag: delay_s must be >= 0")
        _check(isinstance(self.clock_offset_s, int | float), "lag: clock_offset_s is one number")

    def apply(self, signal: Signal, rng: np.random.Generator) -> Signal:
        # here, not at the top: scipy.signal takes half a second to import, and every
        # command line reads this module for the effect kinds (``exohil --help`` included)
        from scipy.signal import lfilter, lfilter_zi

        x = signal.values
        n, s = x.shape
        if n == 0:
            return signal
        tau = per_sensor(self.tau_s, s, "lag.tau_s")
        delay = per_sensor(self.delay_s, s, "lag.delay_s")
        period = _sample_period_s(signal.t)
        out = x.copy()
        for j in range(s):
            if tau[j] > 0:  # exact for an input held between samples (step-invariant)
                pole = math.exp(-period / tau[j])
                b, a = [0.0, 1.0 - pole], [1.0, -pole]
                out[:, j], _ = lfilter(b, a, x[:, j], zi=lfilter_zi(b, a) * x[0, j])
            if delay[j] > 0:
                out[:, j] = np.interp(signal.t - delay[j], signal.t, out[:, j])
        return Signal(t=signal.t + float(self.clock_offset_s), values=out, keep=signal.keep)


@dataclass
class Drift:
    """Slow offset change independent of motion (sensor electronics, slipping anchors).

    offset(t) = ``rate_mm_per_s`` · (t − t₀) + a Gaussian random walk whose standard deviation
    grows as ``walk_mm_per_sqrt_s`` · √(t − t₀). Zero at the first sample.
    """

    name: ClassVar[str] = "drift"
    rate_mm_per_s: PerSensor = 0.0
    walk_mm_per_sqrt_s: PerSensor = 0.0

    def __post_init__(self) -> None:
        _check(_all(self.walk_mm_per_sqrt_s, lambda v: v >= 0), "drift: walk must be >= 0")

    def apply(self, signal: Signal, rng: np.random.Generator) -> Signal:
        n, s = signal.values.shape
        rate = per_sensor(self.rate_mm_per_s, s, "drift.rate_mm_per_s")
        walk = per_sensor(self.walk_mm_per_sqrt_s, s, "drift.walk_mm_per_sqrt_s")
        if n == 0:
            return signal
        elapsed = (signal.t - signal.t[0])[:, None]
        dt = np.diff(signal.t, prepend=signal.t[0])[:, None]
        steps = rng.standard_normal((n, s)) * walk * np.sqrt(dt)
        return signal.with_values(signal.values + rate * elapsed + np.cumsum(steps, axis=0))


@dataclass
class Noise:
    """White Gaussian measurement noise with standard deviation ``sigma_mm`` (per sensor)."""

    name: ClassVar[str] = "noise"
    sigma_mm: PerSensor = 0.1

    def __post_init__(self) -> None:
        _check(_all(self.sigma_mm, lambda v: v >= 0), "noise: sigma_mm must be >= 0")

    def apply(self, signal: Signal, rng: np.random.Generator) -> Signal:
        sigma = per_sensor(self.sigma_mm, signal.n_sensors, "noise.sigma_mm")
        return signal.with_values(signal.values + rng.standard_normal(signal.values.shape) * sigma)


@dataclass
class Quantization:
    """ADC quantisation: a ``bits``-bit converter spanning the pot's travel.

    Code k reads as ``zero_mm + k · travel_mm / 2**bits`` for k = 0 … 2**bits − 1 (rounded to
    the nearest code; values beyond the ends clip). The Arduino Due's ADC has 12 bits.

    Attributes:
        bits: ADC resolution (1 … 24).
        travel_mm: the pot's full travel mapped onto the ADC range, mm (per sensor, > 0).
        zero_mm: reading at code 0, mm (per sensor).
    """

    name: ClassVar[str] = "quantization"
    bits: int = 12
    travel_mm: PerSensor = 500.0
    zero_mm: PerSensor = 0.0

    def __post_init__(self) -> None:
        _check(int(self.bits) == self.bits and 1 <= self.bits <= 24,
               "quantization: bits must be an integer in 1..24")
        _check(_all(self.travel_mm, lambda v: v > 0), "quantization: travel_mm must be > 0")

    def apply(self, signal: Signal, rng: np.random.Generator) -> Signal:
        s = signal.n_sensors
        levels = 2 ** int(self.bits)
        step = per_sensor(self.travel_mm, s, "quantization.travel_mm") / levels
        zero = per_sensor(self.zero_mm, s, "quantization.zero_mm")
        codes = np.clip(np.floor((signal.values - zero) / step + 0.5), 0, levels - 1)
        return signal.with_values(zero + codes * step)


@dataclass
class Dropout:
    """Frames lost between the device and the host (sets ``keep`` to False).

    Losses come in bursts: a two-state (Gilbert) process whose long-run fraction of dropped
    frames is ``rate`` and whose burst lengths are geometric with mean ``mean_burst_frames``.
    Runs of kept frames last at least one frame, so the achievable rate is at most
    B / (B + 1) for mean burst length B (e.g. 0.5 for isolated drops).
    """

    name: ClassVar[str] = "dropout"
    rate: float = 0.001
    mean_burst_frames: float = 1.0

    def __post_init__(self) -> None:
        _check(0.0 <= self.rate < 1.0, "dropout: rate must be in [0, 1)")
        _check(self.mean_burst_frames >= 1.0, "dropout: mean_burst_frames must be >= 1")

    def apply(self, signal: Signal, rng: np.random.Generator) -> Signal:
        n = signal.t.shape[0]
        if self.rate == 0.0 or n == 0:
            return signal
        mean_bad = float(self.mean_burst_frames)
        mean_good = mean_bad * (1.0 - self.rate) / self.rate
        pairs = int(n / (mean_good + mean_bad)) + 16
        lengths = np.empty(0, dtype=np.int64)
        while lengths.sum() < n:  # alternate good/bad runs until they cover the series
            good = rng.geometric(1.0 / mean_good, size=pairs) if mean_good > 1 else np.ones(pairs)
            bad = rng.geometric(1.0 / mean_bad, size=pairs)
            # A run longer than the series counts as the whole series: the cap keeps a rare
            # event (tiny rate, runs of ~1e12 frames or numpy's saturated int64) from asking
            # np.repeat for terabytes.
            runs = np.minimum(np.column_stack([good, bad]).ravel(), n)
            lengths = np.concatenate([lengths, runs])
        start_bad = rng.random() < self.rate
        states = np.resize(np.array([start_bad, not start_bad]), lengths.shape[0])
        kept = ~np.repeat(states, lengths.astype(np.int64))[:n]
        return Signal(t=signal.t, values=signal.values, keep=signal.keep & kept)


@dataclass
class Gain:
    """The string pot's transfer and its zero after a donning: out = ``gain`` · in + ``offset_mm``.

    A new wearer or a new donning changes where each pot's string sits when the arm hangs (its
    zero) and, through the routing and the pot's calibration, how many mm of reading one mm of
    tendon travel gives. Deterministic (draws nothing from ``rng``).

    Attributes:
        gain: reading per mm of input (dimensionless, per sensor, > 0 and finite).
        offset_mm: added to the reading after the gain, mm (per sensor, finite).
    """

    name: ClassVar[str] = "gain"
    gain: PerSensor = 1.0
    offset_mm: PerSensor = 0.0

    def __post_init__(self) -> None:
        _check(_all(self.gain, lambda v: np.isfinite(v) & (v > 0)),
               "gain: gain must be > 0 and finite")
        _check(_all(self.offset_mm, np.isfinite), "gain: offset_mm must be finite")

    def apply(self, signal: Signal, rng: np.random.Generator) -> Signal:
        s = signal.n_sensors
        gain = per_sensor(self.gain, s, "gain.gain")
        offset = per_sensor(self.offset_mm, s, "gain.offset_mm")
        return signal.with_values(gain * signal.values + offset)


EFFECT_TYPES: dict[str, type] = {
    cls.name: cls
    for cls in (Hysteresis, Creep, Saturation, Lag, Drift, Noise, Quantization, Dropout,
                Gain)
}


#: The largest magnitude of an effect's (or a frame fault's) parameter: far beyond any
#: meaningful rate, duration (s, ms), width (mm) or count, small enough that no arithmetic on
#: it overflows.
MAX_PARAMETER = 1e9


def check_parameter(kind: str, name: str, value: Any) -> None:
    """ValueError unless ``value`` is a finite number (or a list of them) within
    ±:data:`MAX_PARAMETER`; a bool is not a number."""
    for item in value if isinstance(value, list) and value else [value]:
        if isinstance(item, bool) or not isinstance(item, int | float):
            raise ValueError(f"{kind}: {name} must be a number (or a list of numbers), "
                             f"got {value!r}")
        if not (math.isfinite(item) and abs(item) <= MAX_PARAMETER):
            raise ValueError(f"{kind}: {name} must be a finite number within "
                             f"±{MAX_PARAMETER:g}, got {item!r}")


def effect_from_dict(d: dict) -> Effect:
    """Build an effect from ``{"kind": <registry key>, <parameter>: <value>, ...}``.

    Every parameter must be a finite number, or a list of them, within ±:data:`MAX_PARAMETER`
    (a suit profile's ``nan`` or ``inf`` would otherwise turn whole recordings into NaN or
    clipped garbage). Raises ValueError naming the kind or parameter that is wrong.
    """
    if not isinstance(d, dict) or "kind" not in d:
        raise ValueError(f"an effect needs a 'kind' (one of {', '.join(EFFECT_TYPES)}); got {d!r}")
    params = dict(d)
    kind = params.pop("kind")
    cls = EFFECT_TYPES.get(kind)
    if cls is None:
        raise ValueError(f"unknown effect kind {kind!r}; known: {', '.join(EFFECT_TYPES)}")
    allowed = [f.name for f in dataclasses.fields(cls)]
    unknown = sorted(set(params) - set(allowed))
    if unknown:
        raise ValueError(f"{kind}: unknown parameter(s) {', '.join(unknown)}; "
                         f"allowed: {', '.join(allowed)}")
    per_sensor_fields = {f.name for f in dataclasses.fields(cls) if "PerSensor" in str(f.type)}
    for name, value in params.items():
        check_parameter(kind, name, value)
        if isinstance(value, list) and name not in per_sensor_fields:
            raise ValueError(f"{kind}: {name} takes one number, got {value!r}")
    return cls(**params)


def effect_to_dict(e: Effect) -> dict:
    """The inverse of :func:`effect_from_dict`: ``{"kind": e.name, <parameters>...}``."""
    out: dict[str, Any] = {"kind": e.name}
    for f in dataclasses.fields(e):  # type: ignore[arg-type]  # every Effect is a dataclass
        value = getattr(e, f.name)
        if value is not None:
            out[f.name] = list(value) if isinstance(value, tuple | np.ndarray) else value
    return out


@dataclass
class EffectChain:
    """Effects applied in order; each draws from its own generator
    (:func:`~exohil.emulators.seeding.keyed_rng`), so adding or removing one effect leaves the
    others' random streams unchanged."""

    effects: list[Effect] = field(default_factory=list)

    def apply(self, signal: Signal, seed: int) -> Signal:
        seen: dict[str, int] = {}
        for effect in self.effects:
            occurrence = seen.get(effect.name, 0)
            seen[effect.name] = occurrence + 1
            signal = effect.apply(signal, keyed_rng(seed, effect.name, occurrence))
        return signal

    def to_dicts(self) -> list[dict]:
        return [effect_to_dict(e) for e in self.effects]

    @classmethod
    def from_dicts(cls, dicts: list[dict]) -> EffectChain:
        return cls([effect_from_dict(d) for d in dicts])

    def to_json(self) -> str:
        """Canonical JSON (sorted keys, compact) for provenance metadata."""
        return json.dumps(self.to_dicts(), sort_keys=True, separators=(",", ":"))

    def without(self, *kinds: str) -> EffectChain:
        """A copy without the effects of the given kinds (e.g. for ablations)."""
        return EffectChain([e for e in self.effects if e.name not in kinds])
