"""Where the static map misses on this generator: tendons whose anchors pass opposite sides
of the cap.

``python -m benchmarks.blind3.antipodal RUNS [--only N ...]``

RUNS is the folder of the clean twins' summaries (``bench_discrepancy_blind
/tmp/blind3-twins --out RUNS``, see the README). For every twin this regenerates its suit and
movement (the generator's own draws, written to a temporary folder and thrown away) and
prints, per sensor, what the calibrated static map left of it (the summary's held-out
``sensor_gap_before`` over the sensor's ``noise_floor_per_sensor``) beside the largest angle
between the tendon's two anchors seen from the cap's centre (in the cap's unit-sphere space,
where the generator wraps the path), the share of frames where that angle exceeds 175°, and
the sudden steps of the reading the workflow's localisation found after its effects (method
step 5 of docs/discrepancy-method.md: their count, and in brackets how many came back at one pose).

At 180° the plane of the wrapped path (the great circle through both anchors) is undefined:
the generator's path goes over whichever side the anchors' small misalignment points to, and
on an ellipsoid the two sides differ in length, so the reading jumps or peaks sharply within
a degree of the pose. No smooth map of the pose follows that; a real tendon would keep to
the side it lies on. The summary line groups the sensors by that angle.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from benchmarks.blind3 import generate as blind3
from benchmarks.report import description

NEARLY_OPPOSITE_DEG = 175.0


@contextlib.contextmanager
def first_lengths_call() -> Iterator[dict]:
    """Record the suit and the angles (deg) of the generator's first ``Suit.lengths`` call,
    the one over the recording's whole movement."""
    seen: dict = {}
    original = blind3.Suit.lengths

    def spy(suit, th, ph, ps, K=20):  # noqa: N803 (the generator's own signature)
        if not seen:
            seen.update(suit=suit, angles=(th, ph, ps))
        return original(suit, th, ph, ps, K)

    blind3.Suit.lengths = spy
    try:
        yield seen
    finally:
        blind3.Suit.lengths = original


def anchor_angles_deg(suit: blind3.Suit, th: np.ndarray, ph: np.ndarray, ps: np.ndarray
                      ) -> np.ndarray:
    """(N, S) angle between each tendon's anchors seen from the cap's centre, in the cap's
    unit-sphere space, deg: the frames and scalings of ``Suit.lengths``."""
    tilt = suit.rhythm * blind3.softplus(ph - suit.knee, 5.0) * blind3.D2R
    scapula = blind3.rot_x(-tilt)
    joint = suit.pivot[None, :] + np.einsum("nij,j->ni", scapula, -suit.pivot)
    cap = suit.pivot[None, :] + np.einsum("nij,j->ni", scapula, suit.cap_offset - suit.pivot)
    humerus = blind3.humerus_rotation(th, ph, ps)
    out = np.empty((th.size, len(suit.names)))
    for k in range(len(suit.names)):
        if suit.onscap[k]:
            near = suit.pivot[None, :] + np.einsum("nij,j->ni", scapula,
                                                   suit.prox[k] - suit.pivot)
        else:
            near = np.repeat(suit.prox[k][None, :], th.size, 0)
        far = joint + np.einsum("nij,j->ni", humerus, suit.dist[k])
        u = np.einsum("nji,nj->ni", scapula, near - cap) / suit.axes
        w = np.einsum("nji,nj->ni", scapula, far - cap) / suit.axes
        cos = np.sum(u * w, 1) / (np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1))
        out[:, k] = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    return out


def twin_angles(index: int) -> tuple[list[str], np.ndarray]:
    """Sensor names and (N, S) anchor angles of twin ``index``, from its regenerated draws."""
    rng = np.random.default_rng(blind3.MASTER_SEED)
    plan = blind3.make_plan(rng)
    seeds = rng.integers(1, 2**31 - 1, blind3.N_REC)
    effect, family, target = plan[index]
    with tempfile.TemporaryDirectory() as scratch, first_lengths_call() as seen:
        blind3.generate(index, effect, family, target, int(seeds[index]), Path(scratch),
                        with_effect=False)
    suit = seen["suit"]
    names = [f"{name}{k}" for k, name in enumerate(suit.names)]
    return names, anchor_angles_deg(suit, *seen["angles"])


def main() -> None:
    parser = argparse.ArgumentParser(description=description(__doc__))
    parser.add_argument("runs", type=Path, help="the clean twins' summaries (rec_XX.json)")
    parser.add_argument("--only", type=int, nargs="*", default=[], help="only these twins")
    args = parser.parse_args()
    indices = args.only or range(blind3.N_REC)
    bad = [i for i in indices if not 0 <= i < blind3.N_REC]
    if bad:
        parser.error(f"--only: no twin {bad[0]} (0 to {blind3.N_REC - 1})")
    paths = [args.runs / f"rec_{index:02d}.json" for index in indices]
    missing = [str(path) for path in paths if not path.is_file()]
    if missing:  # before minutes of regenerating
        parser.error(f"{missing[0]} is missing ({len(missing)} in all): score the twins "
                     f"first (see benchmarks/blind3/README.md)")
    summaries = [json.loads(path.read_text()) for path in paths]
    older = [str(path) for path, summary in zip(paths, summaries, strict=True)
             if "steps" not in summary.get("localisation_after", {})]
    if older:
        parser.error(f"{older[0]} has no steps of the reading ({len(older)} in all): "
                     f"scored before they were found; score the twins again")
    rows = []
    print("twin    sensor     left/noise  max angle  frames > 175°  steps (at one pose)")
    for index, summary in zip(indices, summaries, strict=True):
        names, angles = twin_angles(index)
        steps = {e["sensor"]: e for e in summary["localisation_after"]["steps"]}
        for j, name in enumerate(summary["sensors"]):
            left = summary["sensor_gap_before"][j] / summary["noise_floor_per_sensor"][j]
            a = angles[:, names.index(name)]
            found = steps.get(name, {"count": 0, "at_a_recurring_pose": 0})
            rows.append((left, float(a.max()), found["at_a_recurring_pose"] > 0))
            print(f"rec_{index:02d}  {name:9s} {left:8.2f} {a.max():9.1f}° "
                  f"{np.mean(a > NEARLY_OPPOSITE_DEG):12.1%}  {found['count']:6d} "
                  f"({found['at_a_recurring_pose']})", flush=True)
    left, widest, recurring = np.array(rows).T
    for label, group in ((f"never past {NEARLY_OPPOSITE_DEG:g}°",
                          widest < NEARLY_OPPOSITE_DEG),
                         (f"past {NEARLY_OPPOSITE_DEG:g}°, never 179°",
                          (widest >= NEARLY_OPPOSITE_DEG) & (widest < 179.0)),
                         ("past 179°", widest >= 179.0)):
        if group.any():
            print(f"anchors {label}: {group.sum()} sensors, left/noise median "
                  f"{np.median(left[group]):.2f}, over 3 in {np.mean(left[group] > 3):.0%}, "
                  f"over 5 in {np.mean(left[group] > 5):.0%}, steps at one pose in "
                  f"{int(recurring[group].sum())}")


if __name__ == "__main__":
    main()
