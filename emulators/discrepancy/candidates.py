"""The candidate effects (the vocabulary) and the searches of their shape parameters.

Each effect the workflow may name is a family of terms added to the current model
(:class:`~.model.Spec`): a step compares each kind at its best configuration on a coarse
grid (:func:`best_candidate`), and the kind it names is then refined between its grid
neighbours (:func:`refine`): a lag's time constant, delay or rate limits, a creep's time
constants, a drift's degree. Every comparison is the held-out gap of a full fit.
"""

from __future__ import annotations

import functools
import math
from dataclasses import replace

import numpy as np
from scipy.optimize import minimize

from exohil.emulators.discrepancy.data import BLOCK_S, Trial
from exohil.emulators.discrepancy.folds import block_mse
from exohil.emulators.discrepancy.model import (
    STATIC_RIDGES,
    Fit,
    Inputs,
    SensorPart,
    Spec,
    coefficient_slices,
    fit,
    sensor_part,
)
from exohil.emulators.discrepancy.rules import candidate_evidence, pooled_noise
from exohil.emulators.discrepancy.workers import forked_map

VOCABULARY = ("hysteresis", "creep", "saturation", "lag", "drift")
#: The vocabulary by how long a candidate's jobs usually take (each lag model refined on its
#: grid, the loop fitted on the reading and on the pose, each sensor's stops chosen on
#: held-out blocks): the order a step hands them to its processes, so that the longest do
#: not start last.
COSTLIEST_FIRST = ("lag", "hysteresis", "saturation", "creep", "drift")
#: The lag's models, each searched on its own (:func:`lag_model`): a step may try them at
#: once, the longest candidate after a saturation is named (every fit goes through the
#: stops) and alone as long as the other candidates together.
LAG_MODELS = ("first_order", "delay", "rate_limit")
LAG_TAU_S = (0.01, 0.02, 0.04, 0.08, 0.2)
LAG_DELAY_S = (0.01, 0.025, 0.06, 0.15)
#: Relative precision of a lag searched between its grid neighbours (log seconds): a
#: search ends once the best point's bracket is narrower than twice this
#: (:func:`_parabolic_step`).
LAG_LOG_TOL = 0.02
#: Steps of successive parabolic interpolation (:func:`_parabolic_step`) after the grid of
#: the low-pass and of the delay while the candidates are compared.
LAG_COMPARE_STEPS = 2
#: The golden ratio's conjugate, (√5 − 1) / 2.
GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0
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
#: Golden-section steps of each sensor's log limit between its best quantile's neighbours:
#: while the candidates are compared, and once a rate limit is named.
RATE_LIMIT_COMPARE_STEPS = 2
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
#: Degrees a named drift is refined over (see refine_drift), up to one per DRIFT_SPAN_S.
DRIFT_REFINE_DEGREES = (4, 6, 8, 12, 16, 24, 32, 48)
#: Shortest span of time one degree of a refined drift may stand for, s: twice a held-out
#: block, so the drift over a block is interpolated from the blocks around it.
DRIFT_SPAN_S = 2 * BLOCK_S


def _candidates(kind: str, spec: Spec) -> list[Spec]:
    """The configurations of ``kind`` to try on top of ``spec`` (lag: see lag_model;
    creep: see creep_families; saturation: see saturation_candidate)."""
    if kind == "hysteresis":  # a loop in the reading, or in the pose
        return [replace(spec, hysteresis=True), replace(spec, hysteresis=True,
                                                        hysteresis_angles=True)]
    if kind == "drift":
        return [replace(spec, drift_degree=d) for d in DRIFT_DEGREES]
    raise ValueError(f"unknown effect {kind!r}; known: {', '.join(VOCABULARY)}")


def best_candidate(trial: Trial, inputs: Inputs, kind: str, spec: Spec) -> Fit:
    """The candidate configuration of ``kind`` with the lowest held-out error."""
    if kind == "lag":  # each lag model refined between its grid neighbours, then compared
        return best_lag([lag_model(trial, inputs, spec, m) for m in LAG_MODELS])
    if kind == "creep":
        return min(creep_families(trial, inputs, spec), key=lambda f: f.gap)
    if kind == "saturation":
        return saturation_candidate(trial, inputs, spec)
    return min((fit(trial, inputs, s) for s in _candidates(kind, spec)), key=lambda f: f.gap)


