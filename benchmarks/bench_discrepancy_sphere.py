"""Discrepancy workflow on suits and effects written apart from the ones it was built against.

``python -m benchmarks.bench_discrepancy_sphere [--seeds 4] [--controls] [--workers N]
[--out DIR]``

Nothing here comes from :mod:`exohil.emulators` (whose effect library and ``hidden.py``
families the workflow was developed on): a humeral head as a sphere of radius 25–35 mm that
each tendon wraps around along its geodesic once the straight line would cut it (3–6 tendons
T1…TN, insertions 90–150 mm down the humerus and up to 15 mm off its axis, carried without
axial rotation), a random cubic map from length to reading, minimum-jerk reaches at
25–90 °/s with 0.5–3 s holds, motion capture at 100–120 Hz with 0.02° of noise, 0.15 mm of
sensor noise at 250 Hz. One effect per recording, its deviation from the clean reading
scaled to 0.30 mm (m1) or 0.60 mm (m2) RMS, from families the workflow does not contain:

- hysteresis: Dahl friction (even seeds) or Bouc–Wen with exponent 2 (odd);
- creep: a logarithmic memory (a step's creep grows as log(1 + t/t0) and never settles), or
  three exponentials of 0.7, 4 and 18 s;
- saturation: a softplus clamp at the upper end, or a soft knee at the lower end;
- lag: a second-order Butterworth low-pass at 2.5–5 Hz, or a slew-rate limit;
- drift: a piecewise-linear offset, or a thermal step (1 − e^(−t/τ), τ 5–15 s).

Prints one row per recording (first named effect, held-out gap before → after, noise floor)
and, per hidden effect, how often the first named effect is right and how often a named
effect halves the gap. ``--controls`` adds, per effect recording, the gap before of the same
suit, movement and noise without the effect (what the calibrated static map alone leaves)
and what was named in it: 40 more clean recordings, a check that nothing is named in them.
``--out DIR`` also writes each recording there (``exohil discrepancy`` reads them;
``truth.json`` lists what each hides, in the list form ``bench_discrepancy_blind DIR``
scores: ``{"file", "effect", "family", "rms_mm"}`` per recording).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from collections import defaultdict
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from scipy.signal import butter, fftconvolve, lfilter

from benchmarks.report import description, out_folder, positive_float, positive_int, run_main
from exohil.emulators.discrepancy import run
from exohil.emulators.discrepancy.hidden import first_effect
from exohil.emulators.discrepancy.workers import parallel_map
from exohil.formats.atomic import write_text
from exohil.formats.recording import AngleStream, Recording, SensorStream
from exohil.formats.recording_writer import write_recording
from exohil.harness.machine import machine

RATE_HZ = 250.0
NOISE_MM = 0.15
RMS_PER_MAGNITUDE_MM = 0.30
FAMILIES = {"clean": ("none", "none"), "hysteresis": ("dahl", "bouc-wen-2"),
            "creep": ("log", "three-tau"), "saturation": ("softplus-top", "knee-bottom"),
            "lag": ("butterworth", "slew-limit"), "drift": ("piecewise", "thermal-step")}


@dataclass(frozen=True)
class SphereCase:
    """One recording: the hidden effect, its magnitude (1 or 2) and the seed."""

    kind: str
    magnitude: int
    seed: int
    duration_s: float
    with_effect: bool = True

    @property
    def family(self) -> str:
        return FAMILIES[self.kind][self.seed % 2]

    @property
    def label(self) -> str:
        return f"{self.kind}_m{self.magnitude}_s{self.seed}"


def _reaches(rng: np.random.Generator, t: np.ndarray) -> np.ndarray:
    """(N, 2) plane of elevation and elevation, degrees: minimum-jerk reaches and holds."""
    knot_t, knots = [0.0], [(rng.uniform(-20, 100), rng.uniform(0, 15))]
    while knot_t[-1] < t[-1]:
        target = (rng.uniform(-30, 120), rng.uniform(0, 120))
        move_s = max(0.4, float(np.hypot(*np.subtract(target, knots[-1]))) / rng.uniform(25, 90))
        knot_t += [knot_t[-1] + move_s, knot_t[-1] + move_s + rng.uniform(0.5, 3.0)]
        knots += [target, target]
    kt, kv = np.array(knot_t), np.array(knots)
    i = np.clip(np.searchsorted(kt, t, side="right") - 1, 0, len(kt) - 2)
    s = np.clip((t - kt[i]) / (kt[i + 1] - kt[i]), 0.0, 1.0)
    return kv[i] + (kv[i + 1] - kv[i]) * (10 * s**3 - 15 * s**4 + 6 * s**5)[:, None]


def _arm_direction(plane_deg: np.ndarray, elevation_deg: np.ndarray) -> np.ndarray:
    """(N, 3) unit humerus axis; (0, −1, 0) with the arm hanging."""
    th, ph = np.radians(plane_deg), np.radians(elevation_deg)
    return np.stack([np.sin(ph) * np.cos(th), -np.cos(ph), np.sin(ph) * np.sin(th)], axis=-1)


def _carry(d: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``v`` turned by the smallest rotation taking (0, −1, 0) to each row of ``d``."""
    down = np.array([0.0, -1.0, 0.0])
    c = np.cross(down, d)
    cv = np.cross(c, v)
    return v + cv + np.cross(c, cv) / (1.0 + d @ down)[:, None]


