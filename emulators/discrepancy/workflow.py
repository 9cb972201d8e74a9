"""The discrepancy workflow: calibrate, simulate, localise, name the missing effect, add it,
repeat until nothing significant remains.

Why an effect is named, and when nothing is: the decision rule (:mod:`.rules`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from scipy.ndimage import uniform_filter1d
from scipy.optimize import minimize, minimize_scalar

from exohil.emulators.discrepancy.data import (
    BLOCK_S,
    FRAME_COUNTER,
    MOCAP_CUTOFF_HZ,
    SPIKE_SIGMAS,
    SPIKE_WINDOW,
    Trial,
    prepare_trial,
    spike_counts,
)
from exohil.emulators.discrepancy.folds import block_mse
from exohil.emulators.discrepancy.localise import localise, motion, signatures
from exohil.emulators.discrepancy.model import (
    LOCAL_DEGREE,
    LOCAL_RIDGES,
    LOCAL_STATIC_RIDGES,
    STATIC_RIDGES,
    Fit,
    Inputs,
    Spec,
    drift_columns,
    fit,
    make_inputs,
    restrict_to_coverage,
    static_basis,
)
from exohil.emulators.discrepancy.rules import (
    beyond_noise_somewhere,
    candidate_evidence,
    rules_on_blocks,
    stops_leave_curve_nothing,
)
from exohil.emulators.discrepancy.timing import (
    clock_offset,
    clock_words,
    filter_words,
    lead_after_effects,
    mocap_filter,
    read_trial,
)
from exohil.emulators.discrepancy.workers import forked_map, one_blas_thread, workers_for
from exohil.formats.recording import Recording

VOCABULARY = ("hysteresis", "creep", "saturation", "lag", "drift")
#: The vocabulary by how long a candidate usually takes to fit (stops are chosen per sensor
#: on held-out blocks, lags refined on three grids): the order a step hands them to its
#: processes, so that the longest do not start last.
COSTLIEST_FIRST = ("saturation", "lag", "creep", "drift", "hysteresis")
LAG_TAU_S = (0.01, 0.02, 0.04, 0.08, 0.2)
LAG_DELAY_S = (0.01, 0.025, 0.06, 0.15)
#: Relative precision of the refined lag (log seconds).
LAG_LOG_TOL = 0.02
#: Search of a named lag's low-pass-plus-delay model (Nelder–Mead on the log total lag and
#: the delay's share of it): first steps, tolerances and the most fits it may spend.
LAG_TOTAL_LOG_STEP = math.log(1.25)
LAG_SHARE_STEP = 0.3
LAG_SHARE_TOL = 0.02
LAG_MAX_FITS = 24
#: Rate-limit candidates: each sensor's limit at these quantiles of its static prediction's
#: speed over the valid frames where it moves (then searched between the best one's
#: neighbours).
RATE_LIMIT_QUANTILES = (0.7, 0.85, 0.93, 0.97, 0.99, 0.997, 0.999)
#: Golden-section steps of each sensor's log limit between its best quantile's neighbours.
RATE_LIMIT_STEPS = 7
CREEP_TAU_S = (1.5, 5.0, 15.0, 45.0)
#: (build, recover) pairs of the asymmetric creep state, s.
CREEP_ASYM_S = ((3.0, 9.0), (10.0, 30.0), (30.0, 90.0))
#: (grow, recover) pairs of the creep that flows only during holds, s.
CREEP_HOLD_S = ((3.0, 2.0), (3.0, 10.0), (20.0, 2.0), (20.0, 10.0))
#: Refinement of a named creep's time constants (Nelder–Mead on log seconds): first step,
#: tolerance and the most fits it may spend.
CREEP_LOG_STEP = math.log(1.6)
CREEP_LOG_TOL = 0.03
CREEP_MAX_FITS = 16
#: Range of a fitted creep time constant, s. Creep is a relaxation over seconds; faster is
#: the lag's range (unbounded, one graphene file reached a build 132 s / recover 6 ms state,
#: a one-sided lag, and on the default suit a 0.2 s low-pass stood in for the lag model's
#: missing delay); slower than ten minutes is a ramp over any recording (drift).
CREEP_TAU_RANGE_S = (1.0, 600.0)
DRIFT_DEGREES = (1, 2, 3)
#: Degrees a named drift is refined over (see _refine_drift), up to one per DRIFT_SPAN_S.
DRIFT_REFINE_DEGREES = (4, 6, 8, 12, 16, 24, 32, 48)
#: Shortest span of time one degree of a refined drift may stand for, s: twice a held-out
#: block, so the drift over a block is interpolated from the blocks around it.
DRIFT_SPAN_S = 2 * BLOCK_S


@dataclass
class Outcome:
    """Everything the workflow found.

    Attributes:
        trial: the recording on its grid.
        inputs: scaling, static input and caches of the final model.
        before / after: fits of the calibrated model before any effect was added and at the
            end.
        summary: the ``discrepancy.json`` content.
    """

    trial: Trial
    inputs: Inputs
    before: Fit
    after: Fit
    summary: dict


def _static_maps(inputs: Inputs) -> list[Spec]:
    """Static maps tried, each with every ridge: more polynomial degrees for fewer inputs
    (the basis grows as degree^inputs), and for an arm direction also the local basis beside
    a cubic (:func:`~.model.local_terms`) with each of its ridges."""
    n_inputs = inputs.u.shape[1]
    degrees = {1: range(1, 8), 2: range(2, 7), 3: range(2, 6)}.get(n_inputs, range(2, 4))
    maps = [Spec(degree=d, ridge=r) for d in degrees for r in STATIC_RIDGES]
    if inputs.centres.shape[0]:
        maps += [Spec(degree=LOCAL_DEGREE, local=True, local_ridge=q, ridge=r)
                 for q in LOCAL_RIDGES for r in LOCAL_STATIC_RIDGES]
    return maps


def _static_map(trial: Trial, inputs: Inputs, floor: float) -> Fit:
    """The static map with the lowest held-out gap, except that a map with the local basis
    must also beat the best polynomial bent at stops (saturation) by more than the noise,
    by rules 1 and 2 (the bar an effect must clear to be named). A stop is a static bend
    of the reading that local functions can follow too, taking it in as the pose's doing;
    so can a loop where the arm goes out and back on different paths. Of a flexible map and
    a physical explanation, the workflow keeps the second unless the local functions predict
    the held-out blocks better by more than it would take to name an effect (``floor``:
    the recording's pooled noise RMS, the bar's σ). Without rule 2's sign test: local
    functions help where the poses they cover are, so on some blocks more than others."""
    fits = [fit(trial, inputs, static_map) for static_map in _static_maps(inputs)]
    best = min(fits, key=lambda f: f.gap)
    if not best.spec.local:
        return best
    polynomial = min((f for f in fits if not f.spec.local), key=lambda f: f.gap)
    bent = _best(trial, inputs, "saturation", polynomial.spec)
    bends = rules_on_blocks(bent.block_mse, best.block_mse, floor)["beyond_noise"]
    return best if bends else polynomial


def steps_words(steps: list[dict], units: str) -> str:
    """The sudden changes of the reading (:func:`~.localise.reading_steps`) in words."""
    return "sudden changes of the reading no effect follows: " + "; ".join(
        f"{e['sensor']} {e['count']} ({e['at_a_recurring_pose']} at a pose of another, median "
        f"{e['median_size']:.4g} {units}, joint at {e['median_speed_deg_s']:.4g} deg/s)"
        for e in steps)


def _map_of(spec: Spec) -> tuple:
    """What identifies ``spec``'s static map."""
    return (spec.degree, spec.ridge) + ((spec.local_ridge,) if spec.local else ())


