"""Write the blind6 recordings and their answer key (see README.md).

    python -m benchmarks.blind6.generate --out DIR [--without-effect] [--only I] [--workers N]

writes ``rec_00.mcap`` … ``rec_39.mcap`` and ``truth.json`` into DIR (with ``--only I``: that
one recording, and a ``truth.json`` listing only it), each read back to check it, and prints
one line per recording. ``--without-effect`` writes the clean twins: every random draw the
same, the effect left out.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.signal import lfilter

from benchmarks.blind6.effects import MODELS, EffectModel, Render
from benchmarks.blind6.motion import MOTION_RATE_HZ, trajectory
from benchmarks.blind6.suits import Transfer, make_suit
from exohil.formats.recording import AngleStream, Recording, SensorStream
from exohil.formats.recording_reader import read_recording
from exohil.formats.recording_writer import write_recording

MASTER_SEED = 20261205
FAMILIES = ("shoulder-res", "shoulder-cap", "elbow-sleeve", "wrist-band")
EFFECT_COUNTS = {"hysteresis": 7, "creep": 7, "saturation": 7, "lag": 6, "drift": 6}
CLEAN_COUNT = 7
SENSOR_RATES_HZ = (100.0, 120.0, 200.0, 250.0, 400.0, 500.0)
MOCAP_RATES_HZ = (60.0, 100.0, 120.0, 150.0, 200.0)
GENERATOR = "blind6.generate 1 (independent helper-written generator)"


@dataclass(frozen=True)
class Planned:
    """What one recording hides: the effect (or ``clean``), the garment, the effect model."""

    index: int
    effect: str
    family: str
    model: int


def plan() -> list[Planned]:
    """The 40 recordings: each effect spread over the garments and its model families, the
    clean ones over the garments, in an order shuffled by the master seed."""
    entries = []
    for e, (effect, count) in enumerate(EFFECT_COUNTS.items()):
        for j in range(count):
            entries.append((effect, FAMILIES[(j + e) % len(FAMILIES)], j % len(MODELS[effect])))
    entries += [("clean", FAMILIES[j % len(FAMILIES)], 0) for j in range(CLEAN_COUNT)]
    order = np.random.default_rng(MASTER_SEED).permutation(len(entries))
    return [Planned(i, *entries[k]) for i, k in enumerate(order)]


def magnitude(changed: np.ndarray, clean: np.ndarray, noise_sd: float) -> float:
    """What an effect leaves beyond a recalibration, in noise SDs: the RMS of
    ``changed − clean`` after removing its best affine fit in the clean reading."""
    design = np.column_stack([np.ones_like(clean), clean])
    diff = changed - clean
    coef, *_ = np.linalg.lstsq(design, diff, rcond=None)
    return float(np.sqrt(np.mean((diff - design @ coef) ** 2)) / noise_sd)


def fit_strength(ratio: Callable[[float], float], bounds: tuple[float, float],
                 target: float) -> float:
    """The strength in ``bounds`` at which ``ratio`` (increasing) reaches ``target``
    (geometric bisection); a bound where the target lies beyond it."""
    lo, hi = bounds
    if ratio(hi) <= target:
        return hi
    if ratio(lo) >= target:
        return lo
    for _ in range(36):
        mid = float(np.sqrt(lo * hi))
        lo, hi = (mid, hi) if ratio(mid) < target else (lo, mid)
    return float(np.sqrt(lo * hi))


def coloured_noise(rng: np.random.Generator, n: int, sd: float, share: float,
                   tau_s: float, fs: float) -> np.ndarray:
    """Noise of SD ``sd``: white, plus a ``share`` of its variance as AR(1) noise with
    correlation time ``tau_s``."""
    a = np.exp(-1.0 / (tau_s * fs))
    red = lfilter([np.sqrt(1 - a * a)], [1, -a], rng.standard_normal(n))
    return sd * (np.sqrt(1 - share) * rng.standard_normal(n) + np.sqrt(share) * red)


def reading_renderer(model: EffectModel, strain: np.ndarray, clean: np.ndarray,
                     transfer: Transfer, t: np.ndarray) -> Render:
    """One sensor's reading as a function of the effect strength."""
    if model.domain == "strain":
        render = model.prepare(strain, t)
        return lambda s: transfer(render(s))
    return model.prepare(clean, t)