def _wrapped_length(a: np.ndarray, b: np.ndarray, r: float) -> np.ndarray:
    """Shortest path, mm, from ``a`` to each row of ``b`` around a sphere of radius ``r``."""
    na, nb = np.linalg.norm(a), np.linalg.norm(b, axis=1)
    gamma = np.arccos(np.clip(b @ a / (na * nb), -1.0, 1.0))
    arc = gamma - np.arccos(r / na) - np.arccos(r / nb)
    around = np.sqrt(na**2 - r**2) + np.sqrt(nb**2 - r**2) + r * np.maximum(arc, 0.0)
    return np.where(arc > 0, around, np.linalg.norm(b - a, axis=1))


def _readings(rng: np.random.Generator, angles: np.ndarray) -> np.ndarray:
    """(N, S) clean readings, mm, of 3–6 tendons wrapped over the humeral head."""
    r = rng.uniform(25, 35)
    d = _arm_direction(angles[:, 0], angles[:, 1])
    n = int(rng.integers(3, 7))
    out = []
    for k in range(n):
        azimuth = np.radians(rng.uniform(-100, 100) + 180 * k / n)
        anchor = (r + rng.uniform(8, 20)) * 0.7 * np.array(
            [np.cos(azimuth), 1.0, np.sin(azimuth)]) + rng.normal(0, 3, 3)
        offset = np.array([rng.uniform(-15, 15), 0.0, rng.uniform(-15, 15)])
        length = _wrapped_length(anchor, d * rng.uniform(90, 150) + _carry(d, offset), r)
        x = length - length.mean()
        out.append(rng.uniform(50, 300) + rng.uniform(0.7, 1.3) * x
                   + rng.uniform(-2e-5, 2e-5) * x**3)
    return np.stack(out, axis=1)


def _low_pass(x: np.ndarray, tau_s: float) -> np.ndarray:
    a = np.exp(-1.0 / (RATE_HZ * tau_s))
    return lfilter([1 - a], [1, -a], x - x[0], axis=0) + x[0]


def _hysteresis(family: str, x: np.ndarray, dx: np.ndarray, rng: np.random.Generator
                ) -> np.ndarray:
    width = np.ptp(x, axis=0) * rng.uniform(0.03, 0.08)
    z = np.zeros_like(x)
    sigma = rng.uniform(0.3, 1.0)
    for i in range(1, len(x)):
        if family == "dahl":
            z[i] = z[i - 1] + sigma * dx[i] * (1 - np.sign(dx[i]) * z[i - 1] / width)
        else:
            zz = z[i - 1]
            z[i] = zz + dx[i] - (0.6 * np.abs(dx[i]) * zz * np.abs(zz) + 0.4 * dx[i] * zz**2
                                 ) / width**2
    return -z