def map_words(static_map: dict) -> str:
    """A static map of the JSON (:func:`_map_summary`) in words, as progress line [2] and
    the report say it: "degree 4", "degree 3 and 212 local functions; straight runs on s1"."""
    local = static_map.get("local_functions", 0)
    runs = static_map.get("straight_runs", [])
    return (f"degree {static_map['degree']}" + (f" and {local} local functions" if local else "")
            + (f"; straight runs on {', '.join(runs)}" if runs else ""))


def _map_summary(spec: Spec, inputs: Inputs, runs: list[str]) -> dict:
    """The static map of ``spec`` for the JSON (``runs``: the sensors with a straight run)."""
    return {"kind": "legendre_polynomial_and_local" if spec.local else "legendre_polynomial",
            "degree": spec.degree,
            "local_functions": inputs.centres.shape[0] if spec.local else 0,
            "ridge": spec.ridge,
            **({"local_ridge": spec.local_ridge} if spec.local else {}),
            "straight_runs": runs}


def _candidates(kind: str, spec: Spec) -> list[Spec]:
    """The configurations of ``kind`` to try on top of ``spec`` (lag: see _refine_lag;
    creep: see _creep_families)."""
    if kind == "hysteresis":
        return [replace(spec, hysteresis=True)]
    if kind == "drift":
        return [replace(spec, drift_degree=d) for d in DRIFT_DEGREES]
    if kind == "saturation":  # see _best
        return [replace(spec, saturation=True)]
    raise ValueError(f"unknown effect {kind!r}; known: {', '.join(VOCABULARY)}")


def _best(trial: Trial, inputs: Inputs, kind: str, spec: Spec) -> Fit:
    """The candidate configuration of ``kind`` with the lowest held-out error."""
    if kind == "lag":  # refine each lag model between its grid neighbours, then compare
        return min([_refine_lag(trial, inputs, spec, "first_order", LAG_TAU_S),
                    _refine_lag(trial, inputs, spec, "delay", LAG_DELAY_S),
                    _rate_limit(trial, inputs, spec)],
                   key=lambda f: f.gap)
    if kind == "creep":
        return min(_creep_families(trial, inputs, spec), key=lambda f: f.gap)
    best = min((fit(trial, inputs, s) for s in _candidates(kind, spec)), key=lambda f: f.gap)
    if kind == "saturation":  # fitted between the stops, the map extrapolates into them: its
        # ridge is chosen again (a small one that interpolates well can extrapolate wildly),
        # through the stops chosen with the current one
        kept = _keep_stops(best).spec
        best = min([best] + [fit(trial, inputs, replace(kept, ridge=r)) for r in STATIC_RIDGES
                             if r != spec.ridge], key=lambda f: f.gap)
    return best


def _creep_families(trial: Trial, inputs: Inputs, spec: Spec) -> tuple[Fit, ...]:
    """The best creep of each family on its grid added to ``spec``: low-passes of the stretch
    (one time constant, then a second if it helps), the asymmetric build/recover state and
    the state that flows only during holds.
    Kept for the last ``spec`` asked: a named creep is refined from the grid it was
    compared on (:func:`_best`, then :func:`_refine`)."""
    kept = inputs.cache.get("creep_families")
    if kept is None or kept[0] != spec:
        kept = (spec, _creep_grids(trial, inputs, spec))
        inputs.cache["creep_families"] = kept
    return kept[1]


def pooled_noise(trial: Trial) -> float:
    """The recording's noise RMS over its sensors (the naming rule's σ), sensor units."""
    return float(np.sqrt(np.mean(trial.noise**2)))


def _flows_within_holds(trial: Trial, inputs: Inputs, held: Fit) -> bool:
    """A creep during holds must beat the same model with both time constants one frame
    long (an offset while still that does not flow within the hold) by the naming rule."""
    instant = fit(trial, inputs, replace(held.spec, creep_hold_s=(1.0 / trial.rate_hz,) * 2))
    return bool(candidate_evidence(trial, instant, held, pooled_noise(trial))["significant"])


def _creep_grids(trial: Trial, inputs: Inputs, spec: Spec) -> tuple[Fit, ...]:
    lows = min((fit(trial, inputs, replace(spec, creep_tau_s=(tau,))) for tau in CREEP_TAU_S),
               key=lambda f: f.gap)
    tau = lows.spec.creep_tau_s[0]
    lows = min([lows] + [fit(trial, inputs, replace(spec, creep_tau_s=(tau, other)))
                         for other in CREEP_TAU_S if other != tau], key=lambda f: f.gap)
    asym = min((fit(trial, inputs, replace(spec, creep_asym_s=pair)) for pair in CREEP_ASYM_S),
               key=lambda f: f.gap)
    hold = min((fit(trial, inputs, replace(spec, creep_hold_s=pair)) for pair in CREEP_HOLD_S),
               key=lambda f: f.gap)
    return (lows, asym, hold) if _flows_within_holds(trial, inputs, hold) else (lows, asym)


def _without_lag(trial: Trial, inputs: Inputs, spec: Spec) -> Fit:
    """The fit of ``spec`` (a model without a lag), kept for the last ``spec`` asked: both
    lag models compare every sensor against it."""
    kept = inputs.cache.get("without_lag")
    if kept is None or kept.spec != spec:
        kept = fit(trial, inputs, spec)
        inputs.cache["without_lag"] = kept
    return kept


def _where_it_helps(trial: Trial, lagged: Fit, plain: Fit) -> Fit:
    """``lagged`` (a low-pass or delay on every sensor) kept on the sensors whose held-out
    error it lowers, ``plain`` (the same model without the lag) on the others.

    Sensors are fitted independently, so the result is exactly the fit of the lag on those
    sensors alone (``Spec.lag_sensors``). A lag that no sensor is better for is returned
    as it is (it loses to ``plain``)."""
    keep = (np.nanmean(lagged.residual**2, axis=0) < np.nanmean(plain.residual**2, axis=0))
    if keep.all() or not keep.any():
        return lagged
    residual = np.where(keep, lagged.residual, plain.residual)
    return Fit(spec=replace(lagged.spec, lag_sensors=tuple(int(j) for j in np.flatnonzero(keep))),
               residual=residual, block_mse=block_mse(trial, residual),
               coef=[a if k else b for a, b, k in zip(lagged.coef, plain.coef, keep, strict=True)],
               prediction=np.where(keep, lagged.prediction, plain.prediction),
               stops=[a if k else b for a, b, k in zip(lagged.stops, plain.stops, keep,
                                                        strict=True)])