def saturation_candidate(trial: Trial, inputs: Inputs, spec: Spec,
                         parts: list[list[SensorPart]] | None = None, workers: int = 1) -> Fit:
    """Stops added to ``spec`` (:func:`saturation_parts` of each sensor: ``parts`` where
    computed apart, else here, one sensor a job in ``workers`` processes), at the ridge of
    the map that predicts the held-out blocks best. Fitted between the stops, the map
    extrapolates into them: its ridge is chosen again (a small one that interpolates well
    can extrapolate wildly), through the stops chosen with the current one."""
    if parts is None:
        parts = forked_map(functools.partial(saturation_parts, trial, inputs, spec),
                           range(trial.n_sensors), workers)
    first = fit(trial, inputs, replace(spec, saturation=True), [p[0] for p in parts])
    kept = _keep_stops(first).spec
    return min([first] + [fit(trial, inputs, replace(kept, ridge=r), [p[k] for p in parts])
                          for k, r in enumerate(_other_ridges(spec), start=1)],
               key=lambda f: f.gap)


def saturation_parts(trial: Trial, inputs: Inputs, spec: Spec, j: int) -> list[SensorPart]:
    """Sensor j's share of :func:`saturation_candidate`: its stops chosen with ``spec``'s
    ridge (the candidate's costliest part), then its fit through them at that ridge and at
    each of the others (:func:`~.model.sensor_part`). No other sensor's enters it, so a
    step computes each sensor's apart (:func:`~.workflow._candidates`)."""
    first = sensor_part(trial, inputs, replace(spec, saturation=True), j)
    return [first] + [sensor_part(trial, inputs, replace(spec, saturation=True, ridge=r), j,
                                  first[1]) for r in _other_ridges(spec)]


def _other_ridges(spec: Spec) -> list[float]:
    """The static ridges a saturation tries beside ``spec``'s, in order."""
    return [r for r in STATIC_RIDGES if r != spec.ridge]


def lag_model(trial: Trial, inputs: Inputs, spec: Spec, model: str) -> Fit:
    """The best lag of one of the ``LAG_MODELS`` added to ``spec``: a low-pass or a delay
    refined between its grid neighbours (:func:`_refine_lag`), or a rate limit per sensor
    (:func:`rate_limit_candidate`)."""
    if model == "first_order":
        return _refine_lag(trial, inputs, spec, model, LAG_TAU_S)
    if model == "delay":
        return _refine_lag(trial, inputs, spec, model, LAG_DELAY_S)
    if model == "rate_limit":
        return rate_limit_candidate(trial, inputs, spec,
                                    steps=RATE_LIMIT_COMPARE_STEPS)
    raise ValueError(f"unknown lag model {model!r}; known: {', '.join(LAG_MODELS)}")


def best_lag(fits: list[Fit]) -> Fit:
    """The lag candidate: of the best fit of each of the ``LAG_MODELS``, in that order, the
    one with the lowest held-out error (the first of equals)."""
    return min(fits, key=lambda f: f.gap)


def creep_families(trial: Trial, inputs: Inputs, spec: Spec,
                   computed: tuple[Fit, ...] | None = None) -> tuple[Fit, ...]:
    """The best creep of each family on its grid added to ``spec``: low-passes of the stretch
    (one time constant, then a second if it helps), the asymmetric build/recover state and
    the state that flows only during holds (``computed``, where computed apart: a step's
    job, :func:`~.workflow._candidates`).
    Kept for the last ``spec`` asked: a named creep is refined from the grid it was
    compared on (:func:`best_candidate`, then :func:`refine`)."""
    kept = inputs.cache.get("creep_families")
    if computed is not None:
        kept = (spec, computed)
        inputs.cache["creep_families"] = kept
    elif kept is None or kept[0] != spec:
        kept = (spec, _creep_grids(trial, inputs, spec))
        inputs.cache["creep_families"] = kept
    return kept[1]


