"""The physical effects blind6 hides in its recordings, one model family at a time.

Every model is an :class:`EffectModel`: its parameters are drawn at construction; ``prepare``
takes one sensor's noise-free signal (strain for effects in the textile, the reading for
effects in the electronics) on the uniform sensor grid and returns ``render(s)``, the signal
with the effect at strength ``s``. The generator chooses ``s`` per sensor so that the effect
leaves a set multiple of the noise SD (see ``generate.magnitude``). See README.md for the laws.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from scipy.signal import bilinear, fftconvolve, lfilter, lfilter_zi

Render = Callable[[float], np.ndarray]
Domain = Literal["strain", "reading"]


@dataclass
class EffectModel:
    """One effect family with drawn parameters.

    Attributes:
        kind: the effect (hysteresis, creep, saturation, lag, drift).
        model: the family's short name.
        domain: ``strain`` (in the textile, before the sensor's transfer) or ``reading``.
        bounds: the physically plausible range of the strength ``s`` (lower, upper).
        strength_unit: what ``s`` measures.
        prepare: (signal, sample times) → ``render(s)``.
        params: the drawn parameters, for the answer key.
    """

    kind: str
    model: str
    domain: Domain
    bounds: tuple[float, float]
    strength_unit: str
    prepare: Callable[[np.ndarray, np.ndarray], Render]
    params: dict[str, float] = field(default_factory=dict)


def _normalised(x: np.ndarray) -> tuple[np.ndarray, float, float]:
    """``x`` scaled to [0, 1] over its range, with its minimum and span."""
    lo, span = float(x.min()), float(np.ptp(x)) or 1.0
    return (x - lo) / span, lo, span


# ----------------------------------------------------------------------------- hysteresis


def preisach(rng: np.random.Generator) -> EffectModel:
    """Preisach loop: a weighted sum of relays (up at α, down at β < α) on the normalised
    strain, weights a Gaussian in loop width α − β and loop centre (α + β) / 2."""
    p = {"width_mean": rng.uniform(0.08, 0.35), "width_sd": rng.uniform(0.04, 0.15),
         "centre": rng.uniform(0.3, 0.7), "centre_sd": rng.uniform(0.2, 0.5)}
    grid = np.linspace(-0.05, 1.05, 17)

    def prepare(x: np.ndarray, _t: np.ndarray) -> Render:
        u, _, span = _normalised(x)
        out = np.zeros_like(u)
        total = 0.0
        index = np.arange(u.size)
        for i, alpha in enumerate(grid):
            for beta in grid[:i]:
                w = np.exp(-0.5 * ((alpha - beta - p["width_mean"]) / p["width_sd"]) ** 2
                           - 0.5 * ((0.5 * (alpha + beta) - p["centre"]) / p["centre_sd"]) ** 2)
                event = np.where(u >= alpha, 1.0, np.where(u <= beta, -1.0, 0.0))
                event[0] = 1.0 if u[0] >= alpha else -1.0
                last = np.maximum.accumulate(np.where(event != 0, index, 0))
                out += w * event[last]
                total += w
        shape = span * out / total
        return lambda s: x + s * shape

    return EffectModel("hysteresis", "preisach", "strain", (1e-4, 0.6),
                       "loop output × strain span", prepare, p)


def _rate_independent(u: np.ndarray, step: Callable[[float, float], float]) -> np.ndarray:
    """Integrate dz = step(z, du) along the input ``u`` (sample by sample)."""
    z = np.empty_like(u)
    value = 0.0
    z[0] = 0.0
    for k, du in enumerate(np.diff(u).tolist(), start=1):
        value += step(value, du)
        z[k] = value
    return z


def bouc_wen(rng: np.random.Generator) -> EffectModel:
    """Rate-independent Bouc–Wen loop on the normalised strain u:
    dz = du − β |du| |z|^(n−1) z − γ du |z|^n, with β + γ = z₀^(−n) so |z| ≤ z₀."""
    n = rng.uniform(1.0, 2.0)
    z0 = rng.uniform(0.05, 0.3)
    beta_share = rng.uniform(0.55, 0.95)
    beta = beta_share / z0**n
    gamma = (1.0 - beta_share) / z0**n
    p = {"n": n, "z0": z0, "beta": beta, "gamma": gamma}

    def step(z: float, du: float) -> float:
        mag = abs(z) ** n
        return du - beta * abs(du) * abs(z) ** (n - 1) * z - gamma * du * mag

    def prepare(x: np.ndarray, _t: np.ndarray) -> Render:
        u, _, span = _normalised(x)
        shape = span * _rate_independent(u, step) / z0
        return lambda s: x + s * shape

    return EffectModel("hysteresis", "bouc-wen", "strain", (1e-4, 0.6),
                       "z/z0 × strain span", prepare, p)


def dahl(rng: np.random.Generator) -> EffectModel:
    """Dahl friction loop on the normalised strain u (yarn-on-yarn friction):
    dz = (du / z₀) · |1 − z sgn du|^i · sgn(1 − z sgn du), z ∈ [−1, 1]."""
    z0 = rng.uniform(0.04, 0.25)
    power = rng.uniform(0.6, 2.0)
    p = {"z0": z0, "i": power}

    def step(z: float, du: float) -> float:
        gap = 1.0 - z * (1.0 if du >= 0 else -1.0)
        return du / z0 * abs(gap) ** power * (1.0 if gap >= 0 else -1.0)

    def prepare(x: np.ndarray, _t: np.ndarray) -> Render:
        u, _, span = _normalised(x)
        shape = span * _rate_independent(u, step)
        return lambda s: x + s * shape

    return EffectModel("hysteresis", "dahl", "strain", (1e-4, 0.6),
                       "friction state × strain span", prepare, p)


# ----------------------------------------------------------------------------- creep


def findley(rng: np.random.Generator) -> EffectModel:
    """Findley power-law creep with Boltzmann superposition: every strain increment Δε at t_k
    adds s · Δε · ((t − t_k + t₀)^n − t₀^n) / 60^n (t in s, t₀ = 0.05 s)."""
    n = rng.uniform(0.15, 0.45)
    p = {"n": n, "t0_s": 0.05}

    def prepare(x: np.ndarray, t: np.ndarray) -> Render:
        dt = float(t[1] - t[0])
        lag = np.arange(x.size) * dt
        kernel = ((lag + 0.05) ** n - 0.05**n) / 60.0**n
        steps = np.diff(x, prepend=x[0])
        shape = fftconvolve(steps, kernel)[: x.size]
        return lambda s: x + s * shape

    return EffectModel("creep", "findley", "strain", (1e-4, 3.0),
                       "creep compliance at 60 s per unit strain step", prepare, p)


def prony(rng: np.random.Generator) -> EffectModel:
    """Viscoelastic relaxation, a three-term Prony series: the signal plus
    sign · s · Σ gᵢ (ε − εᵢ), εᵢ the strain first-order low-passed with τᵢ (1.5–6, 8–30,
    40–150 s). sign +1: overshoot then relaxation after a step; −1: lag then creep on."""
    taus = [rng.uniform(1.5, 6.0), rng.uniform(8.0, 30.0), rng.uniform(40.0, 150.0)]
    weights = rng.dirichlet([2.0, 2.0, 2.0])
    sign = 1.0 if rng.random() < 0.65 else -1.0
    p = {"tau1_s": taus[0], "tau2_s": taus[1], "tau3_s": taus[2], "g1": weights[0],
         "g2": weights[1], "g3": weights[2], "sign": sign}

    def prepare(x: np.ndarray, t: np.ndarray) -> Render:
        dt = float(t[1] - t[0])
        shape = np.zeros_like(x)
        for tau, g in zip(taus, weights, strict=True):
            a = np.exp(-dt / tau)
            low, _ = lfilter([1 - a], [1, -a], x, zi=[a * x[0]])
            shape += g * (x - low)
        return lambda s: x + sign * s * shape

    return EffectModel("creep", "prony", "strain", (1e-4, 1.0),
                       "relaxing share of a strain step", prepare, p)


# ----------------------------------------------------------------------------- saturation


def slack(rng: np.random.Generator) -> EffectModel:
    """The patch goes slack below a length: strain max(ε, ε_s), rounded over 1–3 % of the
    span; ε_s = min + s · span."""
    roundness = rng.uniform(0.01, 0.03)
    p = {"roundness": roundness}

    def prepare(x: np.ndarray, _t: np.ndarray) -> Render:
        _, lo, span = _normalised(x)
        w = roundness * span

        def render(s: float) -> np.ndarray:
            floor = lo + s * span
            return floor + w * np.logaddexp(0.0, (x - floor) / w)

        return render

    return EffectModel("saturation", "slack", "strain", (0.005, 0.6),
                       "share of the strain span below the slack length", prepare, p)


def compressive(rng: np.random.Generator) -> EffectModel:
    """The conductive path saturates at large strain: above a knee ε_k = max − s · span the
    strain reads ε_k + w tanh((ε − ε_k) / w), w = c · s · span, c 0.2–0.5."""
    c = rng.uniform(0.2, 0.5)
    p = {"knee_width_share": c}

    def prepare(x: np.ndarray, _t: np.ndarray) -> Render:
        _, lo, span = _normalised(x)
        hi = lo + span

        def render(s: float) -> np.ndarray:
            knee, w = hi - s * span, c * s * span
            return np.where(x > knee, knee + w * np.tanh((x - knee) / w), x)

        return render

    return EffectModel("saturation", "compressive", "strain", (0.01, 0.7),
                       "share of the strain span above the knee", prepare, p)


def rail(rng: np.random.Generator) -> EffectModel:
    """The amplifier / ADC hits its upper rail: reading min(y, rail), rounded over 0.2–0.6 %
    of the range; rail = max − s · range."""
    roundness = rng.uniform(0.002, 0.006)
    p = {"roundness": roundness}

    def prepare(y: np.ndarray, _t: np.ndarray) -> Render:
        _, lo, span = _normalised(y)
        w = roundness * span

        def render(s: float) -> np.ndarray:
            top = lo + span * (1.0 - s)
            return top - w * np.logaddexp(0.0, (top - y) / w)

        return render

    return EffectModel("saturation", "rail", "reading", (0.005, 0.6),
                       "share of the reading range above the rail", prepare, p)


# ----------------------------------------------------------------------------- lag


def second_order(rng: np.random.Generator) -> EffectModel:
    """Sensor + front-end dynamics: ωₙ² / (s² + 2ζωₙ s + ωₙ²), ζ 0.3–0.9 (underdamped),
    time constant 1/ωₙ = s (bilinear transform, started at rest at the first value)."""
    zeta = rng.uniform(0.3, 0.9)
    p = {"zeta": zeta}

    def prepare(y: np.ndarray, t: np.ndarray) -> Render:
        fs = 1.0 / float(t[1] - t[0])

        def render(s: float) -> np.ndarray:
            wn = 1.0 / s
            b, a = bilinear([wn**2], [1.0, 2 * zeta * wn, wn**2], fs)
            out, _ = lfilter(b, a, y, zi=lfilter_zi(b, a) * y[0])
            return out

        return render

    return EffectModel("lag", "second-order", "reading",
                       (1 / (2 * np.pi * 15.0), 1 / (2 * np.pi * 1.5)), "1/ωn, s", prepare, p)


def moving_average(rng: np.random.Generator) -> EffectModel:
    """Firmware smoothing: a median of 3 then a causal moving average over s seconds."""
    p = {"median_taps": 3.0}

    def prepare(y: np.ndarray, t: np.ndarray) -> Render:
        fs = 1.0 / float(t[1] - t[0])
        padded = np.concatenate([[y[0], y[0]], y])
        median = np.median(np.stack([padded[:-2], padded[1:-1], padded[2:]]), axis=0)

        def render(s: float) -> np.ndarray:
            taps = max(2, int(round(s * fs)))
            csum = np.cumsum(np.concatenate([np.full(taps, median[0]), median]))
            return (csum[taps:] - csum[:-taps]) / taps

        return render

    return EffectModel("lag", "moving-average", "reading", (0.04, 0.3),
                       "window, s", prepare, p)


def transport_delay(rng: np.random.Generator) -> EffectModel:
    """A transport delay (buffering in the wireless link, timestamped on arrival):
    y(t − s), s 20–150 ms, linearly interpolated."""
    p = {"interpolation": 1.0}

    def prepare(y: np.ndarray, t: np.ndarray) -> Render:
        return lambda s: np.interp(t - s, t, y)

    return EffectModel("lag", "transport-delay", "reading", (0.02, 0.15),
                       "delay, s", prepare, p)


# ----------------------------------------------------------------------------- drift


def thermal(rng: np.random.Generator) -> EffectModel:
    """Temperature drift: the garment warms on the skin (first order, τ 40–200 s, from t_on)
    and later partly cools (a draught, τ₂ 30–120 s); baseline and gain follow the temperature:
    y + s · T(t) · (b · range + g · (y − mean y)), b = ±(0.5–1), g = ±(0.3–1)."""
    p = {"tau_s": rng.uniform(40.0, 200.0), "onset_share": rng.uniform(0.0, 0.3),
         "cool_share": rng.uniform(0.5, 0.9), "cool_tau_s": rng.uniform(30.0, 120.0),
         "cool_fraction": rng.uniform(0.0, 0.8),
         "baseline": rng.choice([-1.0, 1.0]) * rng.uniform(0.5, 1.0),
         "gain": rng.choice([-1.0, 1.0]) * rng.uniform(0.3, 1.0)}

    def prepare(y: np.ndarray, t: np.ndarray) -> Render:
        rel = t - t[0]
        dur = float(rel[-1])
        on, cool = p["onset_share"] * dur, p["cool_share"] * dur
        temp = np.where(rel > on, 1 - np.exp(-(rel - on) / p["tau_s"]), 0.0)
        temp -= p["cool_fraction"] * np.where(rel > cool,
                                              1 - np.exp(-(rel - cool) / p["cool_tau_s"]), 0.0)
        span = float(np.ptp(y)) or 1.0
        shape = temp * (p["baseline"] * span + p["gain"] * (y - y.mean()))
        return lambda s: y + s * shape

    return EffectModel("drift", "thermal", "reading", (1e-5, 2.0),
                       "share of the range per unit temperature", prepare, p)


def random_walk(rng: np.random.Generator) -> EffectModel:
    """A random-walk baseline (contact resistance wandering): a Gaussian walk with one step a
    second, linearly interpolated and smoothed over 5 s, scaled by s · range."""
    seed = int(rng.integers(2**31))
    p = {"walk_seed": float(seed)}

    def prepare(y: np.ndarray, t: np.ndarray) -> Render:
        rel = t - t[0]
        knots = np.arange(0.0, rel[-1] + 2.0)
        walk = np.cumsum(np.random.default_rng(seed).standard_normal(knots.size))
        walk -= walk[0]
        base = np.interp(rel, knots, walk)
        taps = max(1, int(round(5.0 / float(t[1] - t[0]))))
        csum = np.cumsum(np.concatenate([np.full(taps, base[0]), base]))
        base = (csum[taps:] - csum[:-taps]) / taps
        shape = base / (np.abs(base).max() or 1.0) * (float(np.ptp(y)) or 1.0)
        return lambda s: y + s * shape

    return EffectModel("drift", "random-walk", "reading", (1e-5, 2.0),
                       "largest excursion / range", prepare, p)


def ramp(rng: np.random.Generator) -> EffectModel:
    """A linear baseline ramp from a start time, with a little curvature:
    s · range · v (1 + c v), v = (t − t_start) / (t_end − t_start) ≥ 0, c −0.3–0.3."""
    p = {"start_share": rng.uniform(0.0, 0.4), "curvature": rng.uniform(-0.3, 0.3),
         "sign": rng.choice([-1.0, 1.0])}

    def prepare(y: np.ndarray, t: np.ndarray) -> Render:
        rel = (t - t[0]) / float(t[-1] - t[0])
        v = np.clip((rel - p["start_share"]) / (1 - p["start_share"]), 0.0, None)
        shape = p["sign"] * (float(np.ptp(y)) or 1.0) * v * (1 + p["curvature"] * v)
        return lambda s: y + s * shape

    return EffectModel("drift", "ramp", "reading", (1e-5, 2.0),
                       "ramp height / range", prepare, p)


MODELS: dict[str, list[Callable[[np.random.Generator], EffectModel]]] = {
    "hysteresis": [preisach, bouc_wen, dahl],
    "creep": [findley, prony],
    "saturation": [slack, compressive, rail],
    "lag": [second_order, moving_average, transport_delay],
    "drift": [thermal, random_walk, ramp],
}