def _refine_lag(trial: Trial, inputs: Inputs, spec: Spec, lag_kind: str,
                grid: tuple[float, ...]) -> Fit:
    """The best time constant or delay of one lag model: grid, then a golden-section search
    on log(seconds) between the best grid point's neighbours (the held-out error is sharp in
    τ: 10 % off leaves a velocity-shaped residual).

    The lag acts on the sensors it brings closer (:func:`_where_it_helps`), and its value is
    chosen on that fit: a 9.5 ms low-pass on one sensor of five (the third blind generator's
    rec 1) takes that sensor from 45.4 to 15.5 mrad at 5 ms, while every lag on all five
    left a larger gap than none (28.8 mrad) or the same.
    """
    plain = _without_lag(trial, inputs, spec)

    def lagged(value: float) -> Fit:
        return _where_it_helps(
            trial, fit(trial, inputs, replace(spec, lag_kind=lag_kind, lag_s=value)), plain)

    fits = {v: lagged(v) for v in grid}
    k = min(range(len(grid)), key=lambda i: fits[grid[i]].gap)
    lo = math.log(grid[max(k - 1, 0)] if k > 0 else grid[0] / 2)
    hi = math.log(grid[min(k + 1, len(grid) - 1)] if k < len(grid) - 1 else grid[-1] * 2)

    def gap(log_s: float) -> float:
        value = math.exp(log_s)
        if value not in fits:
            fits[value] = lagged(value)
        return fits[value].gap

    minimize_scalar(gap, bounds=(lo, hi), method="bounded",
                    options={"xatol": LAG_LOG_TOL, "maxiter": 8})
    return min(fits.values(), key=lambda f: f.gap)


def _rate_limit(trial: Trial, inputs: Inputs, spec: Spec) -> Fit:
    """The best rate limit per sensor added to ``spec`` (without its lag).

    A slew-rate limit is not a linear filter: the reading falls behind only while the pose
    moves faster than the limit and catches up afterwards, so the residual lives in the
    fastest moves, whatever their frequency. Each sensor's limit is searched on its own
    (sensors are fitted independently, so every fit tries one limit per sensor): at the
    ``RATE_LIMIT_QUANTILES`` of its static prediction's speed, then by golden-section search
    on the log limit between the best one's neighbours (the held-out error is sharp in the
    limit: on a suit limited at its 99.5th percentile of speed, the 99th and 99.7th leave
    a third of the effect or more).

    A limit counts only with a positive gain: the reading falls behind, it never runs ahead
    (a negative gain at a very low limit is a filter of the pose's history, creep's
    ground, not a rate limit). A sensor with no such limit gets none (rate +inf).
    """
    spec = spec.without_lag()
    speed = np.abs(np.gradient(inputs.static, axis=0))[trial.valid] * trial.rate_hz
    # quantiles of the speed while the prediction moves: a recording that holds still most
    # of the time would otherwise put the lower quantiles at 0 units/s
    grid = np.log(np.column_stack([np.quantile(v[v > 0] if (v > 0).any() else np.ones(1),
                                               RATE_LIMIT_QUANTILES) for v in speed.T]))
    sensors = np.arange(grid.shape[1])
    n_static = static_basis(inputs, spec.degree, spec.local).shape[1]

    def at(log_rates: np.ndarray) -> tuple[Fit, np.ndarray]:
        """The fit with these limits and its held-out mean squared error per sensor (+inf
        where the limit's gain is not positive)."""
        rates = tuple(float(f"{r:.5g}") for r in np.exp(log_rates))
        f = fit(trial, inputs, replace(spec, lag_kind="rate_limit", lag_rates=rates))
        col = _column_slices(f.spec, n_static, inputs.thresholds.shape[1])["lag"].start
        gain = np.array([c[col] for c in f.coef])
        return f, np.where(gain > 0, np.nanmean(f.residual[trial.scored] ** 2, axis=0), np.inf)

    mse = np.array([at(g)[1] for g in grid])  # (Q, S)
    k = np.argmin(mse, axis=0)
    lo = grid[np.maximum(k - 1, 0), sensors] - np.where(k == 0, math.log(2.0), 0.0)
    hi = grid[np.minimum(k + 1, len(grid) - 1), sensors] + np.where(
        k == len(grid) - 1, math.log(2.0), 0.0)
    golden = (math.sqrt(5.0) - 1.0) / 2.0
    x1, x2 = hi - golden * (hi - lo), lo + golden * (hi - lo)
    f1, f2 = at(x1)[1], at(x2)[1]
    for _ in range(RATE_LIMIT_STEPS):  # every sensor's bracket shrinks by the golden ratio
        left = f1 < f2  # the minimum lies in [lo, x2]
        hi, lo = np.where(left, x2, hi), np.where(left, lo, x1)
        x1, x2, f1, f2 = (np.where(left, hi - golden * (hi - lo), x2),
                          np.where(left, x1, lo + golden * (hi - lo)),
                          np.where(left, np.nan, f2), np.where(left, f1, np.nan))
        new = np.where(left, x1, x2)
        m = at(new)[1]
        f1, f2 = np.where(left, m, f1), np.where(left, f2, m)
    candidates = np.vstack([grid[k, sensors], x1, x2])
    scores = np.vstack([mse[k, sensors], f1, f2])
    chosen = candidates[np.argmin(scores, axis=0), sensors]
    return at(np.where(np.isfinite(scores.min(axis=0)), chosen, np.inf))[0]


