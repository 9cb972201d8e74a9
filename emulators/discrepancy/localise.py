"""Where the residual lives (time, angle space, direction, speed, holds) and each effect's
physical signature in it. All statistics are in the recording's sensor units unless named
otherwise; they describe a held-out residual (measurement − simulation), so a model that
over-fits cannot make them look small.
"""

from __future__ import annotations

import numpy as np

from exohil.emulators.discrepancy.data import Trial, true_runs
from exohil.emulators.discrepancy.figures import significant
from exohil.emulators.discrepancy.filters import low_pass
from exohil.emulators.discrepancy.model import map_inputs, trial_motion

#: A hold counts for creep when it lasts at least this long, s.
MIN_HOLD_S = 1.0
#: Equal time windows of the localisation in time.
TIME_WINDOWS = 8
#: A step in the reading (:func:`reading_steps`): the reading's mean over the STEP_WINDOW_S
#: after a frame differs from its mean over the STEP_WINDOW_S before by at least STEP_SIGMAS
#: of the sensor's noise (a difference of two such means has 0.28 σ of noise at 250 Hz), and
#: so does the held-out residual's: by at least STEP_FLATNESS times the residual's spread
#: within either window, from one level to another, while the simulation's own change is at
#: most SIMULATED_SHARE of the reading's. A straight ramp across both windows differs by
#: √12 ≈ 3.46 times its spread, a swing or a decay more spread than that, so a fast move
#: that the reading follows late (a lag) is no step; a move the simulation follows too (the
#: reading relaxing after it, a loop turning) is none either, nor is a reading that stays put
#: while the simulation moves: the reading jumps where the simulation does not.
STEP_WINDOW_S = 0.1
STEP_SIGMAS = 6.0
STEP_FLATNESS = 4.0
SIMULATED_SHARE = 0.5
#: Share of a window's frames that must be scored for its mean to count.
STEP_WINDOW_SHARE = 0.6
#: Two steps of one sensor are at the same pose when no angle differs by more than this
#: (the arm's axes, for a shoulder in MoBL-ARMS angles), degrees.
SAME_POSE_DEG = 5.0
#: The largest steps listed per sensor.
STEPS_LISTED = 5
#: Each signature :func:`signatures` measures, and what it points to.
SIGNATURES = {
    "direction_split_slow": "mean residual while the sensor's input falls minus while it "
                            "rises, slowest third of movement (sensor units, sign-aligned per "
                            "sensor): about the loop width for hysteresis, small for lag",
    "direction_split_fast": "the same split in the fastest third: about the loop width for "
                            "hysteresis, grows with speed for lag",
    "rate_independence": "slow split / fast split: about 1 for hysteresis, much less than 1 "
                         "for lag",
    "velocity_correlation": "correlation of the residual with the input's rate of change: "
                            "strong (either sign) for lag",
    "hold_relaxation": "RMS change of the residual over holds of at least 1 s after a move, "
                       "in noise floors: creep relaxes during holds; hysteresis and lag stay "
                       "flat",
    "time_trend": "share of the residual's variance a cubic in time explains: drift",
    "extreme_excess": "residual RMS in the outer 5 % of each sensor's range over the RMS in "
                      "the middle 90 %: saturation compresses the extremes",
}


def motion(trial: Trial, static: np.ndarray) -> dict[str, np.ndarray]:
    """Per-frame motion descriptors.

    Returns a dict with ``speed_deg_s`` (N,) angular speed; ``still`` (N,) bool;
    ``velocity`` (N, S) rate of change of the static prediction (sensor units/s);
    ``direction`` (N, S) +1 rising, −1 falling, 0 still.
    """
    speed, still = trial_motion(trial)
    velocity = np.gradient(low_pass(static, 0.05, trial.rate_hz), axis=0) * trial.rate_hz
    direction = np.where(still[:, None], 0, np.sign(velocity)).astype(np.int64)
    return {"speed_deg_s": speed, "still": still, "velocity": velocity, "direction": direction}


def _rms(x: np.ndarray) -> float | None:
    """RMS of the finite values, to significant digits; None (JSON null) when there are none
    (a time window or angle bin with no scored frame, a recording without holds)."""
    x = x[np.isfinite(x)]
    return significant(np.sqrt(np.mean(x**2))) if x.size else None


