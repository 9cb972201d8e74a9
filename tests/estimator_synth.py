"""Small synthetic recordings for the estimator tests (not a suit model: just enough structure
— smooth angles, nonlinear sensors with backlash hysteresis — to exercise the code)."""

from __future__ import annotations

import numpy as np

from exohil.formats.recording import AngleStream, Recording, Segment, SensorStream


def play(u: np.ndarray, r: float) -> np.ndarray:
    """Backlash (play) operator of half-width r applied to a 1-D signal."""
    out = np.empty_like(u)
    p = u[0]
    for i, v in enumerate(u):
        p = min(v + r, max(v - r, p))
        out[i] = p
    return out


def shoulder_recording(
    seconds: float = 20.0, rate: float = 250.0, n_sensors: int = 4, seed: int = 0,
    offset_mm: float = 0.0, hysteresis: float = 8.0,
) -> Recording:
    """θ/φ sweeps in two segments; sensors = quadratic maps of hysteretic angles (mm)."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * rate)) / rate
    theta = 40 * np.sin(2 * np.pi * 0.21 * t + rng.uniform(0, 6)) + 10
    phi = 35 * np.sin(2 * np.pi * 0.33 * t + rng.uniform(0, 6)) + 50
    values = np.empty((t.shape[0], n_sensors))
    for s in range(n_sensors):
        a, b = np.cos(s * 1.3), np.sin(s * 1.3)
        lag = play(a * theta + b * phi, hysteresis)
        values[:, s] = 100 + 0.4 * lag + 0.002 * lag**2 + offset_mm + rng.normal(0, 0.05, t.size)
    mt = np.arange(0, seconds, 1 / 120.0)
    angles = np.stack([np.interp(mt, t, theta), np.interp(mt, t, phi), np.zeros_like(mt)], 1)
    return Recording(
        sensor_names=tuple("F SF SR R X Y Z W".split()[:n_sensors]),
        sensors=SensorStream(np.arange(t.size, dtype=np.int64), t, values),
        mocap={"shoulder": AngleStream(mt, ("elv_angle", "shoulder_elv", "shoulder_rot"), angles)},
        sensor_rate_hz=rate,
        segments=[Segment("abduction", 0.0, seconds / 2), Segment("flexion", seconds / 2, seconds)],
    )