def _refine_lag_delay(trial: Trial, inputs: Inputs, current: Fit) -> Fit:
    """A named lag refined as a low-pass followed by a delay (first order plus dead time),
    of which the low-pass alone and the delay alone are the two ends.

    Nelder–Mead on (log T, share), T = τ + delay the total lag and share = delay / T, from
    the current lag (first named: the single model that won, share 0 or 1; once another
    effect is added, the lag as refitted before). A cascade of low-passes, or a low-pass
    behind a transport delay and a clock offset, is neither end: on the default suit (30 ms
    low-pass, 8 ms delay, 12 ms clock offset) the low-pass alone leaves 0.74 mm, τ 30 ms with
    20 ms of delay 0.32 mm. The current lag is kept unless another beats it held out.
    Each point acts on the sensors it brings closer (:func:`_where_it_helps`), chosen
    again: the grid's choice was made on the map without the lag.
    """
    spec = current.spec
    if spec.lag_kind == "rate_limit":  # no low-pass or delay: its limits, searched again
        # on the model as it is now (another degree, or the next effect added)
        return min([current, _rate_limit(trial, inputs, spec)], key=lambda f: f.gap)
    total0 = spec.lag_s + spec.lag_delay_s
    share0 = {"delay": 1.0, "first_order": 0.0}.get(spec.lag_kind, spec.lag_delay_s / total0)
    fits = {(round(math.log(total0), 6), round(share0, 6)): current}
    plain = _without_lag(trial, inputs, spec.without_lag())

    def gap(point: np.ndarray) -> float:
        key = (round(float(point[0]), 6), round(float(point[1]), 6))
        if key not in fits:
            total, share = math.exp(key[0]), min(max(key[1], 0.0), 1.0)
            fits[key] = _where_it_helps(trial, fit(trial, inputs, replace(
                spec, lag_kind="first_order_delay", lag_s=float(f"{total * (1 - share):.4g}"),
                lag_delay_s=float(f"{total * share:.4g}"), lag_sensors=())), plain)
        return fits[key].gap

    start = np.array([math.log(total0), share0])
    inward = LAG_SHARE_STEP if share0 < 0.5 else -LAG_SHARE_STEP
    simplex = np.vstack([start, start + [LAG_TOTAL_LOG_STEP, 0.0], start + [0.0, inward]])
    minimize(gap, start, method="Nelder-Mead", bounds=[(-math.inf, math.inf), (0.0, 1.0)],
             options={"initial_simplex": simplex, "xatol": LAG_SHARE_TOL, "fatol": 0.0,
                      "maxfev": LAG_MAX_FITS})
    return min(fits.values(), key=lambda f: f.gap)


def _refine(trial: Trial, inputs: Inputs, kind: str, current: Fit) -> Fit:
    """Refine the continuous shape parameters of a named effect from its best grid point.

    The candidates' grids are coarse (creep: time constants a factor of 3 apart) so that every
    effect is compared at a modest cost; once one is named its parameters are fitted properly.
    Creep: a Nelder–Mead search on the log time constants minimising the held-out error, from
    the best grid point of each family (one or two low-passes; the build/recover pair of the
    asymmetric state): the family that wins on the grid need not win refined (a symmetric
    pair 0.199 mm on the grid, 0.194 refined; the asymmetric state 0.222 and 0.157), and the
    refined low-passes once more with a quadratic driver (``Spec.creep_quadratic``: a load
    that is not proportional to the stretch). Saturation:
    the stops chosen in its candidate fit are kept from here on (:func:`_keep_stops`). Lag: each
    single model is already refined on its grid (:func:`_refine_lag`), then the low-pass and
    the delay together (:func:`_refine_lag_delay`); a rate limit was searched in full by
    :func:`_best` on this very model, so searching it again would return the same fit. The
    other effects have no shape parameter.
    """
    if kind == "saturation":
        return _keep_stops(current)
    if kind == "lag":
        return (current if current.spec.lag_kind == "rate_limit"
                else _refine_lag_delay(trial, inputs, current))
    if kind == "drift":
        return _refine_drift(trial, inputs, current)
    if kind != "creep":
        return current
    bare = replace(current.spec, creep_tau_s=(), creep_asym_s=(), creep_hold_s=())
    refined = [_refine_creep(trial, inputs, start)
               for start in _creep_families(trial, inputs, bare)]
    lows = refined[0]
    refined = [f for f in refined if not f.spec.creep_hold_s
               or _flows_within_holds(trial, inputs, f)]
    # the low-passes again with a driver that is not proportional to the stretch
    quadratic = _refine_creep(trial, inputs, fit(trial, inputs, replace(
        lows.spec, creep_quadratic=True)))
    return min(refined + [quadratic], key=lambda f: f.gap)


def _refine_drift(trial: Trial, inputs: Inputs, current: Fit) -> Fit:
    """A named drift refined over more functions of time, the best held out.

    Degrees 1–3 only rank the candidates: a more flexible function of time would also explain
    a slow pose-driven relaxation (degrees up to 34 named 4 of 20 creeps drift). Once drift is
    named it may follow an offset that wanders (a random walk, a piecewise ramp, a slip step)
    as finely as the held-out blocks allow: at most one function per ``DRIFT_SPAN_S`` seconds,
    as a Legendre polynomial (a smooth warm-up or cycle) or as a piecewise-linear function
    on even knots (a step or a walk, followed locally where a polynomial rings over the
    whole recording). The choice is made again, from degree 1 up, after each effect added
    later (see :func:`run`): one made before another effect was in place may have stood in
    for part of it. Kept for the last ``current`` asked: a drift counted on its refined form
    (:func:`_counted_refined`) and then named is refined from the same fit.
    """
    kept = inputs.cache.get("refined_drift")
    if kept is not None and kept[0] == current.spec:
        return kept[1]
    here = _drift_of(current.spec)
    refined = min([current] + [fit(trial, inputs, replace(current.spec, drift_degree=d,
                                                           drift_piecewise=piecewise))
                               for d, piecewise in drift_options(inputs.t_span[1]
                                                                 - inputs.t_span[0])
                               if (d, piecewise) != here],
                  key=lambda f: f.gap)
    inputs.cache["refined_drift"] = (current.spec, refined)
    return refined


def drift_options(span_s: float) -> list[tuple[int, bool]]:
    """(count, piecewise) of every drift a named drift is refined over on ``span_s`` seconds
    of recording: Legendre degrees and piecewise-linear intervals, at most one function per
    ``DRIFT_SPAN_S``."""
    options = [(d, False) for d in DRIFT_DEGREES + DRIFT_REFINE_DEGREES]
    options += [(d, True) for d in DRIFT_REFINE_DEGREES]
    return [(d, piecewise) for d, piecewise in options if d * DRIFT_SPAN_S <= span_s]


def _refine_creep(trial: Trial, inputs: Inputs, current: Fit) -> Fit:
    """Nelder–Mead on the log time constants of ``current``'s creep term, within
    ``CREEP_TAU_RANGE_S``."""
    spec = current.spec
    field = ("creep_asym_s" if spec.creep_asym_s else "creep_hold_s" if spec.creep_hold_s
             else "creep_tau_s")
    start = np.log(np.asarray(getattr(spec, field), dtype=float))
    fits = {tuple(start.round(6)): current}

    def gap(log_s: np.ndarray) -> float:
        key = tuple(np.asarray(log_s).round(6))
        if key not in fits:
            values = tuple(float(f"{v:.4g}") for v in np.exp(key))
            shaped = (replace(spec, creep_asym_s=values) if field == "creep_asym_s" else
                      replace(spec, creep_hold_s=values) if field == "creep_hold_s" else
                      replace(spec, creep_tau_s=values))
            fits[key] = fit(trial, inputs, shaped)
        return fits[key].gap

    simplex = np.vstack([start] + [start + CREEP_LOG_STEP * np.eye(start.size)[i]
                                   for i in range(start.size)])
    bounds = [(math.log(CREEP_TAU_RANGE_S[0]), math.log(CREEP_TAU_RANGE_S[1]))] * start.size
    minimize(gap, start, method="Nelder-Mead", bounds=bounds,
             options={"initial_simplex": simplex, "xatol": CREEP_LOG_TOL, "fatol": 0.0,
                      "maxfev": CREEP_MAX_FITS})
    return min(fits.values(), key=lambda f: f.gap)