def _saturation(family: str, x: np.ndarray) -> np.ndarray:
    out = np.empty_like(x)
    for j in range(x.shape[1]):
        c = x[:, j]
        w = np.ptp(c) * 0.04
        if family == "knee-bottom":  # below its 20th percentile the reading loses sensitivity
            out[:, j] = 0.7 * w * (np.logaddexp(0, (np.percentile(c, 20) - c) / w) - np.log(2))
        else:  # clamps softly at its 80th percentile
            level = np.percentile(c, 80)
            out[:, j] = level - w * np.logaddexp(0, (level - c) / w) - c
    return out


def _effect(case: SphereCase, x: np.ndarray, t: np.ndarray, rng: np.random.Generator
            ) -> np.ndarray:
    """(N, S) deviation of the affected reading from the clean one, before scaling."""
    dx = np.diff(x, axis=0, prepend=x[:1])
    family = case.family
    if case.kind == "hysteresis":
        return _hysteresis(family, x, dx, rng)
    if case.kind == "creep":
        if family == "log":  # a step's creep grows as log(1 + t/t0) for the whole recording
            kernel = np.log1p((t - t[0]) / rng.uniform(0.2, 1.0))
            return fftconvolve(dx, (kernel / kernel[-1])[:, None], axes=0)[: len(x)]
        return sum(rng.uniform(0.3, 1) * (x - _low_pass(x, tau)) for tau in (0.7, 4.0, 18.0))
    if case.kind == "saturation":
        return _saturation(family, x)
    if case.kind == "lag":
        if family == "butterworth":
            b, a = butter(2, rng.uniform(2.5, 5.0) / (RATE_HZ / 2))
            return lfilter(b, a, x - x[0], axis=0) + x[0] - x
        limit = np.percentile(np.abs(dx), 92, axis=0) * 0.8
        y = x.copy()
        for i in range(1, len(x)):
            y[i] = y[i - 1] + np.clip(x[i] - y[i - 1], -limit, limit)
        return y - x
    if family == "piecewise":
        knot_t = np.arange(0, t[-1] + 15, rng.uniform(10, 20))
        knots = rng.normal(0, 1, (len(knot_t), x.shape[1]))
        return np.stack([np.interp(t, knot_t, knots[:, j]) for j in range(x.shape[1])], 1)
    t0, tau = rng.uniform(10, 25), rng.uniform(5, 15)
    step = np.where(t > t0, 1 - np.exp(-(t - t0) / tau), 0.0)
    return step[:, None] * rng.choice([-1, 1], x.shape[1]) * rng.uniform(0.5, 1, x.shape[1])


def make_recording(case: SphereCase) -> Recording:
    """The recording of ``case``: sensors at 250 Hz, shoulder mocap at 100–120 Hz."""
    rng = np.random.default_rng([case.seed, case.magnitude, list(FAMILIES).index(case.kind)])
    t = np.arange(0, case.duration_s, 1 / RATE_HZ)
    angles = _reaches(rng, t)
    x = _readings(rng, angles)
    if case.kind != "clean":
        e = _effect(case, x, t, rng)  # drawn even for a control: the noise stays the same
        e -= e.mean(axis=0)
        if case.with_effect:
            x = x + e * (RMS_PER_MAGNITUDE_MM * case.magnitude / np.sqrt(np.mean(e**2)))
    y = x + rng.normal(0, NOISE_MM, x.shape)
    mocap_hz = rng.uniform(100, 120)
    tm = np.arange(0, case.duration_s, 1 / mocap_hz)
    am = np.column_stack([np.interp(tm, t, angles[:, k]) for k in range(2)])
    am += rng.normal(0, 0.02, am.shape)
    return Recording(sensor_names=tuple(f"T{k + 1}" for k in range(y.shape[1])),
                     sensors=SensorStream(seq=np.arange(len(t)), t=t, values=y),
                     mocap={"shoulder": AngleStream(t=tm, names=("elv_angle", "shoulder_elv"),
                                                    angles=am)},
                     sensor_rate_hz=RATE_HZ, mocap_rate_hz=mocap_hz,
                     metadata={"generator": "benchmarks.bench_discrepancy_sphere",
                               "case": case.label, "family": case.family})