def build(planned: Planned, out: Path, apply_effect: bool) -> dict:
    """Generate, write and read back one recording; its answer-key entry."""
    streams = [np.random.default_rng(s)
               for s in np.random.SeedSequence([MASTER_SEED, planned.index]).spawn(5)]
    r_suit, r_timing, r_motion, r_noise, r_effect = streams
    suit = make_suit(planned.family, r_suit)

    fs = float(r_timing.choice(SENSOR_RATES_HZ))
    fm = float(r_timing.choice(MOCAP_RATES_HZ))
    duration = float(r_timing.uniform(60.0, 240.0))
    start = float(r_timing.uniform(0.2, 2.5))
    mocap_end = start + duration + float(r_timing.uniform(0.0, 1.5))
    path = trajectory(r_motion, suit.motion, mocap_end + 0.1)
    grid = np.arange(path.shape[0]) / MOTION_RATE_HZ

    n = int(duration * fs)
    t = start + np.arange(n) / fs
    angles = np.column_stack([np.interp(t, grid, path[:, d]) for d in range(path.shape[1])])
    raw = suit.raw_strain(angles)
    pretension = np.maximum(r_suit.uniform(0.02, 0.08, size=raw.shape[0]),
                            0.015 - raw.min(axis=1))
    strain = raw + pretension[:, None]
    clean = np.array([f(row) for f, row in zip(suit.transfers, strain, strict=True)])
    noise_frac = r_noise.uniform(0.002, 0.01, size=len(suit.names))
    noise_sd = noise_frac * np.ptp(clean, axis=1)
    coloured = bool(r_noise.random() < 0.5)
    share, tau = (float(r_noise.uniform(0.2, 0.7)), float(r_noise.uniform(0.05, 1.0))) \
        if coloured else (0.0, 0.0)
    noise = np.array([coloured_noise(r_noise, n, sd, share, tau or 1.0, fs)
                      for sd in noise_sd])

    values = clean.copy()
    entry_effect: dict[str, object] = {}
    if planned.effect != "clean":
        model = MODELS[planned.effect][planned.model](r_effect)
        count = int(r_effect.integers(1, len(suit.names) + 1))
        touched = np.sort(r_effect.choice(len(suit.names), size=count, replace=False))
        target = float(np.exp(r_effect.uniform(np.log(2.0), np.log(10.0))))
        strengths, achieved = [], []
        for j in touched.tolist():
            render = reading_renderer(model, strain[j], clean[j], suit.transfers[j], t)
            s = fit_strength(lambda s, j=j, render=render:
                             magnitude(render(s), clean[j], noise_sd[j]), model.bounds, target)
            changed = render(s)
            strengths.append(s)
            achieved.append(magnitude(changed, clean[j], noise_sd[j]))
            if apply_effect:
                values[j] = changed
        entry_effect = {
            "effect_model": model.model, "effect_domain": model.domain,
            "touched": [suit.names[j] for j in touched.tolist()],
            "target_x_noise": round(target, 3),
            "per_sensor_x_noise": [round(a, 3) for a in achieved],
            "strengths": [float(f"{s:.6g}") for s in strengths],
            "strength_unit": model.strength_unit,
            "effect_params": {k: float(f"{float(v):.6g}") for k, v in model.params.items()},
            "hidden_magnitude_x_noise": round(float(np.mean(achieved)), 3),
        }
    values = values + noise

    keep = np.ones(n, dtype=bool)
    bursts = []
    for _ in range(int(r_timing.integers(0, 5))):
        first, length = int(r_timing.integers(n // 20, n - 300)), int(r_timing.integers(3, 250))
        keep[first:first + length] = False
        bursts.append([first, length])
    seq = np.arange(n, dtype=np.int64)

    t_m = np.arange(0.0, mocap_end, 1.0 / fm)
    mocap = np.column_stack([np.interp(t_m, grid, path[:, d]) for d in range(path.shape[1])])
    mocap_sd = float(r_timing.uniform(0.1, 0.5))
    mocap += r_timing.normal(0.0, mocap_sd, size=mocap.shape)
    seen = np.ones(t_m.size, dtype=bool)
    for _ in range(int(r_timing.integers(0, 4))):
        first = int(r_timing.integers(0, t_m.size - 200))
        seen[first:first + int(r_timing.uniform(0.1, 1.0) * fm)] = False

    name = f"rec_{planned.index:02d}.mcap"
    seed_text = f"SeedSequence([{MASTER_SEED}, {planned.index}])"
    rec = Recording(
        sensor_names=suit.names,
        sensors=SensorStream(seq[keep], t[keep], values.T[keep]),
        mocap={suit.joint: AngleStream(t_m[seen], suit.motion.names, mocap[seen])},
        sensor_units=suit.units,
        sensor_rate_hz=fs,
        mocap_rate_hz=fm,
        metadata={"generator": GENERATOR, "seed": seed_text, "garment": suit.family,
                  "lab": "blind6 textile garment lab (simulated)"},
    )
    write_recording(out / name, rec)
    back = read_recording(out / name)
    if len(back.sensors) != int(keep.sum()) or len(back.mocap[suit.joint]) != int(seen.sum()):
        raise RuntimeError(f"{name}: read back {len(back.sensors)} frames, "
                           f"{len(back.mocap[suit.joint])} mocap samples")

    entry: dict[str, object] = {
        "file": name,
        "effect": planned.effect if apply_effect else "clean",
        "family": suit.family,
        "magnitude_x_noise": 0.0,
    }
    effect_family = f"{suit.family}:{entry_effect.get('effect_model', '')}".rstrip(":")
    if apply_effect and planned.effect != "clean":
        entry["family"] = effect_family
        entry["magnitude_x_noise"] = entry_effect["hidden_magnitude_x_noise"]
    elif planned.effect != "clean":
        entry["twin_of"] = planned.effect
        entry["twin_family"] = effect_family
    entry.update(entry_effect)
    entry.update({
        "garment": suit.family, "joint": suit.joint, "angles": list(suit.motion.names),
        "sensors": list(suit.names), "units": suit.units, "sensor_rate_hz": fs,
        "mocap_rate_hz": fm, "duration_s": round(duration, 2),
        "sensor_frames": int(keep.sum()), "dropped_bursts": bursts,
        "mocap_samples": int(seen.sum()), "mocap_noise_deg": round(mocap_sd, 3),
        "noise_sd": [float(f"{v:.4g}") for v in noise_sd],
        "noise_frac_of_range": [round(float(v), 5) for v in noise_frac],
        "coloured_noise": {"share": round(share, 3), "tau_s": round(tau, 3)} if coloured
        else None,
        "garment_params": suit.params, "seed": seed_text,
    })
    return entry


def _build_args(args: tuple[Planned, Path, bool]) -> dict:
    return build(*args)


def table(truth: list[dict]) -> str:
    """One line per recording: effect, family, sensors, units, rates, duration, magnitude."""
    lines = [f"{'file':<12} {'effect':<11} {'family':<30} {'S':>2} {'units':<6} "
             f"{'fs':>5} {'fm':>5} {'dur s':>6} {'mag×σ':>6}"]
    for e in truth:
        family = e["family"] if e["effect"] != "clean" else e.get("twin_family", e["family"])
        lines.append(f"{e['file']:<12} {e['effect']:<11} {family:<30} {len(e['sensors']):>2} "
                     f"{e['units']:<6} {e['sensor_rate_hz']:>5g} {e['mocap_rate_hz']:>5g} "
                     f"{e['duration_s']:>6.1f} {e['magnitude_x_noise']:>6.2f}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    """Command line: see the module docstring."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="folder for the recordings")
    parser.add_argument("--without-effect", action="store_true",
                        help="write the clean twins (same draws, no effect)")
    parser.add_argument("--only", type=int, help="write only recording I (0-39)")
    parser.add_argument("--workers", type=int, default=2, help="processes (default 2)")
    args = parser.parse_args(argv)
    planned = plan()
    if args.only is not None:
        if not 0 <= args.only < len(planned):
            parser.error(f"--only must be 0..{len(planned) - 1}")
        planned = [planned[args.only]]
    args.out.mkdir(parents=True, exist_ok=True)
    jobs = [(p, args.out, not args.without_effect) for p in planned]
    with ProcessPoolExecutor(max_workers=max(1, args.workers)) as pool:
        truth = list(pool.map(_build_args, jobs))
    (args.out / "truth.json").write_text(json.dumps(truth, indent=1) + "\n")
    print(table(truth))


if __name__ == "__main__":
    main()