def _keep_stops(current: Fit) -> Fit:
    """Keep the stops (levels, softness and shape per sensor) chosen in ``current`` from here on:
    later candidates refit the map through them instead of choosing them again in every fit.
    Without the saturation term, ``current`` as it is."""
    if not current.spec.saturation or current.spec.stops:
        return current
    return replace(current, spec=replace(current.spec, stops=tuple(current.stops)))


def _best_degree(trial: Trial, inputs: Inputs, current: Fit) -> Fit:
    """Re-choose the static map's degree and ridges with the effect terms in place: an
    unexplained effect makes the static-only fit prefer a stiffer map than the suit needs.
    The map keeps its kind (a polynomial, or local functions) chosen at calibration: trying
    the local functions under every effect, each with its lag, cost minutes per recording."""
    spec = current.spec
    others = [fit(trial, inputs, replace(spec, degree=m.degree, local=m.local,
                                         local_ridge=m.local_ridge, ridge=m.ridge))
              for m in _static_maps(inputs)
              if m.local == spec.local and _map_of(m) != _map_of(spec)]
    return min([current] + others, key=lambda f: f.gap)


def _column_slices(spec: Spec, n_static: int, n_play: int) -> dict[str, slice]:
    """Where each term's coefficients sit in a sensor's coefficient vector."""
    out, at = {}, n_static
    for kind, width in (("hysteresis", n_play if spec.hysteresis else 0),
                        ("creep", len(spec.creep_tau_s) * (2 if spec.creep_quadratic else 1)
                         + (1 if spec.creep_asym_s else 0) + (2 if spec.creep_hold_s else 0)),
                        ("lag", 1 if spec.lag_kind == "rate_limit" else 0),
                        ("drift", spec.drift_degree)):
        out[kind] = slice(at, at + width)
        at += width
    return out


def effect_params(kind: str, result: Fit, inputs: Inputs, trial: Trial) -> dict:
    """The fitted parameters of one effect term, per sensor where they differ (sensor units
    unless the name says otherwise)."""
    spec = result.spec
    n_static = static_basis(inputs, spec.degree, spec.local).shape[1]
    cols = _column_slices(spec, n_static, inputs.thresholds.shape[1]).get(kind, slice(0, 0))
    if kind == "hysteresis":
        weights = [c[cols] for c in result.coef]
        # rising: ŝ − play = +r, and the rising branch reads low, so the full width
        # (falling − rising) after a large excursion is −2 Σ w·r
        width = [float(-2.0 * np.dot(w, r)) for w, r in zip(weights, inputs.thresholds,
                                                              strict=True)]
        return {"loop_width": [round(w, 5) for w in width],
                "play_thresholds": np.round(inputs.thresholds, 5).tolist(),
                "weights": [np.round(w, 5).tolist() for w in weights]}
    if kind == "creep":  # columns: a low-pass of ŝ per τ, of (ŝ − centre)² per τ, asymmetric,
        # held (driven by ŝ, by 1)
        n = len(spec.creep_tau_s)
        quadratic = slice(n, 2 * n if spec.creep_quadratic else n)
        return {"tau_s": list(spec.creep_tau_s), "build_recover_s": list(spec.creep_asym_s),
                "hold_grow_recover_s": list(spec.creep_hold_s),
                "gain": [np.round(np.r_[c[cols][:n], c[cols][quadratic.stop:]], 5).tolist()
                         for c in result.coef],
                "quadratic_gain_per_unit": ([np.round(c[cols][quadratic], 8).tolist()
                                             for c in result.coef]
                                            if spec.creep_quadratic else None),
                "centre": np.round(inputs.centre, 5).tolist() if spec.creep_quadratic else None}
    if kind == "lag":
        if spec.lag_kind == "rate_limit":
            return {"model": spec.lag_kind, "rate_per_s": spec.rate_limits(),
                    "gain": [round(float(c[cols][0]), 5) for c in result.coef]}
        on = {"sensors": [trial.sensor_names[j] for j in
                          (spec.lag_sensors or range(trial.n_sensors))]}
        if spec.lag_kind == "first_order_delay":
            return {"model": spec.lag_kind, "tau_s": spec.lag_s, "delay_s": spec.lag_delay_s,
                    **on}
        key = "tau_s" if spec.lag_kind == "first_order" else "delay_s"
        return {"model": spec.lag_kind, key: spec.lag_s, **on}
    if kind == "drift":
        ends = drift_columns(np.array([-1.0, 1.0]), spec.drift_degree, spec.drift_piecewise)
        change = [float((ends[1] - ends[0]) @ c[cols]) for c in result.coef]
        span = inputs.t_span[1] - inputs.t_span[0]
        shape = ({"basis": "piecewise_linear", "intervals": spec.drift_degree,
                  "knots_every_s": round(span / spec.drift_degree, 3)}
                 if spec.drift_piecewise else
                 {"basis": "legendre_polynomial", "degree": spec.drift_degree})
        return {**shape, "change": [round(c, 5) for c in change],
                "mean_rate_per_s": [round(c / span, 7) for c in change]}
    if kind == "saturation":
        pred = result.prediction[trial.valid]

        def level(v: float) -> float | None:
            return round(v, 5) if np.isfinite(v) else None

        return {"stops": [[level(st.lo), level(st.hi)] for st in result.stops],
                "softness": [[round(st.soft_lo, 5), round(st.soft_hi, 5)]
                             for st in result.stops],
                "shape": [[st.shape_lo if st.soft_lo > 0 else None,
                           st.shape_hi if st.soft_hi > 0 else None] for st in result.stops],
                "lower": np.round(pred.min(axis=0), 5).tolist(),
                "upper": np.round(pred.max(axis=0), 5).tolist()}
    raise ValueError(kind)