def run_sphere_case(case: SphereCase) -> dict:
    """The workflow's summary on ``case``'s recording."""
    return run(make_recording(case), case.label).summary


def write_cases(out: Path, selected: list[SphereCase]) -> None:
    """Each case's recording as ``out/LABEL.mcap`` and ``out/truth.json``."""
    out.mkdir(parents=True, exist_ok=True)
    truth = []
    for case in selected:
        tmp = out / f".{case.label}.mcap.tmp"
        write_recording(tmp, make_recording(case))
        os.replace(tmp, out / f"{case.label}.mcap")
        truth.append({"file": f"{case.label}.mcap", "effect": case.kind,
                      "family": case.family,
                      "rms_mm": RMS_PER_MAGNITUDE_MM * case.magnitude
                      if case.kind != "clean" else 0.0})
    write_text(out / "truth.json", json.dumps(truth, indent=1) + "\n")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=description(__doc__))
    parser.add_argument("--seeds", type=positive_int, default=4,
                        help="seeds 0 … N−1 (default 4)")
    parser.add_argument("--duration", type=positive_float, default=60.0,
                        help="s per recording")
    parser.add_argument("--workers", type=positive_int, default=None,
                        help="processes (default: CPUs)")
    parser.add_argument("--controls", action="store_true",
                        help="also run each effect recording's suit and movement without it")
    parser.add_argument("--out", type=out_folder, default=None,
                        help="also write the recordings here")
    args = parser.parse_args(argv)
    selected = [SphereCase(kind, m, seed, args.duration) for kind in FAMILIES
                for m in ((1,) if kind == "clean" else (1, 2)) for seed in range(args.seeds)]
    controls = [replace(case, with_effect=False) for case in selected
                if args.controls and case.kind != "clean"]
    if args.out is not None:
        write_cases(args.out, selected)
    print(f"machine: {machine()}")
    start = time.perf_counter()
    if controls:
        print(f"running the {len(controls)} effect recordings without their effect first ...",
              flush=True)
    control = {case.label: s for case, s in parallel_map(run_sphere_case, controls, args.workers)}
    print("| recording | family | sensors | effects named | gap before → after, mm | floor |"
          + (" without the effect, mm |" if args.controls else ""))
    print("|---|---|---|---|---|---|" + ("---|" if args.controls else ""))
    right: dict[str, list[int]] = defaultdict(lambda: [0, 0, 0, 0])
    for case, s in parallel_map(run_sphere_case, selected, args.workers):
        named = first_effect(s)
        tally = right[case.kind]
        tally[0] += 1
        tally[1] += named == case.kind
        if s["effects"] and case.kind != "clean":
            tally[2] += 1
            tally[3] += s["gap_after"] <= 0.5 * s["gap_before"]
        row = (f"| {case.label} | {case.family} | {len(s['sensors'])} | "
               f"{', '.join(s['effects']) or '—'} | {s['gap_before']:.3f} → "
               f"{s['gap_after']:.3f} | {s['noise_floor']:.3f} |")
        if args.controls:  # a clean recording is its own control
            c = control.get(case.label)
            row += (f" {c['gap_before']:.3f} ({', '.join(c['effects']) or 'nothing named'}) |"
                    if c is not None else " — |")
        print(row, flush=True)
    print(f"\n{len(selected) + len(controls)} recordings in {time.perf_counter() - start:.0f} s")
    if control:
        in_controls = sorted(f"{label}: {', '.join(c['effects'])}"
                             for label, c in control.items() if c["effects"])
        print(f"controls (effect recordings without their effect): nothing named in "
              f"{len(control) - len(in_controls)}/{len(control)}"
              + "".join(f"\n  {entry}" for entry in in_controls))
    for kind, (n, ok, named, halved) in right.items():
        line = f"{kind}: first named right {ok}/{n}"
        print(line + (f", gap halved {halved}/{named} of those named" if kind != "clean"
                      else " (nothing named)"))


if __name__ == "__main__":
    run_main(main)
