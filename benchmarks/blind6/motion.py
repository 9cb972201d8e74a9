"""Joint motion for the blind6 recordings: reaches, holds, repeated cycles and sweeps.

A trajectory is built from blocks on a 1 kHz grid, in degrees, one column per joint angle:

* ``reach``: a minimum-jerk move to a random target at a slow (15–60 °/s peak) or fast
  (120–320 °/s peak) speed, followed by a hold of 2–20 s (sometimes a short 0.4–2 s pause);
* ``cycles``: 6–17 moves back and forth between the current pose and a target, each half
  0.35–4 s long, with reversal pauses of 0–0.5 s;
* ``sweep``: a minimum-jerk move to a random pose, then a chirped sinusoid about it,
  0.15–1.2 Hz, 8–30 s, faded in and out.

Holds carry a slow postural sway (low-pass noise, 0.1–0.6°), and the whole trajectory a small
physiological tremor (8–11 Hz, 0.03–0.15°). Angles are kept within the joint's limits.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

MOTION_RATE_HZ = 1000.0


@dataclass(frozen=True)
class JointRange:
    """The angles a joint moves through, degrees: names, lower and upper limits, rest pose."""

    names: tuple[str, ...]
    low: np.ndarray
    high: np.ndarray
    rest: np.ndarray


def min_jerk(start: np.ndarray, end: np.ndarray, n: int) -> np.ndarray:
    """``n`` samples (n, D) of a minimum-jerk move from ``start`` to ``end`` (end included)."""
    s = np.linspace(0.0, 1.0, max(n, 2))[1:, None]
    h = 10 * s**3 - 15 * s**4 + 6 * s**5
    return start + (end - start) * h


def sway(rng: np.random.Generator, n: int, dims: int, sd: float) -> np.ndarray:
    """Slow postural sway (n, D): white noise low-passed at about 0.3 Hz, scaled to ``sd``°."""
    a = np.exp(-2 * np.pi * 0.3 / MOTION_RATE_HZ)
    raw = lfilter([1 - a], [1, -a], rng.standard_normal((n, dims)), axis=0)
    raw = lfilter([1 - a], [1, -a], raw, axis=0)
    scale = raw.std(axis=0) + 1e-12
    return sd * (raw - raw[:1]) / scale


def move_samples(rng: np.random.Generator, start: np.ndarray, end: np.ndarray,
                 fast: bool) -> int:
    """Samples of a minimum-jerk move between two poses at a random slow or fast peak speed
    (a minimum-jerk move peaks at 1.875 × distance / duration)."""
    peak = rng.uniform(120.0, 320.0) if fast else rng.uniform(15.0, 60.0)
    distance = float(np.max(np.abs(end - start)))
    seconds = max(0.25, 1.875 * distance / peak)
    return int(seconds * MOTION_RATE_HZ)


def target(rng: np.random.Generator, joint: JointRange) -> np.ndarray:
    """A random pose within the joint's limits (kept 3 % inside them)."""
    margin = 0.03 * (joint.high - joint.low)
    return rng.uniform(joint.low + margin, joint.high - margin)


def trajectory(rng: np.random.Generator, joint: JointRange, seconds: float) -> np.ndarray:
    """A trajectory of ``seconds`` (samples at :data:`MOTION_RATE_HZ`, shape (N, D)), starting
    with a 3–8 s rest hold, then random reach / cycles / sweep blocks."""
    dims = len(joint.names)
    total = int(seconds * MOTION_RATE_HZ) + 1
    pose = joint.rest.astype(float)
    pieces = [np.repeat(pose[None], int(rng.uniform(3.0, 8.0) * MOTION_RATE_HZ), axis=0)]
    count = pieces[0].shape[0]
    while count < total:
        kind = rng.choice(["reach", "reach", "cycles", "sweep"])
        if kind == "reach":
            goal = target(rng, joint)
            piece = min_jerk(pose, goal, move_samples(rng, pose, goal, rng.random() < 0.45))
            hold_s = rng.uniform(2.0, 20.0) if rng.random() < 0.75 else rng.uniform(0.4, 2.0)
            hold = np.repeat(goal[None], int(hold_s * MOTION_RATE_HZ), axis=0)
            hold += sway(rng, hold.shape[0], dims, rng.uniform(0.1, 0.6))
            piece = np.vstack([piece, hold])
        elif kind == "cycles":
            goal = target(rng, joint)
            fast = rng.random() < 0.5
            parts = []
            ends = [pose, goal]
            for k in range(int(rng.integers(6, 18))):
                a, b = ends[k % 2], ends[(k + 1) % 2]
                half_s = rng.uniform(0.35, 1.0) if fast else rng.uniform(1.2, 4.0)
                half = int(half_s * MOTION_RATE_HZ)
                parts.append(min_jerk(a, b, half))
                pause = int(rng.uniform(0.0, 0.5) * MOTION_RATE_HZ)
                parts.append(np.repeat(b[None], pause, axis=0))
            piece = np.vstack(parts)
        else:
            centre = target(rng, joint)
            lead = min_jerk(pose, centre, move_samples(rng, pose, centre, rng.random() < 0.5))
            pose = centre
            n = int(rng.uniform(8.0, 30.0) * MOTION_RATE_HZ)
            tt = np.arange(1, n + 1) / MOTION_RATE_HZ
            f0, f1 = np.sort(rng.uniform(0.15, 1.2, size=2))
            phase = 2 * np.pi * (f0 * tt + (f1 - f0) * tt**2 / (2 * tt[-1]))
            envelope = np.sqrt(np.clip(np.sin(np.pi * tt / tt[-1]), 0.0, None))
            room = np.minimum(pose - joint.low, joint.high - pose)
            amplitude = rng.uniform(0.3, 0.9, size=dims) * np.maximum(room, 0.0)
            amplitude *= rng.random(dims) < 0.8
            sweep = pose + np.sin(phase)[:, None] * envelope[:, None] * amplitude
            piece = np.vstack([lead, sweep])
        pieces.append(piece)
        count += piece.shape[0]
        pose = piece[-1].copy()
    path = np.vstack(pieces)[:total]
    tt = np.arange(total) / MOTION_RATE_HZ
    tremor_f = rng.uniform(8.0, 11.0)
    tremor = rng.uniform(0.03, 0.15) * np.sin(2 * np.pi * tremor_f * tt + rng.uniform(0, 6.3))
    path = path + tremor[:, None] * rng.uniform(0.3, 1.0, size=dims)
    return np.clip(path, joint.low, joint.high)