def _holds(still: np.ndarray, valid: np.ndarray, rate_hz: float) -> list[tuple[int, int]]:
    """(start, stop) frame ranges of holds lasting ≥ MIN_HOLD_S that follow a movement."""
    return [(start, stop) for start, stop in true_runs(still)
            if start > 0 and stop - start >= MIN_HOLD_S * rate_hz
            and valid[start:stop].mean() > 0.9]


def localise(trial: Trial, residual: np.ndarray, mot: dict[str, np.ndarray]) -> dict:
    """Residual RMS by time window, angle bin, direction of motion, speed tercile
    and during holds; sensor units."""
    by_time = []
    edges = np.linspace(trial.t[0], trial.t[-1], TIME_WINDOWS + 1)
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        sel = (trial.t >= lo) & (trial.t <= hi)
        by_time.append({"t0_s": round(float(lo), 3), "t1_s": round(float(hi), 3),
                        "rms": _rms(residual[sel])})
    by_angle = {}
    for k, name in enumerate(trial.angle_names):
        a = trial.angles[:, k]
        edges = np.linspace(np.min(a[trial.valid]), np.max(a[trial.valid]), 7)
        cells = []
        for lo, hi in zip(edges[:-1], edges[1:], strict=True):
            sel = (a >= lo) & (a <= hi)
            cells.append({"lo_deg": round(float(lo), 2), "hi_deg": round(float(hi), 2),
                          "rms": _rms(residual[sel])})
        by_angle[name] = cells
    direction = mot["direction"]
    by_direction = {
        label: _rms(residual[direction == sign])
        for label, sign in (("rising", 1), ("falling", -1), ("still", 0))
    }
    moving = ~mot["still"] & trial.valid
    speed = mot["speed_deg_s"]
    by_speed = []
    if moving.sum() > 3:
        cuts = np.quantile(speed[moving], [0.0, 1 / 3, 2 / 3, 1.0])
        for lo, hi in zip(cuts[:-1], cuts[1:], strict=True):
            sel = moving & (speed >= lo) & (speed <= hi)
            by_speed.append({"lo_deg_s": round(float(lo), 2), "hi_deg_s": round(float(hi), 2),
                             "rms": _rms(residual[sel])})
    holds = _holds(mot["still"], trial.valid, trial.rate_hz)
    in_hold = np.zeros(trial.n, dtype=bool)
    for start, stop in holds:
        in_hold[start:stop] = True
    return {"by_time": by_time, "by_angle": by_angle, "by_direction": by_direction,
            "by_speed": by_speed,
            "holds": {"count": len(holds), "rms": _rms(residual[in_hold]),
                      "moving_rms": _rms(residual[moving])},
            "steps": reading_steps(trial, residual)}