def flows_within_holds(trial: Trial, inputs: Inputs, held: Fit) -> bool:
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
    return (lows, asym, hold) if flows_within_holds(trial, inputs, hold) else (lows, asym)


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
    """The best time constant or delay of one lag model: grid, then ``LAG_COMPARE_STEPS``
    steps of parabolic interpolation on log(seconds) between the best grid point's
    neighbours (:func:`_parabolic_step`; the held-out error is sharp in τ: 10 % off leaves
    a velocity-shaped residual). A named lag is searched again in full
    (:func:`refine_lag_delay`): this one ranks the lag against the other candidates.

    The lag acts on the sensors it brings closer (:func:`_where_it_helps`), and its value is
    chosen on that fit: a 9.5 ms low-pass on one sensor of five (the third blind generator's
    rec 1) takes that sensor from 45.4 to 15.5 mrad at 5 ms, while every lag on all five
    left a larger gap than none (28.8 mrad) or the same.
    """
    plain = _without_lag(trial, inputs, spec)

    def lagged(log_s: float) -> Fit:
        return _where_it_helps(trial, fit(trial, inputs, replace(
            spec, lag_kind=lag_kind, lag_s=math.exp(log_s))), plain)

    fits = {math.log(v): lagged(math.log(v)) for v in grid}
    lo, hi = math.log(grid[0] / 2), math.log(grid[-1] * 2)
    for _ in range(LAG_COMPARE_STEPS):
        log_s = _parabolic_step({x: f.gap for x, f in fits.items()}, lo, hi)
        if log_s is None:
            break
        fits[log_s] = lagged(log_s)
    return min(fits.values(), key=lambda f: f.gap)


def _parabolic_step(tried: dict[float, float], lo: float, hi: float) -> float | None:
    """The next point of a search for the minimum of a function of x in [lo, hi], given its
    values at the points ``tried`` (+inf where a fit does not count), or None once the best
    point's bracket (its nearest tried neighbours, or the range's ends) is narrower than
    twice ``LAG_LOG_TOL``.

    The next point is the vertex of the parabola through the best point and its neighbours
    (it lies between them). Where the best point is the lowest or highest tried, it is
    halfway to that end of the range. Where the three values make no parabola (equal, or
    infinite) or the vertex lies within ``LAG_LOG_TOL`` of a point tried, it is the
    golden-section point of the wider side of the best point: a far neighbour on a steep
    wall puts the vertex next to the best point although the minimum lies further on (a
    rate limit's error at 6.8, 36.4 and 54.2 units/s put it 0.4 % above 36.4; the minimum
    was near 41). This is Brent's method's safeguard; on a smooth minimum a parabolic step
    gains far more than a golden-section step, which only shrinks the bracket by 0.618.
    """
    xs = sorted(tried)
    values = [tried[x] for x in xs]
    if not np.isfinite(values).any():
        return None
    b = int(np.argmin(values))
    x1, f1 = xs[b], values[b]
    left, right = (xs[b - 1] if b > 0 else lo), (xs[b + 1] if b < len(xs) - 1 else hi)
    if right - left < 2 * LAG_LOG_TOL:
        return None
    nxt = math.nan
    if b == 0 and x1 - lo > LAG_LOG_TOL:
        nxt = 0.5 * (lo + x1)
    elif b == len(xs) - 1 and hi - x1 > LAG_LOG_TOL:
        nxt = 0.5 * (x1 + hi)
    elif 0 < b < len(xs) - 1 and math.isfinite(values[b - 1] + values[b + 1]):
        x0, f0, x2, f2 = left, values[b - 1], right, values[b + 1]
        den = (x1 - x0) * (f1 - f2) - (x1 - x2) * (f1 - f0)
        if den != 0.0:
            nxt = x1 - 0.5 * ((x1 - x0) ** 2 * (f1 - f2) - (x1 - x2) ** 2 * (f1 - f0)) / den
    if not math.isfinite(nxt) or min(abs(nxt - x) for x in xs) < LAG_LOG_TOL:
        far = left if x1 - left > right - x1 else right
        nxt = x1 + (1.0 - GOLDEN) * (far - x1)
    return min(max(nxt, lo), hi)


