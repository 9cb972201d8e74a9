"""Why the discrepancy workflow names an effect: rules 1–4 on held-out blocks.

A candidate is *significant* when, on held-out
contiguous blocks (blocked cross-validation: every block is predicted by a model fitted on
the others), it

1. removes systematic error larger than the measurement noise: the drop in held-out mean
   squared error ΔMSE exceeds σ², σ being the white-noise floor estimated from second
   differences (:func:`~.data.noise_floor`); an effect whose contribution per sample is
   below the sensor noise cannot be told from it (signal-to-noise ratio < 1), and
2. does not rest on a few blocks: ΔMSE stays positive when the block with the largest
   improvement is left out (evidence from at least two independent stretches of time), and
   the candidate lowers the error on so many blocks that chance would rarely do it (a sign
   test at ``SIGN_TEST_LEVEL``: 7 of 8). A model that misses the static map by many noise
   variances (a foreign geometry) lets any flexible term win a little on some blocks and
   lose on others; a physical effect acts everywhere the motion shows it. A drift is
   counted again on its refined form (:func:`~.workflow._counted_refined`), and once more
   before the workflow concludes that nothing is significant
   (:func:`~.workflow._last_count`).

A stop is a local effect: a clamp on one sensor of five can remove more than that sensor's
noise and still less than the noise of all five. So a saturation candidate that holds some
sensors at a hard stop (each sits on a plateau while the joint moves, its physical
signature, see :func:`~.stops.plateaus`) is also significant
when rules 1 and 2 hold on those sensors alone, against their own noise, or on the frames
it holds there alone (without rule 2's count, as those frames lie only in the blocks where
the arm reached the stop) while it lowers those sensors' held-out error as a whole: a stop
reached on 5 % of the frames changes only those, and a map fitted through it spreads what
it cannot bend over the rest, but a map so foreign to the suit that the stops make it worse
overall explains nothing by them. Those frames must be as many
as a plateau spans (the share of the signature): a map that passes the stop on a handful
of frames shows no plateau there.

Any other effect can also act on some sensors only (one sensor's warm-up, one sheath's
creep): it is also significant when rules 1 and 2 hold on one sensor alone, against that
sensor's noise, with rule 2's sign test shared among the sensors (Bonferroni: each at
``SIGN_TEST_LEVEL`` divided by their number, every one of eight blocks), so that a suit
with more sensors is not given more chances to name what its map misses on one of them,
and the candidate lowers the held-out error of all sensors together (also without its
best block): a term that follows one sensor's misfit and fits noise on the others does not.
Stops are judged on their plateaus instead (above): a map that misses one sensor bends
like a stop there.

3. A stop must bend more than a smooth curve: a significant saturation is fitted again on
   top of a cubic transfer curve of each sensor's static prediction and must clear rules 1
   and 2 over that curve alone (:func:`~.workflow._against_curve`), unless it explains
   everything the curve would: the curve added to the stops does not clear rule 1 over
   them, and the stops alone predict the held-out blocks better than the curve alone.
   Knees at both ends of a sensor can imitate a reading that curves gently over its whole
   range, which is calibration; a stop approached gently is a bend that both follow, and
   the better one that leaves the other nothing to add is the explanation.

4. The gain must hold over whole movements: averaged over ``MOVEMENT_S`` windows, the
   held-out residual's error must be lower with the candidate than without it (ΔMSE of
   that slow part > 0, :func:`over_movements`). Each of the five effects follows the pose,
   the direction or speed of motion, or time, which hold for longer than that; noise in
   the motion capture's angles, seen through the suit, changes from frame to frame. A term
   that smooths the simulation (a play operator about as wide as that noise) removes some
   of the fast error and adds its own over each movement: on a clean suit whose angles
   carry 1° of white noise, read at 6 Hz, hysteresis lowered the held-out error by 1.6–2.3
   noise variances and raised its slow part's. The rule is taken on all sensors together,
   for every way a candidate may clear rules 1 and 2 (pooled, on one sensor, at hard
   stops); a drift's jump in a hold (:func:`~.workflow._jumped_in_hold`) and a sensor
   pinned at a rail (:func:`~.workflow._at_rail`) are signatures of their own and are not
   asked it.

Held-out error already charges a candidate for its extra parameters (fitting noise makes
held-out error worse, not better), so no parameter-count penalty is added. Among significant
candidates the largest ΔMSE is named; the workflow stops when none is significant.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.ndimage import uniform_filter1d

from exohil.emulators.discrepancy.data import Trial
from exohil.emulators.discrepancy.figures import MSE_DIGITS, significant
from exohil.emulators.discrepancy.folds import block_mse
from exohil.emulators.discrepancy.model import Fit
from exohil.emulators.discrepancy.stops import PLATEAU_SHARE

#: Rule 2's sign test: the largest chance that a candidate no better than the model it
#: extends improves as many held-out blocks as it must (7 of 8 blocks: 3.5 %).
SIGN_TEST_LEVEL = 0.05


#: Rule 4's window, s: about the shortest time a human movement holds its direction, and
#: long enough to average out angle noise low-passed at a few Hz (a boxcar of 0.5 s passes
#: half the power at 0.9 Hz and none at 2 Hz).
MOVEMENT_S = 0.5


def windowed_mean(trial: Trial, residual: np.ndarray, span_s: float) -> np.ndarray:
    """The held-out ``residual`` (N, S) averaged over centred windows of ``span_s`` seconds
    of its scored frames, per sensor; NaN where ``residual`` is."""
    window = max(int(round(span_s * trial.rate_hz)), 1)
    finite = np.isfinite(residual)
    sums = uniform_filter1d(np.where(finite, residual, 0.0), window, axis=0, mode="constant")
    counts = uniform_filter1d(finite.astype(float), window, axis=0, mode="constant")
    return np.where(finite, sums / np.maximum(counts, 1e-12), np.nan)


def over_movements(trial: Trial, base: Fit, cand: Fit) -> dict:
    """Rule 4 (the module's docstring): the held-out ΔMSE of the residual averaged over
    ``MOVEMENT_S`` windows, ``cand`` over ``base``, sensor units², and the blocks whose
    error it lowers; ``holds`` where that ΔMSE is positive (``fails_alone`` is set by
    :func:`candidate_evidence`)."""
    slow = rules_on_blocks(block_mse(trial, windowed_mean(trial, base.residual, MOVEMENT_S)),
                           block_mse(trial, windowed_mean(trial, cand.residual, MOVEMENT_S)),
                           0.0)
    return {"window_s": MOVEMENT_S, "delta_mse": slow["delta_mse"],
            "blocks_improved": slow["blocks_improved"], "holds": slow["delta_mse"] > 0}


def blocks_needed(n: int, level: float = SIGN_TEST_LEVEL) -> int:
    """The fewest of ``n`` blocks a candidate must improve to pass rule 2's sign test: so many
    that a candidate no better than the model it extends (each block as likely to improve
    as not) improves that many with probability at most ``level``; ``n + 1`` when no count
    is that unlikely (too few blocks to tell)."""
    for k in range(n + 1):
        if sum(math.comb(n, i) for i in range(k, n + 1)) / 2.0**n <= level:
            return k
    return n + 1


def rules_on_blocks(base_mse: np.ndarray, cand_mse: np.ndarray, floor: float,
           level: float = SIGN_TEST_LEVEL) -> dict:
    """Rules 1 and 2 (the module's docstring) from held-out MSE per block, over the blocks
    with scored frames, against white noise of RMS ``floor``, rule 2's sign test at
    ``level``."""
    delta = base_mse - cand_mse
    delta = delta[np.isfinite(delta)]
    dmse = float(np.mean(delta)) if delta.size else 0.0
    robust = float(np.mean(np.sort(delta)[:-1])) if delta.size > 1 else 0.0
    improved, needed = int(np.sum(delta > 0)), blocks_needed(delta.size, level)
    beyond_noise = bool(dmse > floor**2 and robust > 0)
    return {
        "delta_mse": significant(dmse, MSE_DIGITS),
        "removed_rms": significant(np.sqrt(max(dmse, 0.0))),
        "noise_floor": significant(floor),
        "blocks_improved": improved,
        "blocks_needed": needed,
        "delta_mse_without_best_block": significant(robust, MSE_DIGITS),
        "beyond_noise": beyond_noise,
        "significant": beyond_noise and improved >= needed,
    }


def adds_stops(base: Fit, cand: Fit) -> bool:
    """Whether ``cand`` is ``base`` with the stops (saturation) added."""
    return cand.spec.saturation and not base.spec.saturation


def held_at_stops(trial: Trial, base: Fit, cand: Fit) -> dict | None:
    """Rules 1 and 2 on the sensors ``cand`` holds at a hard stop, against their own noise,
    over all their frames, or over the frames it holds where it also lowers those sensors'
    held-out error over all their frames (see the module's docstring); None
    unless ``cand`` adds the stops and holds a sensor at one on as many frames as a plateau
    spans (``PLATEAU_SHARE`` of the scored frames)."""
    if not adds_stops(base, cand):
        return None
    hard = [j for j, st in enumerate(cand.stops) if st.hard]
    at_stop = np.zeros((trial.n, len(hard)), dtype=bool)
    for k, j in enumerate(hard):  # frames the fitted map takes beyond a hard stop
        st, p = cand.stops[j], cand.prediction[:, j]
        at_stop[:, k] = ((st.soft_lo == 0) & (p == st.lo)) | ((st.soft_hi == 0) & (p == st.hi))
    # a stop the map reaches on fewer frames than a plateau spans holds no plateau there:
    # its sensor is not held (a stop at the end of a copy's range that binds on no frame
    # would add that sensor's noise to the held sensors' and name it as held)
    holds = at_stop[trial.scored].mean(axis=0) >= PLATEAU_SHARE
    if not holds.any():
        return None
    held, at_stop = [j for j, h in zip(hard, holds, strict=True) if h], at_stop[:, holds]
    noise = float(np.sqrt(np.mean(trial.noise[held] ** 2)))
    sensors = rules_on_blocks(block_mse(trial, base.residual[:, held]),
                     block_mse(trial, cand.residual[:, held]), noise)
    frames = rules_on_blocks(block_mse(trial, np.where(at_stop, base.residual[:, held], np.nan)),
                    block_mse(trial, np.where(at_stop, cand.residual[:, held], np.nan)), noise)
    return {"sensors": [trial.sensor_names[j] for j in held], **sensors,
            # the frames held lie only in the folds where the arm reached the stop (four of
            # eight can never pass rule 2's count); the plateau there is the evidence, where
            # the stops do not make the held sensors' held-out error worse as a whole
            "significant": sensors["significant"] or (frames["beyond_noise"]
                                                      and sensors["delta_mse"] > 0),
            "frames_held": {"share": round(float(at_stop[trial.scored].mean()), 4), **frames}}


def on_one_sensor(trial: Trial, base: Fit, cand: Fit, pooled: dict) -> dict | None:
    """Rules 1 and 2 on each sensor alone, against its own noise, with rule 2's sign test
    shared among the sensors (Bonferroni: at ``SIGN_TEST_LEVEL`` / sensors each, so every
    one of eight blocks with up to twelve sensors, and never with more): the sensors where
    ``cand`` passes, or None with one sensor. None passes unless ``cand`` also lowers the
    held-out error of all sensors together, without its best block too (``pooled``: its
    rules over all of them): a term that follows what the map misses on one sensor and
    fits noise on the others makes the model worse."""
    if trial.n_sensors < 2:
        return None
    if not (pooled["delta_mse"] > 0 and pooled["delta_mse_without_best_block"] > 0):
        return {"significant": False, "pooled_error_lowered": False, "sensors": {},
                "beyond_noise_sensors": []}
    level = SIGN_TEST_LEVEL / trial.n_sensors
    passing, beyond_noise = {}, []
    for j in range(trial.n_sensors):
        rules = rules_on_blocks(block_mse(trial, base.residual[:, [j]]),
                       block_mse(trial, cand.residual[:, [j]]), float(trial.noise[j]), level)
        if rules["beyond_noise"]:
            beyond_noise.append(trial.sensor_names[j])
        if rules["significant"]:
            passing[trial.sensor_names[j]] = {
                k: rules[k] for k in ("delta_mse", "removed_rms", "noise_floor",
                                      "blocks_improved", "blocks_needed")}
    return {"significant": bool(passing), "pooled_error_lowered": True, "sensors": passing,
            "beyond_noise_sensors": beyond_noise}


def beyond_noise_somewhere(evidence: dict) -> bool:
    """Rule 1 and the first half of rule 2 (without the sign test), pooled over the sensors
    or on one sensor alone (:func:`on_one_sensor`)."""
    alone = evidence.get("on_one_sensor")
    return bool(evidence["beyond_noise"] or (alone and alone["beyond_noise_sensors"]))


def candidate_evidence(trial: Trial, base: Fit, cand: Fit, floor: float) -> dict:
    """Rules 1 and 2 for ``cand`` over ``base``, pooled over the sensors; a candidate that adds
    stops is also judged on the sensors it holds at hard stops, any other on each sensor
    alone; then rule 4 (:func:`over_movements`)."""
    rules = rules_on_blocks(base.block_mse, cand.block_mse, floor)
    held = held_at_stops(trial, base, cand)
    alone = None if adds_stops(base, cand) else on_one_sensor(trial, base, cand, rules)
    for extra in (held, alone):
        if extra is not None:
            rules["significant"] = rules["significant"] or extra["significant"]
    movements = over_movements(trial, base, cand)
    movements["fails_alone"] = bool(rules["significant"] and not movements["holds"])
    rules["significant"] = rules["significant"] and movements["holds"]
    return {
        "heldout_gap": significant(cand.gap),
        "gap_reduction": round((base.gap - cand.gap) / base.gap, 4) if base.gap > 0 else 0.0,
        **rules,
        "config": cand.spec.config(),
        **({} if held is None else {"held_at_stops": held}),
        **({} if alone is None else {"on_one_sensor": alone}),
        "over_movements": movements,
    }


def stops_leave_curve_nothing(stops: Fit, curve: Fit, curve_adds: dict, floor: float
                               ) -> tuple[bool, dict]:
    """Rule 3's other branch: the curve added to the stops does not clear rule 1 over them
    (``curve_adds``), and the stops alone predict the held-out blocks better than the curve
    alone, on the whole and in as many blocks as rule 2's sign test asks: two explanations
    of one bend that each win some blocks are a tie, and a tie names nothing. Also the
    rules of the stops alone against the curve alone."""
    stops_vs_curve = rules_on_blocks(curve.block_mse, stops.block_mse, floor)
    return (bool(not curve_adds["beyond_noise"] and stops.gap < curve.gap
                 and stops_vs_curve["blocks_improved"] >= stops_vs_curve["blocks_needed"]),
            stops_vs_curve)


def pooled_noise(trial: Trial) -> float:
    """The recording's noise RMS over its sensors (the naming rule's σ), sensor units."""
    return float(np.sqrt(np.mean(trial.noise**2)))


def remainder(trial: Trial, fit: Fit, floor: float) -> dict:
    """What ``fit`` (the final model) leaves on the held-out blocks beyond the noise, in
    noise variances, rule 1's unit: (gap² − σ²) / σ², pooled over the sensors against the
    pooled floor ``floor`` and per sensor against its own. ``beyond_noise`` where the pooled
    figure is more than one, the bar an effect must clear to be named: the model then leaves
    systematic error that no candidate explained (the static map's, an effect outside the
    vocabulary's, or the motion capture's angle noise seen through the suit, which the
    sensors' floor does not count). None where a sensor has no scored frame."""

    def variances(gap: float, sigma: float) -> float | None:
        if not (np.isfinite(gap) and sigma > 0):
            return None
        return round(float((gap**2 - sigma**2) / sigma**2), 3)

    pooled = variances(fit.gap, floor)
    per_sensor = [variances(float(g), float(s)) for g, s in zip(fit.sensor_gap(), trial.noise,
                                                                 strict=True)]
    return {
        "gap_over_floor": round(fit.gap / floor, 3) if floor > 0 else None,
        "noise_variances": pooled,
        "sensor_noise_variances": per_sensor,
        "beyond_noise": bool(pooled is not None and pooled > 1.0),
        "beyond_noise_sensors": [name for name, v in zip(trial.sensor_names, per_sensor,
                                                         strict=True)
                                 if v is not None and v > 1.0],
    }