def _against_curve(trial: Trial, inputs: Inputs, spec: Spec, cand: Fit, evidence: dict,
                   floor: float) -> dict:
    """``evidence`` of the stops ``cand`` over ``spec`` with rule 3: added to a smooth
    transfer curve of each sensor (``Spec.output_curve``), they must still clear rules 1
    and 2 over it, pooled or on the sensors held at hard stops, or else explain everything
    the curve does (``stops_leave_curve_nothing``): the curve added to the stops does not
    clear rule 1 over them (``curve_over_stops``) and the stops alone leave a lower held-out
    gap than the curve alone. A reading that bends gently over its whole range (a nonlinear
    transfer, a misfit spread over the poses) is calibration that soft knees at both ends
    can imitate, and the curve follows it better; a stop is a bend at an end that no smooth
    curve follows, or one approached so gently that a curve follows part of it and adds
    nothing to the stops."""
    curve = fit(trial, inputs, replace(spec, output_curve=True))
    both = fit(trial, inputs, replace(cand.spec, output_curve=True))
    over = candidate_evidence(trial, curve, both, floor)
    curve_adds = rules_on_blocks(cand.block_mse, both.block_mse, floor)
    encompassed, stops_vs_curve = stops_leave_curve_nothing(cand, curve, curve_adds, floor)
    return {**evidence, "significant": over["significant"] or encompassed,
            "against_smooth_curve": {
                "curve_gap": round(curve.gap, 6), **over,
                "curve_over_stops": {k: curve_adds[k] for k in (
                    "delta_mse", "removed_rms", "blocks_improved", "beyond_noise")},
                "stops_alone_over_curve_alone": {k: stops_vs_curve[k] for k in (
                    "delta_mse", "blocks_improved", "blocks_needed")},
                "stops_leave_curve_nothing": encompassed}}


def _counted_refined(trial: Trial, inputs: Inputs, base: Fit, cand: Fit, evidence: dict,
                     floor: float) -> dict:
    """``evidence`` of a drift beyond the noise that improves too few blocks, with rules 1
    and 2 taken again on the drift it would become if named (:func:`_refine_drift`). Degrees
    1–3 only rank the candidates; a slip step or a random walk that they smear over the
    recording worsens the blocks around the step until a drift follows it. The drift is
    still ranked by its low-degree ΔMSE, so a flexible function of time never outranks a
    creep for its flexibility."""
    refined = candidate_evidence(trial, base, _refine_drift(trial, inputs, cand), floor)
    keys = ("heldout_gap", "delta_mse", "blocks_improved", "blocks_needed", "significant")
    alone = refined.get("on_one_sensor") or {"sensors": {}}
    return {**evidence, "significant": refined["significant"],
            "refined": {**{k: refined[k] for k in keys},
                        "significant_on_sensors": list(alone["sensors"])}}


def _last_count(trial: Trial, inputs: Inputs, base: Fit, cand: Fit, evidence: dict,
                floor: float) -> dict:
    """``evidence`` of a drift when no candidate is significant: counted on the drift it
    would become if named (:func:`_counted_refined`) unless it was already. Degrees 1–3
    smear a sawtooth that re-zeroes every 20–50 s over the whole recording: they may pass
    neither rule, or make the error worse, while the piecewise-linear drift that follows its
    ramps passes both. Taken only before the workflow would conclude and where the
    residual's slow part holds more than the noise on some sensor, against that sensor's
    own noise (:func:`_slow_part`; a refined drift costs a dozen fits, and one sensor's
    sawtooth among twelve is under the pooled noise), so the drift is still never named over
    a candidate that passes on its low degrees."""
    if "refined" in evidence or not np.any(_slow_part(trial, base.residual) > trial.noise**2):
        return evidence
    return _counted_refined(trial, inputs, base, cand, evidence, floor)


def _slow_part(trial: Trial, residual: np.ndarray) -> np.ndarray:
    """Mean square of the held-out ``residual`` averaged over ``DRIFT_SPAN_S`` windows, per
    sensor (sensor units²; white noise leaves σ² / frames per window of it): about the most
    a drift of one function per window can remove from each sensor's held-out error. Under
    each sensor's noise variance no refined drift can pass rule 1, pooled or on one sensor,
    and its dozen fits are spared."""
    window = max(int(round(DRIFT_SPAN_S * trial.rate_hz)), 1)
    finite = np.isfinite(residual)
    sums = uniform_filter1d(np.where(finite, residual, 0.0), window, axis=0, mode="constant")
    counts = uniform_filter1d(finite.astype(float), window, axis=0, mode="constant")
    slow = np.where(finite, sums / np.maximum(counts, 1e-12), np.nan)
    return np.nanmean(slow**2, axis=0)  # every sensor analysed has finite frames


def _drift_of(spec: Spec) -> tuple[int, bool]:
    """The drift term's count and basis (to tell whether a refit changed it)."""
    return spec.drift_degree, spec.drift_piecewise


def _lag_of(spec: Spec) -> tuple:
    """The lag term's model and parameters (to tell whether a refit changed it)."""
    return spec.lag_kind, spec.lag_s, spec.lag_delay_s, spec.lag_rates, spec.lag_sensors


def _conclusion(steps: list[dict], spec: Spec) -> str:
    if steps:
        return f"named {', '.join(s['effect'] for s in steps)}"
    if not [k for k in VOCABULARY if k not in spec.effects()]:
        return "every effect of the vocabulary is already in the model; nothing to add"
    return "no candidate effect beats the noise; nothing added"


def _candidate(trial: Trial, inputs: Inputs, spec: Spec, base: Fit, floor: float, kind: str
               ) -> tuple[str, Fit, dict]:
    """The best configuration of effect ``kind`` added to ``spec`` and its evidence against
    ``base`` (the model without it): one candidate of a step, on its own."""
    cand = _best(trial, inputs, kind, spec)
    evidence = candidate_evidence(trial, base, cand, floor)
    if kind == "drift" and beyond_noise_somewhere(evidence) and not evidence["significant"]:
        evidence = _counted_refined(trial, inputs, base, cand, evidence, floor)
    if kind == "saturation" and evidence["significant"]:
        evidence = _against_curve(trial, inputs, spec, cand, evidence, floor)
    return kind, cand, evidence


def _rms_words(rms: float | None) -> str:
    """A localisation's RMS in a progress line (None: no scored frame there)."""
    return "none scored" if rms is None else f"{rms:.4g}"


def _shape_words(params: dict) -> str:
    """An effect's parameters that are not per sensor, for a progress line (the JSON and
    the report have every one)."""
    return ", ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}"
                     for k, v in params.items() if not isinstance(v, list | type(None)))