def rate_limit_candidate(trial: Trial, inputs: Inputs, spec: Spec, *, steps: int) -> Fit:
    """The best rate limit per sensor added to ``spec`` (without its lag).

    A slew-rate limit is not a linear filter: the reading falls behind only while the pose
    moves faster than the limit and catches up afterwards, so the residual lives in the
    fastest moves, whatever their frequency. Each sensor's limit is searched on its own
    (sensors are fitted independently, so every fit tries one limit per sensor): at the
    ``RATE_LIMIT_QUANTILES`` of its static prediction's speed, then by ``steps`` steps of
    golden-section search on the log limit between the best one's neighbours (the held-out
    error is sharp in the limit: on a suit limited at its 99.5th percentile of speed, the
    99th and 99.7th leave a third of the effect or more): ``RATE_LIMIT_COMPARE_STEPS`` while
    the candidates are compared, ``RATE_LIMIT_STEPS`` once a rate limit is named.

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

    def at(log_rates: np.ndarray) -> tuple[Fit, np.ndarray]:
        """The fit with these limits and its held-out mean squared error per sensor (+inf
        where the limit's gain is not positive)."""
        rates = tuple(float(f"{r:.5g}") for r in np.exp(log_rates))
        f = fit(trial, inputs, replace(spec, lag_kind="rate_limit", lag_rates=rates))
        col = coefficient_slices(inputs, f.spec)["lag"].start
        gain = np.array([c[col] for c in f.coef])
        return f, np.where(gain > 0, np.nanmean(f.residual[trial.scored] ** 2, axis=0), np.inf)

    mse = np.array([at(g)[1] for g in grid])  # (Q, S)
    k = np.argmin(mse, axis=0)
    lo = grid[np.maximum(k - 1, 0), sensors] - np.where(k == 0, math.log(2.0), 0.0)
    hi = grid[np.minimum(k + 1, len(grid) - 1), sensors] + np.where(
        k == len(grid) - 1, math.log(2.0), 0.0)
    x1, x2 = hi - GOLDEN * (hi - lo), lo + GOLDEN * (hi - lo)
    f1, f2 = at(x1)[1], at(x2)[1]
    for _ in range(steps):  # every sensor's bracket shrinks by the golden ratio
        left = f1 < f2  # the minimum lies in [lo, x2]
        hi, lo = np.where(left, x2, hi), np.where(left, lo, x1)
        x1, x2, f1, f2 = (np.where(left, hi - GOLDEN * (hi - lo), x2),
                          np.where(left, x1, lo + GOLDEN * (hi - lo)),
                          np.where(left, np.nan, f2), np.where(left, f1, np.nan))
        new = np.where(left, x1, x2)
        m = at(new)[1]
        f1, f2 = np.where(left, m, f1), np.where(left, f2, m)
    candidates = np.vstack([grid[k, sensors], x1, x2])
    scores = np.vstack([mse[k, sensors], f1, f2])
    chosen = candidates[np.argmin(scores, axis=0), sensors]
    return at(np.where(np.isfinite(scores.min(axis=0)), chosen, np.inf))[0]


def refine_lag_delay(trial: Trial, inputs: Inputs, current: Fit) -> Fit:
    """A named lag refined as a low-pass followed by a delay (first order plus dead time),
    of which the low-pass alone and the delay alone are the two ends.

    Nelder–Mead on (log T, share), T = τ + delay the total lag and share = delay / T, from
    the current lag (first named: the single model that won, share 0 or 1; once another
    effect is added, the lag as refitted before). A cascade of low-passes, or a low-pass
    behind a transport delay and a clock offset, is neither end: on the default suit (30 ms
    low-pass, 8 ms delay, 12 ms clock offset) the low-pass alone leaves 0.74 mm, τ 30 ms with
    20 ms of delay 0.32 mm. The current lag is kept unless another beats it held out.
    Each point acts on the sensors it brings closer (:func:`_where_it_helps`), chosen
    again: the grid's choice was made on the map without the lag. A rate limit has no
    low-pass or delay: its limits are searched again (:func:`rate_limit_candidate`, with
    ``RATE_LIMIT_STEPS``).
    """
    spec = current.spec
    if spec.lag_kind == "rate_limit":  # no low-pass or delay: its limits, searched again
        # on the model as it is now (another degree, or the next effect added)
        return min([current, rate_limit_candidate(trial, inputs, spec, steps=RATE_LIMIT_STEPS)],
                   key=lambda f: f.gap)
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


def refine(trial: Trial, inputs: Inputs, kind: str, current: Fit, workers: int = 1) -> Fit:
    """Refine the continuous shape parameters of a named effect from its best grid point.

    The candidates' grids are coarse (creep: time constants a factor of 3 apart) so that every
    effect is compared at a modest cost; once one is named its parameters are fitted properly.
    Creep: a Nelder–Mead search on the log time constants minimising the held-out error, from
    the best grid point of each family (one or two low-passes; the build/recover pair of the
    asymmetric state): the family that wins on the grid need not win refined (a symmetric
    pair 0.199 mm on the grid, 0.194 refined; the asymmetric state 0.222 and 0.157), and the
    refined low-passes once more with a quadratic driver (``Spec.creep_quadratic``: a load
    that is not proportional to the stretch). Saturation:
    the stops chosen in its candidate fit are kept from here on (:func:`_keep_stops`). Lag: the
    low-pass and the delay together, or a rate limit searched again with
    ``RATE_LIMIT_STEPS`` (:func:`refine_lag_delay`); a low-pass or delay also against a rate
    limit searched in full, the better kept (the candidates were ranked on short searches:
    on a graphene file a low-pass ranked first at 0.1485 where the rate limit searched in
    full leaves 0.1460).
    The other effects have no shape parameter. A creep's families are refined at once in
    ``workers`` processes (:func:`~.workers.forked_map`; the same fits in any number).
    """
    if kind == "saturation":
        return _keep_stops(current)
    if kind == "lag":
        lag = refine_lag_delay(trial, inputs, current)
        if current.spec.lag_kind == "rate_limit":
            return lag
        # ranked after two golden-section steps, a rate limit may lose to a low-pass that
        # it beats searched in full
        return min([lag, rate_limit_candidate(trial, inputs, current.spec,
                                              steps=RATE_LIMIT_STEPS)],
                   key=lambda f: f.gap)
    if kind == "drift":
        return refine_drift(trial, inputs, current)
    if kind != "creep":
        return current
    bare = replace(current.spec, creep_tau_s=(), creep_asym_s=(), creep_hold_s=())
    refined = forked_map(functools.partial(_refine_creep, trial, inputs),
                         creep_families(trial, inputs, bare), workers)
    lows = refined[0]
    refined = [f for f in refined if not f.spec.creep_hold_s
               or flows_within_holds(trial, inputs, f)]
    # the low-passes again with a driver that is not proportional to the stretch
    quadratic = _refine_creep(trial, inputs, fit(trial, inputs, replace(
        lows.spec, creep_quadratic=True)))
    return min(refined + [quadratic], key=lambda f: f.gap)


def refine_drift(trial: Trial, inputs: Inputs, current: Fit) -> Fit:
    """A named drift refined over more functions of time, the best held out.

    Degrees 1–3 only rank the candidates: a more flexible function of time would also explain
    a slow pose-driven relaxation (degrees up to 34 named 4 of 20 creeps drift). Once drift is
    named it may follow an offset that wanders (a random walk, a piecewise ramp, a slip step)
    as finely as the held-out blocks allow: at most one function per ``DRIFT_SPAN_S`` seconds,
    as a Legendre polynomial (a smooth warm-up or cycle) or as a piecewise-linear function
    on even knots (a step or a walk, followed locally where a polynomial rings over the
    whole recording). The choice is made again, from degree 1 up, after each effect added
    later (see :func:`~.workflow.run`): one made before another effect was in place may have
    stood in for part of it. Kept for the last ``current`` asked: a drift counted on its
    refined form (:func:`~.workflow._counted_refined`) and then named is refined from the
    same fit.
    """
    kept = inputs.cache.get("refined_drift")
    if kept is not None and kept[0] == current.spec:
        return kept[1]
    here = current.spec.drift_term()
    refined = min([current] + [fit(trial, inputs, replace(current.spec, drift_degree=d,
                                                           drift_piecewise=piecewise))
                               for d, piecewise in drift_options(recording_length(trial))
                               if (d, piecewise) != here],
                  key=lambda f: f.gap)
    inputs.cache["refined_drift"] = (current.spec, refined)
    return refined


def recording_length(trial: Trial) -> float:
    """How long the trial's frames last, s: its first to last frame and the last frame's
    period (a 60 s recording at 250 Hz spans 59.996 s from its first frame to its last)."""
    return float(trial.t[-1] - trial.t[0]) + 1.0 / trial.rate_hz


def drift_options(length_s: float) -> list[tuple[int, bool]]:
    """(count, piecewise) of every drift a named drift is refined over on a recording
    ``length_s`` seconds long (:func:`recording_length`): Legendre degrees and
    piecewise-linear intervals, at most one function per ``DRIFT_SPAN_S``."""
    options = [(d, False) for d in DRIFT_DEGREES + DRIFT_REFINE_DEGREES]
    options += [(d, True) for d in DRIFT_REFINE_DEGREES]
    # a hair of tolerance: a length that is a whole number of spans is not lost to rounding
    return [(d, piecewise) for d, piecewise in options
            if d * DRIFT_SPAN_S <= length_s * (1.0 + 1e-9)]


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