def _window_stats(r: np.ndarray, w: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean (less that of all of ``r``), standard deviation and count of the finite values
    of ``r`` (N,) over each window r[k : k + w], k = 0 … N − w."""
    ok = np.isfinite(r)
    x = np.where(ok, r - np.mean(r[ok]) if ok.any() else 0.0, 0.0)  # centred: no cancellation
    count, total, squares = (c[w:] - c[:-w] for c in (
        np.concatenate([[0.0], np.cumsum(v)]) for v in (ok.astype(float), x, x * x)))
    mean = total / np.maximum(count, 1.0)
    spread = np.sqrt(np.maximum(squares / np.maximum(count, 1.0) - mean**2, 0.0))
    return mean, spread, count


def _poses(trial: Trial, frames: np.ndarray) -> tuple[np.ndarray, bool]:
    """(M, K) the pose at each of the M ``frames`` and whether it is K/3 unit axes (a
    shoulder in MoBL-ARMS angles: the humerus's axes, compared by the angle between them)
    or K angles in degrees."""
    angles = trial.angles[frames]
    lo, hi = np.zeros(angles.shape[1]), np.ones(angles.shape[1])  # the scaling is not used
    u, kind = map_inputs(angles, trial.angle_names, lo, hi)
    return (u, True) if kind in ("arm_direction", "arm_axes") else (angles, False)


def _near_another(poses: np.ndarray, axes: bool, rows: int = 256) -> int:
    """How many of the M ``poses`` lie within SAME_POSE_DEG of another: no angle between
    two of their axes (or, not ``axes``, no difference of two of their angles) larger. In
    ``rows`` at a time, so memory stays bounded however many steps a sensor has."""
    if axes:
        poses = poses.reshape(poses.shape[0], -1, 3)
        limit = np.cos(np.radians(SAME_POSE_DEG))
    count = 0
    for start in range(0, poses.shape[0], rows):
        part = poses[start:start + rows]
        if axes:
            near = (np.einsum("mak,nak->mna", part, poses) >= limit).all(axis=2)
        else:
            near = (np.abs(part[:, None, :] - poses[None, :, :]) <= SAME_POSE_DEG).all(axis=2)
        count += int(np.sum(near.sum(axis=1) > 1))  # each is near itself
    return count


def reading_steps(trial: Trial, residual: np.ndarray) -> list[dict]:
    """Sudden steps in each sensor's held-out residual ``residual`` (N, S): places where the
    reading jumps from one level to another while the simulation does not (see
    :data:`STEP_SIGMAS`). None of the five effects makes one: a step that comes back
    whenever the joint passes the same pose says the reading is not a smooth function of the
    pose there (a tendon slipping over a bony prominence, a sensor catching on the fabric);
    steps at separate poses are knocks or slips of the suit on the skin.

    A joint that passes every pose each cycle (a knee flexing again and again) brings steps
    made by fast movement back to one pose too: the joint's speed at each step tells them
    apart (a slip happens at any speed; a jump the movement makes, while it is fast).

    Returns one entry per sensor with a step: ``sensor``, ``count``, ``median_size`` (sensor
    units), ``at_a_recurring_pose`` (steps with another of the sensor's steps within
    :data:`SAME_POSE_DEG`), ``median_speed_deg_s`` (the joint's speed at its steps) and the
    :data:`STEPS_LISTED` largest (``t_s``, ``size``, the joint's ``angles_deg`` and
    ``speed_deg_s``). Windows that straddle a held-out block's edge, where the simulation
    changes fold, are not looked at.
    """
    w = max(3, int(round(STEP_WINDOW_S * trial.rate_hz)))
    n = trial.n
    if n < 2 * w + 1:
        return []
    k = np.arange(w, n - w + 1)  # a step between frames k − 1 and k
    stretch = np.concatenate([[0], np.cumsum(np.diff(trial.blocks) != 0)])
    one_block = stretch[k - w] == stretch[k + w - 1]
    speed, _ = trial_motion(trial)
    out = []
    before, after = k - w, k
    for j, name in enumerate(trial.sensor_names):
        reading = np.where(np.isfinite(residual[:, j]), trial.y[:, j], np.nan)
        level, _, _ = _window_stats(reading, w)
        moved = level[after] - level[before]  # the reading's change
        level, spread, count = _window_stats(residual[:, j], w)
        size = level[after] - level[before]  # the residual's: what the simulation misses
        least = STEP_SIGMAS * trial.noise[j]
        hit = (one_block & (np.minimum(count[before], count[after]) >= STEP_WINDOW_SHARE * w)
               & (np.abs(moved) >= least) & (np.abs(size) >= least)
               & (np.abs(size) >= STEP_FLATNESS * np.maximum(spread[before], spread[after]))
               & (np.abs(moved - size) <= SIMULATED_SHARE * np.abs(moved)))
        at = _peaks(np.flatnonzero(hit), np.abs(size), w)
        if not at.size:
            continue
        recurring = _near_another(*_poses(trial, k[at]))
        largest = at[np.argsort(-np.abs(size[at]), kind="stable")[:STEPS_LISTED]]
        out.append({
            "sensor": name, "count": int(at.size),
            "median_size": significant(np.median(np.abs(size[at]))),
            "at_a_recurring_pose": recurring,
            "median_speed_deg_s": round(float(np.median(speed[k[at]])), 1),
            "largest": [{"t_s": round(float(trial.t[k[i]]), 3),
                         "size": significant(size[i]),
                         "angles_deg": [round(float(a), 1) for a in trial.angles[k[i]]],
                         "speed_deg_s": round(float(speed[k[i]]), 1)}
                        for i in largest]})
    return out


def steps_words(steps: list[dict], units: str) -> str:
    """The sudden changes of the reading (:func:`reading_steps`) in words."""
    return "sudden changes of the reading no effect follows: " + "; ".join(
        f"{e['sensor']} {e['count']} ({e['at_a_recurring_pose']} at a pose of another, median "
        f"{e['median_size']:.4g} {units}, joint at {e['median_speed_deg_s']:.4g} deg/s)"
        for e in steps)


def _peaks(hits: np.ndarray, strength: np.ndarray, w: int) -> np.ndarray:
    """The strongest index of each run of ``hits`` (sorted indices) whose members lie
    within ``w`` of the next: one step is seen from every window that straddles it."""
    if not hits.size:
        return hits
    starts = np.flatnonzero(np.concatenate([[True], np.diff(hits) > w]))
    ends = np.append(starts[1:], hits.size)
    return np.array([hits[a + np.argmax(strength[hits[a:b]])] for a, b in zip(starts, ends,
                                                                              strict=True)])


def signatures(trial: Trial, residual: np.ndarray, mot: dict[str, np.ndarray],
               floor: float) -> dict[str, float]:
    """Physical signatures of the five effects in a held-out residual (each is explained
    in :data:`SIGNATURES`)."""
    vel = mot["velocity"]
    valid = trial.valid
    moving = ~mot["still"] & valid
    splits: dict[str, list[float]] = {"slow": [], "fast": []}
    weights: dict[str, list[float]] = {"slow": [], "fast": []}
    corr_num, corr_den = 0.0, 0.0
    excess_out, excess_mid = [], []
    for j in range(trial.n_sensors):
        r = residual[:, j]
        speed = np.abs(vel[:, j])
        mv = moving & np.isfinite(r) & (speed > 0)
        if mv.sum() < 30:
            continue
        cuts = np.quantile(speed[mv], [1 / 3, 2 / 3])
        for label, sel in (("slow", mv & (speed <= cuts[0])), ("fast", mv & (speed >= cuts[1]))):
            up, down = sel & (vel[:, j] > 0), sel & (vel[:, j] < 0)
            if up.sum() > 5 and down.sum() > 5:
                splits[label].append(abs(np.mean(r[down]) - np.mean(r[up])))
                weights[label].append(1.0)
        rv, vv = r[mv] - np.mean(r[mv]), vel[mv, j] - np.mean(vel[mv, j])
        denom = np.sqrt(np.sum(rv**2) * np.sum(vv**2))
        if denom > 0:
            corr_num += abs(np.sum(rv * vv)) / denom
            corr_den += 1.0
        y = trial.y[valid, j]
        lo, hi = np.quantile(y, [0.05, 0.95])
        outer = valid & np.isfinite(r) & ((trial.y[:, j] < lo) | (trial.y[:, j] > hi))
        mid = valid & np.isfinite(r) & ~outer
        if not outer.any() or not mid.any():  # its extremes (or middle) are not scored
            continue
        excess_out.append(np.mean(r[outer] ** 2))
        excess_mid.append(np.mean(r[mid] ** 2))
    slow = float(np.mean(splits["slow"])) if splits["slow"] else 0.0
    fast = float(np.mean(splits["fast"])) if splits["fast"] else 0.0
    holds = _holds(mot["still"], valid, trial.rate_hz)
    changes = []
    skip = int(0.2 * trial.rate_hz)
    for start, stop in holds:
        seg = residual[start + skip:stop]
        seg = seg[np.all(np.isfinite(seg), axis=1)]
        if seg.shape[0] > 10:
            head = seg[: max(3, seg.shape[0] // 10)].mean(axis=0)
            tail = seg[-max(3, seg.shape[0] // 10):].mean(axis=0)
            changes.append(np.mean((tail - head) ** 2))
    relax = float(np.sqrt(np.mean(changes))) / floor if changes and floor > 0 else 0.0
    ok = valid & np.all(np.isfinite(residual), axis=1)
    tn = (trial.t[ok] - trial.t[0]) / max(trial.t[-1] - trial.t[0], 1e-9)
    design = np.vander(tn, 4)
    r = residual[ok]
    coef, *_ = np.linalg.lstsq(design, r, rcond=None)
    r0 = r - r.mean(axis=0)
    trend = 1.0 - float(np.sum((r - design @ coef) ** 2) / max(np.sum(r0**2), 1e-300))
    extreme = (float(np.sqrt(np.mean(excess_out) / max(np.mean(excess_mid), 1e-300)))
               if excess_out else 1.0)
    return {
        "direction_split_slow": significant(slow),
        "direction_split_fast": significant(fast),
        "rate_independence": round(slow / fast, 4) if fast > 0 else 0.0,
        "velocity_correlation": round(corr_num / corr_den, 4) if corr_den else 0.0,
        "hold_relaxation": round(relax, 4),
        "time_trend": round(trend, 4),
        "extreme_excess": round(extreme, 4),
    }