def run(rec: Recording, name: str = "recording", in_model: tuple[str, ...] = (),
        progress: Callable[[str], None] = lambda line: None, workers: int | None = None,
        ) -> Outcome:
    """Run the whole workflow on a recording.

    Args:
        rec: measured recording (sensors + motion capture).
        name: how the recording is named in messages.
        in_model: effects the current suit model already has (from its profile): they are
            fitted from the start and never proposed as missing.
        progress: called with one line per step.
        workers: processes that try a step's candidate effects at once (default: one per
            CPU, one inside a worker process; :func:`~.workers.workers_for`). The result
            does not depend on it: every process runs one BLAS thread.

    Raises:
        DiscrepancyError: the recording cannot be used (no mocap, too short, ...).
    """
    processes = workers_for(workers)
    with one_blas_thread():
        first = _run(rec, name, in_model, progress, processes)
        first = _filter_again(rec, name, in_model, progress, processes, first)
        found = lead_after_effects(rec, name, first.trial, first.after,
                                   pooled_noise(first.trial))
        if found is None:
            return first
        effects = ", ".join(first.summary["effects"]) or "nothing"
        late = 1000.0 * found["mocap_late_s"]
        if not found["applied"]:
            progress(f"    with {effects} added the readings run {late:.3g} ms ahead of the "
                     f"motion capture to first order, but read so late the model explains "
                     f"{found['share_of_excess']:.0%} of what it left above the noise "
                     f"({found['blocks_improved']} blocks improved): left as it is")
            return first
        progress(f"    with {effects} added the readings run {late:.3g} ms ahead of the motion "
                 f"capture (read so late the model leaves {found['gap_with']:.4g} against "
                 f"{found['gap_without']:.4g} {first.trial.units}): again from the start, "
                 f"with its clock {late:.3g} ms late")
        kept_filter = first.summary["mocap_filter"]
        again = _run(rec, name, in_model, progress, processes, found["mocap_late_s"], found,
                     kept_filter if kept_filter and "after_effects" in kept_filter else None)
        return _lower(first, again, progress)


def _lower(first: Outcome, again: Outcome, progress: Callable[[str], None]) -> Outcome:
    """Of a run and the run again from the start, the one whose final held-out gap is lower
    (the first on a tie; keeping the first is said in a progress line)."""
    if again.after.gap < first.after.gap:
        return again
    progress(f"    kept the first run: {again.after.gap:.4g} against "
             f"{first.after.gap:.4g} {first.trial.units} held out")
    return first


def _filter_again(rec: Recording, name: str, in_model: tuple[str, ...],
                  progress: Callable[[str], None], workers: int, first: Outcome) -> Outcome:
    """``first``, or the workflow run again with the motion capture read the other way
    (low-passed or as sampled) where the final model, refitted so, predicts the held-out
    readings better in most held-out blocks (rule 2's sign test; an improvement below one
    noise variance counts, as it would not to name an effect: this only chooses how to read
    the data), and the second run ends lower.

    The choice of :func:`~.timing.mocap_filter` is made on the static map, before any effect: a
    suit whose lag smooths what the tendons feel prefers the low-passed angles there, yet
    once the lag is modelled a pure delay passes what the motion capture holds above the
    cutoff (real human motion, a delayed suit: 0.19 mm low-passed, 0.155 as sampled)."""
    chosen = first.summary["mocap_filter"]
    if chosen is None:
        return first
    trial, final = first.trial, first.after
    other = None if chosen["applied"] else MOCAP_CUTOFF_HZ
    read, inputs = read_trial(rec, name, trial.mocap_late_s, other, final.spec)
    refit = fit(read, inputs, final.spec)
    rules = rules_on_blocks(final.block_mse, refit.block_mse, pooled_noise(trial))
    if refit.gap >= final.gap or rules["blocks_improved"] < rules["blocks_needed"]:
        return first
    gaps = (refit.gap, final.gap) if other is None else (final.gap, refit.gap)
    found = {"low_pass_hz": MOCAP_CUTOFF_HZ, "applied": other is not None,
             "gap_as_sampled": round(gaps[0], 6), "gap_low_passed": round(gaps[1], 6),
             "after_effects": True}
    effects = ", ".join(first.summary["effects"]) or "nothing"
    how = "low-passed" if other is not None else "read as sampled"
    progress(f"    with {effects} added, the motion capture {how} leaves {refit.gap:.4g} against "
             f"{final.gap:.4g} {trial.units}: again from the start, so read")
    return _lower(first, _run(rec, name, in_model, progress, workers, filter_found=found),
                  progress)


def _run(rec: Recording, name: str, in_model: tuple[str, ...],
         progress: Callable[[str], None], workers: int, mocap_late_s: float = 0.0,
         after_effects: dict | None = None, filter_found: dict | None = None) -> Outcome:
    """:func:`run` with ``workers`` processes for a step's candidates, the motion capture
    read ``mocap_late_s`` late (found by :func:`~.timing.lead_after_effects`, whose evidence is
    ``after_effects``) and, given ``filter_found`` (by :func:`_filter_again`), filtered as
    it says instead of as :func:`~.timing.mocap_filter` would choose."""
    low_pass = filter_found is not None and filter_found["applied"]
    trial = prepare_trial(rec, name, mocap_late_s, MOCAP_CUTOFF_HZ if low_pass else None)
    floors = trial.noise
    floor = pooled_noise(trial)
    placed = "" if trial.placed_by == FRAME_COUNTER else f" (placed by {trial.placed_by})"
    progress(f"[1] calibrating the static map: {trial.n_sensors} sensors ({trial.units}) from "
             f"{', '.join(trial.angle_names)} ({trial.joint}), {trial.n} frames at "
             f"{trial.rate_hz:.1f} Hz{placed}, {int((~trial.valid).sum())} invalid; noise floor "
             f"{floor:.4g} {trial.units}")
    for sensor, reason in trial.ignored:
        progress(f"    left out sensor {sensor}: it {reason}")
    if trial.spikes.any():
        progress(f"    isolated spikes, not fitted or scored: "
                 f"{spike_counts(trial.sensor_names, trial.spikes.tolist())} (readings over "
                 f"{SPIKE_SIGMAS:g} σ from the median of their {SPIKE_WINDOW} frames)")
    scaled = make_inputs(trial)  # one basis per map for every ridge
    uncovered = restrict_to_coverage(trial, scaled.u)
    if uncovered > 0:
        progress(f"    {uncovered:.1%} of frames are poses no other fold covers: not scored")
    static_fit = _static_map(trial, scaled, floor)

    def static_map(other: Trial, inputs: Inputs) -> Fit:
        """The static map chosen for ``other``, the trial read another way."""
        return _static_map(other, inputs, floor)

    if filter_found is None:
        trial, scaled, static_fit, filtered = mocap_filter(rec, name, trial, scaled,
                                                           static_fit, static_map)
    else:
        filtered = filter_found
    progress(f"    {filter_words(filtered, trial.units)}")
    trial, scaled, static_fit, clock = clock_offset(rec, name, trial, scaled, static_fit,
                                                    floor, static_map)
    if clock is not None:
        progress(f"    {clock_words(clock, trial.units)}")
    if after_effects is not None:  # read late from the start: found after the effects
        here = clock if clock is not None and clock["applied"] else {
            "mocap_late_s": round(trial.mocap_late_s, 6), "applied": True}
        clock = {**here, "after_effects": after_effects}
    spec = static_fit.spec
    inputs = make_inputs(trial, spec)
    for kind in in_model:
        spec = _refine(trial, inputs, kind, _best(trial, inputs, kind, spec)).spec
    base = fit(trial, inputs, spec) if in_model else static_fit
    before = base
    runs = [trial.sensor_names[j] for j in inputs.segment_sensors]
    calibrated = _map_summary(spec, inputs, runs)
    progress(f"[2] simulated with the calibrated model ({map_words(calibrated)}"
             f"{', with ' + ', '.join(in_model) if in_model else ''}): held-out gap "
             f"{base.gap:.4g} {trial.units}")
    mot = motion(trial, inputs.static)
    local_before = localise(trial, base.residual, mot)
    progress(f"[3] localised ({trial.units} RMS): by direction " + ", ".join(
        f"{d} {_rms_words(r)}" for d, r in local_before["by_direction"].items())
        + f"; during holds {_rms_words(local_before['holds']['rms'])}; by speed, slow to fast, "
        + ", ".join(_rms_words(c["rms"]) for c in local_before["by_speed"]))
    steps: list[dict] = []
    rejected: list[dict] = []
    previous = ""  # the effect named in the previous step
    step = 4
    while True:
        missing = [k for k in VOCABULARY if k not in spec.effects()]
        if not missing:
            break
        sig = signatures(trial, base.residual, mot, floor)
        inputs.cache["without_lag"] = base  # the lag candidates' model without the lag
        # the candidates are independent: tried at once, the costliest first
        order = sorted(missing, key=COSTLIEST_FIRST.index)
        tried = forked_map(functools.partial(_candidate, trial, inputs, spec, base, floor),
                           order, workers)
        scored = sorted(tried, key=lambda item: missing.index(item[0]))
        if not any(e["significant"] for _, _, e in scored):
            scored = [(k, c, _last_count(trial, inputs, base, c, e, floor) if k == "drift"
                       else e) for k, c, e in scored]
        scored.sort(key=lambda item: -item[2]["delta_mse"])
        table = ", ".join(f"{k} {e['heldout_gap']:.4g}" for k, _, e in scored)
        winners = [item for item in scored if item[2]["significant"]]
        if not winners:
            rejected = [{"effect": k, "gap": e["heldout_gap"], "evidence": {**e, **sig}}
                        for k, _, e in scored]
            progress(f"[{step}] no candidate beats the noise (gap {base.gap:.4g}, floor "
                     f"{floor:.4g}; tried {table}): nothing added")
            break
        kind, cand, _ = winners[0]
        refined = _refine(trial, inputs, kind, cand)
        cand = _best_degree(trial, inputs, refined)
        if kind == "lag" and cand.spec != refined.spec:  # a lag refined on the map chosen
            # without it is biased toward that map: refine it again on the map now chosen
            cand = _refine_lag_delay(trial, inputs, cand)
        if kind == "drift" and cand.spec != refined.spec:  # so is a drift's basis and count
            cand = _refine_drift(trial, inputs, cand)
        drift_before = _drift_of(cand.spec)
        if kind != "drift" and cand.spec.drift_degree:
            cand = _refine_drift(trial, inputs, cand)
        lag_before = _lag_of(cand.spec)
        if previous == "lag":  # a lag named while a larger effect was
            # still missing was fitted against it: refit it once, with the next effect added
            cand = _refine_lag_delay(trial, inputs, cand)
        previous = kind
        evidence = candidate_evidence(trial, base, cand, floor)
        if kind == "saturation":  # judged against the smooth curve when it was named
            evidence["against_smooth_curve"] = winners[0][2]["against_smooth_curve"]
        if "refined" in winners[0][2]:  # a drift counted on the drift it would become
            low = winners[0][2]
            evidence["low_degrees"] = {
                **{k: low[k] for k in ("heldout_gap", "delta_mse", "removed_rms",
                                       "blocks_improved", "blocks_needed", "beyond_noise")},
                "beyond_noise_sensors": low.get("on_one_sensor", {}).get(
                    "beyond_noise_sensors", [])}
            evidence["refined"] = low["refined"]  # the count it was named on
        spec, base = cand.spec, cand
        refit = {k: effect_params(k, cand, inputs, trial) for k, changed in
                 (("lag", _lag_of(cand.spec) != lag_before),
                  ("drift", _drift_of(cand.spec) != drift_before))
                 if changed}
        steps.append({"effect": kind, "gap": round(cand.gap, 6),
                      "params": effect_params(kind, cand, inputs, trial),
                      "evidence": {**evidence, "signature": sig, "refitted": refit,
                                   "alternatives": {k: e["heldout_gap"] for k, _, e in scored
                                                    if k != kind}}})
        progress(f"[{step}] added {kind}: held-out gap {cand.gap:.4g} {trial.units} "
                 f"(tried {table})" + "".join(f"; {k} refitted: {_shape_words(p)}"
                                              for k, p in refit.items()))
        step += 1
    after = base
    local_after = localise(trial, after.residual, mot)
    if local_after["steps"]:
        progress(f"    {steps_words(local_after['steps'], trial.units)}; see report.md")
    summary = {
        "recording": name,
        "effects": [s["effect"] for s in steps],
        "gap_before": round(before.gap, 6),
        "gap_after": round(after.gap, 6),
        "units": trial.units,
        "sensors": list(trial.sensor_names),
        "sensors_ignored": [{"sensor": sensor, "reason": reason}
                            for sensor, reason in trial.ignored],
        "sensor_gap_before": np.round(before.sensor_gap(), 6).tolist(),
        "sensor_gap_after": np.round(after.sensor_gap(), 6).tolist(),
        "noise_floor": round(floor, 6),
        "noise_floor_per_sensor": np.round(floors, 6).tolist(),
        "joint": trial.joint,
        "angles": list(trial.angle_names),
        "mocap_low_pass_hz": trial.mocap_low_pass_hz,
        "mocap_filter": filtered,
        "rate_hz": round(trial.rate_hz, 4),
        "frames": trial.n,
        "frames_placed_by": trial.placed_by,
        "invalid_frames": int((~trial.valid).sum()),
        "spikes": trial.spikes.tolist(),
        "unscored_frames": int((trial.valid & ~trial.scored).sum()),
        "already_in_model": list(in_model),
        "clock_offset": clock,
        "static_map": _map_summary(spec, inputs, runs),
        "static_map_calibrated": calibrated,
        "heldout_blocks": int(trial.blocks.max()) + 1,
        "localisation_before": local_before,
        "localisation_after": local_after,
        "steps": steps,
        "not_added": rejected,
        "conclusion": _conclusion(steps, spec),
    }
    return Outcome(trial=trial, inputs=inputs, before=before, after=after, summary=summary)
