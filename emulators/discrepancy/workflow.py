"""The discrepancy workflow: calibrate, simulate, localise, name the missing effect, add it,
repeat until nothing significant remains.

:func:`run` reads the recording onto its grid (:mod:`.data`) with the motion capture's clock
and filter chosen by the readings (:mod:`.timing`), calibrates the static map, then at each
step fits every candidate of the vocabulary not yet in the model (:mod:`.candidates`),
judges each by the decision rule (:mod:`.rules`: why an effect is named, and when nothing
is), names the best, refines it and goes on; its summary is ``discrepancy.json``'s content.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from exohil.emulators.discrepancy.candidates import (
    COSTLIEST_FIRST,
    DRIFT_SPAN_S,
    LAG_MODELS,
    VOCABULARY,
    best_candidate,
    best_lag,
    creep_families,
    lag_model,
    refine,
    refine_drift,
    refine_lag_delay,
    saturation_candidate,
    saturation_parts,
)
from exohil.emulators.discrepancy.data import (
    FRAME_COUNTER,
    RESAMPLED_SPREAD,
    RESAMPLED_STRIDES,
    SPIKE_SIGMAS,
    SPIKE_WINDOW,
    Trial,
    invalid_words,
    prepare_trial,
    spike_counts,
)
from exohil.emulators.discrepancy.figures import LEVEL_DIGITS, significant, significant_list
from exohil.emulators.discrepancy.jumps import jumps_in_holds
from exohil.emulators.discrepancy.localise import localise, motion, signatures, steps_words
from exohil.emulators.discrepancy.model import (
    LOCAL_DEGREE,
    LOCAL_RIDGES,
    LOCAL_STATIC_RIDGES,
    STATIC_RIDGES,
    Fit,
    Inputs,
    SensorPart,
    Spec,
    angle_thresholds,
    coefficient_slices,
    drift_columns,
    drift_kept_heldout,
    fit,
    loop_width_terms,
    make_inputs,
    restrict_to_coverage,
    sensor_part,
    static_basis,
    static_slopes,
    with_static_of,
)
from exohil.emulators.discrepancy.rules import (
    MOVEMENT_S,
    beyond_noise_somewhere,
    candidate_evidence,
    pooled_noise,
    remainder,
    rules_on_blocks,
    stops_leave_curve_nothing,
    windowed_mean,
)
from exohil.emulators.discrepancy.stops import pinned_at_rail
from exohil.emulators.discrepancy.timing import (
    after_effects_words,
    clock_offset,
    clock_skew,
    clock_words,
    filter_words,
    lead_after_effects,
    mocap_filter,
    rate_after_effects,
    read_trial,
    refine_with_loop,
    skew_words,
)
from exohil.emulators.discrepancy.workers import (
    forked_map,
    memory_reused,
    one_blas_thread,
    workers_for,
)
from exohil.formats.recording import Recording
from exohil.formats.recording_metadata import rates_disagree

#: Refits of a named effect's model with its history terms driven by its own static part
#: (:func:`_static_input_again`); the first does most (0.301 → 0.194 → 0.188 mm on the
#: case in :func:`~.model.with_static_of`).
STATIC_INPUT_ROUNDS = 2
#: Degrees of a named hysteresis in its plays' level tried beside the plain loop (degree 1,
#: the candidate; :func:`_own_static_part`).
HYSTERESIS_DEGREES = (2, 3)
#: Below this share of a linear drift kept in the held-out gap
#: (:func:`~.model.drift_kept_heldout`), progress line [2] says that the poses follow time:
#: the static map then takes in more than half of a slow drift.
DRIFT_KEPT_NOTED = 0.5
#: Offset jumps a progress line lists (the JSON has every one).
JUMPS_LISTED = 3


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


def _static_map(trial: Trial, inputs: Inputs, floor: float, workers: int = 1) -> Fit:
    """The static map with the lowest held-out gap, except that a map with the local basis
    must also beat the best polynomial bent at stops (saturation) by more than the noise,
    by rules 1 and 2 (the bar an effect must clear to be named). A stop is a static bend
    of the reading that local functions can follow too, taking it in as the pose's doing;
    so can a loop where the arm goes out and back on different paths. Of a flexible map and
    a physical explanation, the workflow keeps the second unless the local functions predict
    the held-out blocks better by more than it would take to name an effect (``floor``:
    the recording's pooled noise RMS, the bar's σ). Without rule 2's sign test: local
    functions help where the poses they cover are, so on some blocks more than others.

    The maps, and the stops' sensors, are fitted in ``workers`` processes
    (:func:`~.workers.forked_map`; the same fits in any number), the local basis formed here
    first for all of them."""
    if inputs.centres.shape[0]:
        static_basis(inputs, LOCAL_DEGREE, local=True)
    fits = forked_map(functools.partial(fit, trial, inputs), _static_maps(inputs), workers)
    best = min(fits, key=lambda f: f.gap)
    if not best.spec.local:
        return best
    polynomial = min((f for f in fits if not f.spec.local), key=lambda f: f.gap)
    bent = saturation_candidate(trial, inputs, polynomial.spec, workers=workers)
    bends = rules_on_blocks(bent.block_mse, best.block_mse, floor)["beyond_noise"]
    return best if bends else polynomial


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


def _best_degree(trial: Trial, inputs: Inputs, current: Fit, workers: int = 1) -> Fit:
    """Re-choose the static map's degree and ridges with the effect terms in place: an
    unexplained effect makes the static-only fit prefer a stiffer map than the suit needs.
    The map keeps its kind (a polynomial, or local functions) chosen at calibration: trying
    the local functions under every effect, each with its lag, cost minutes per recording.
    The maps are fitted in ``workers`` processes (the same fits in any number): a
    polynomial's 27 others took 0.2–1.2 s in each step of the fixture, the other core
    idle."""
    spec = current.spec
    maps = [replace(spec, degree=m.degree, local=m.local, local_ridge=m.local_ridge,
                    ridge=m.ridge)
            for m in _static_maps(inputs) if m.local == spec.local and _map_of(m) != _map_of(spec)]
    others = forked_map(functools.partial(fit, trial, inputs), maps, workers)
    return min([current] + others, key=lambda f: f.gap)


def effect_params(kind: str, result: Fit, inputs: Inputs, trial: Trial) -> dict:
    """The fitted parameters of one effect term, per sensor where they differ (sensor units
    unless the name says otherwise)."""
    spec = result.spec
    cols = coefficient_slices(inputs, spec).get(kind, slice(0, 0))
    if kind == "hysteresis" and spec.hysteresis_angles:
        return _angle_loop_params(result, inputs, trial, cols)
    if kind == "hysteresis":
        n_play = inputs.thresholds.shape[1]
        weights = [c[cols] for c in result.coef]
        width = [float(np.sum(w.reshape(-1, n_play) * loop_width_terms(r, spec.hysteresis_degree)))
                 for w, r in zip(weights, inputs.thresholds, strict=True)]
        return {"on": "reading", "loop_width": [significant(w) for w in width],
                "play_thresholds": significant_list(inputs.thresholds),
                "level_degree": spec.hysteresis_degree,
                "weights": [np.round(w[:n_play], 5).tolist() for w in weights],
                "level_weights": [np.round(w[n_play:], 5).reshape(-1, n_play).tolist()
                                  for w in weights]}
    if kind == "creep":  # columns: a low-pass of ŝ per τ, of (ŝ − centre)² per τ, asymmetric,
        # held (driven by ŝ, by 1)
        n = len(spec.creep_tau_s)
        quadratic = slice(n, 2 * n if spec.creep_quadratic else n)
        return {"tau_s": list(spec.creep_tau_s), "build_recover_s": list(spec.creep_asym_s),
                "hold_grow_recover_s": list(spec.creep_hold_s),
                "gain": [np.round(np.r_[c[cols][:n], c[cols][quadratic.stop:]], 5).tolist()
                         for c in result.coef],
                "quadratic_gain_per_unit": ([significant_list(c[cols][quadratic])
                                             for c in result.coef]
                                            if spec.creep_quadratic else None),
                "centre": (significant_list(inputs.centre, LEVEL_DIGITS) if spec.creep_quadratic
                           else None)}
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
        return {**shape, "change": [significant(c) for c in change],
                "mean_rate_per_s": [significant(c / span) for c in change]}
    if kind == "saturation":
        pred = result.prediction[trial.valid]

        def level(v: float) -> float | None:
            return significant(v, LEVEL_DIGITS) if np.isfinite(v) else None

        return {"stops": [[level(st.lo), level(st.hi)] for st in result.stops],
                "softness": [[significant(st.soft_lo), significant(st.soft_hi)]
                             for st in result.stops],
                "shape": [[st.shape_lo if st.soft_lo > 0 else None,
                           st.shape_hi if st.soft_hi > 0 else None] for st in result.stops],
                "lower": significant_list(pred.min(axis=0), LEVEL_DIGITS),
                "upper": significant_list(pred.max(axis=0), LEVEL_DIGITS)}
    raise ValueError(kind)


def _angle_loop_params(result: Fit, inputs: Inputs, trial: Trial, cols: slice) -> dict:
    """The parameters of a loop in the pose (plays on the angles,
    :func:`~.model.angle_play_columns`): per sensor, the weights of each angle's plays
    (a row per angle), their half-widths in degrees, and the loop's width in sensor units
    at the median slope of ŝ in each angle over the valid frames: the falling branch less
    the rising one after an excursion wider than the widest play in every angle at once,
    Σ −2·r·w·∂ŝ/∂α over the angles and plays."""
    thresholds = angle_thresholds(inputs)  # (A, K)
    weights = [c[cols].reshape(thresholds.shape) for c in result.coef]
    slope = np.median(static_slopes(inputs)[trial.valid], axis=0)  # (S, A)
    width = [float(np.sum(-2.0 * thresholds * w * slope[j][:, None]))
             for j, w in enumerate(weights)]
    return {"on": "angles", "angles": list(trial.angle_names),
            "loop_width": [significant(v) for v in width],
            "play_thresholds_deg": significant_list(thresholds),
            "weights": [np.round(w, 5).tolist() for w in weights]}


def _static_input_again(trial: Trial, inputs: Inputs, cand: Fit
                        ) -> tuple[Fit, Inputs, dict | None]:
    """``cand`` refitted, up to ``STATIC_INPUT_ROUNDS`` times, with its history terms driven
    by its own static part (:func:`~.model.with_static_of`) for as long as that lowers the
    held-out gap, the inputs it was fitted with, and what that did (JSON
    ``evidence.own_static_input``: the rounds kept and the gap before them; None where no
    term of ``cand`` reads ŝ)."""
    rounds = _static_input_rounds(trial, inputs, cand)
    return rounds[-1][0], rounds[-1][1], _rounds_done([f for f, _ in rounds])


def _static_input_rounds(trial: Trial, inputs: Inputs, cand: Fit) -> list[tuple[Fit, Inputs]]:
    """The rounds of :func:`_static_input_again`: ``cand`` and each refit kept, each with
    the inputs it was fitted with."""
    rounds = [(cand, inputs)]
    if not cand.spec.reads_static():
        return rounds
    for _ in range(STATIC_INPUT_ROUNDS):
        other = with_static_of(inputs, cand)
        refit = fit(trial, other, cand.spec)
        if refit.gap >= cand.gap:
            break
        cand, inputs = refit, other
        rounds.append((cand, inputs))
    return rounds


def _rounds_done(fits: list[Fit]) -> dict | None:
    """JSON ``evidence.own_static_input`` of the rounds ``fits`` (:func:`_static_input_rounds`)."""
    if not fits[0].spec.reads_static():
        return None
    return {"rounds": len(fits) - 1, "gap_before": significant(fits[0].gap)}


def _own_static_part(trial: Trial, inputs: Inputs, cand: Fit, loop_named: bool,
                     workers: int = 1, pose_loop: bool = True
                     ) -> tuple[Fit, Inputs, dict | None]:
    """:func:`_static_input_again`, and where a hysteresis was just named (``loop_named``)
    with each degree of the plays' level on ŝ (``HYSTERESIS_DEGREES``,
    :func:`~.model.hysteresis_columns`) as well: the one with the lowest held-out gap on its
    own static part is kept. Chosen on the first ŝ instead, powers that follow what that ŝ
    got wrong can win and then leave more once ŝ is the model's own
    (hysteresis/alt/m2/s1001: 0.2468 mm against the plain loop's 0.2168). For the same
    reason the loop's other configuration (plays on the angles where the candidate played
    on ŝ, or the other way round; :func:`~.candidates.best_candidate`) is refitted on its
    own static part beside it, with the map's degree chosen again for it
    (:func:`_best_degree`, as ``cand``'s was): a loop in the pose has no level powers, so
    it may win the step's comparison and then leave more than the plays on ŝ with their
    powers (graphene S3_4_HC45: 0.0949 against 0.0919 dR/R0), and on the map chosen with
    the loop in the pose the plays on ŝ left more than on their own (fourth blind
    generator's rec 17: 1.2465 against 1.2154 pF).

    The loop's refits are independent: they run as jobs in ``workers`` processes
    (:func:`_loop_rounds`), each sending back its fits, and the inputs of the one kept are
    formed again here from them (the inputs hold the designs' caches: too large to send).
    A loop in the pose waits for its other configuration's map before the plays' powers
    are fitted on it. Without ``pose_loop`` (the step's loop in the pose did not beat a
    richer map, :func:`_pose_loop_over_richer_map`) the plays on ŝ are not refitted in the
    pose."""
    if not loop_named:
        return _static_input_again(trial, inputs, cand)
    on_reading = replace(cand.spec, hysteresis_angles=False, hysteresis_degree=1)
    other = replace(on_reading, hysteresis_angles=not cand.spec.hysteresis_angles)
    job = functools.partial(_loop_rounds, trial, inputs)
    jobs: list[tuple[str, Fit | Spec]] = [("kept", cand)]
    if pose_loop or cand.spec.hysteresis_angles:
        jobs.append(("map again", other))
    if not cand.spec.hysteresis_angles:  # the powers on the plays' map, ``cand``'s
        jobs += [("fit", replace(on_reading, hysteresis_degree=d)) for d in HYSTERESIS_DEGREES]
    tried = forked_map(job, jobs, workers)
    if cand.spec.hysteresis_angles:  # the powers on the plays' own map, chosen in job 2
        reading = tried[1][0].spec
        tried += forked_map(job, [("fit", replace(reading, hysteresis_degree=d))
                                  for d in HYSTERESIS_DEGREES], workers)
    fits = min(tried, key=lambda rounds: rounds[-1].gap)
    for kept in fits[:-1]:  # the inputs of the last round, formed again
        inputs = with_static_of(inputs, kept)
    return fits[-1], inputs, _rounds_done(fits)


def _loop_rounds(trial: Trial, inputs: Inputs, job: tuple[str, Fit | Spec]) -> list[Fit]:
    """One job of :func:`_own_static_part`: the fits of :func:`_static_input_rounds` from
    ``("kept", fit)``, from ``("fit", spec)`` fitted, or from ``("map again", spec)``
    fitted with its map's degree chosen again (:func:`_best_degree`)."""
    how, start = job
    first = start if isinstance(start, Fit) else fit(trial, inputs, start)
    if how == "map again":
        first = _best_degree(trial, inputs, first)
    return [f for f, _ in _static_input_rounds(trial, inputs, first)]


def _pose_loop_over_richer_map(trial: Trial, inputs: Inputs, spec: Spec, base: Fit,
                               cand: Fit, evidence: dict, floor: float) -> tuple[Fit, dict]:
    """A loop in the pose (``cand``: the plays on the joint's angles added to ``spec``) and
    its ``evidence`` over ``base``, where it also clears rules 1 and 2 over a static map of
    one degree more (``evidence.over_richer_map``); else the plays on ŝ instead, with their
    evidence over ``base`` (and ``loop_in_pose_over_richer_map``).

    Each of its columns follows the direction of motion in one angle, so together they can
    take up what a map too stiff for the suit misses while the arm moves: two clean twins
    of the third blind generator, whose cubic maps of the arm axes leave 5.6 and 48 noise
    variances that a quartic takes, named a loop in the pose, which over the quartic
    removes nothing; a sleeve that slips keeps what it removes (the fifth generator's
    rec 12 and rec 34). A map with local functions is already flexible where the arm went
    and is not checked."""
    if spec.local:
        return cand, evidence
    richer = replace(spec, degree=spec.degree + 1)
    over = candidate_evidence(trial, fit(trial, inputs, richer),
                              fit(trial, inputs, replace(cand.spec, degree=richer.degree)), floor)
    check = {"degree": richer.degree,
             **{k: over[k] for k in ("delta_mse", "blocks_improved", "significant")}}
    if over["significant"]:
        return cand, {**evidence, "over_richer_map": check}
    reading = fit(trial, inputs, replace(cand.spec, hysteresis_angles=False))
    return reading, {**candidate_evidence(trial, base, reading, floor),
                     "loop_in_pose_over_richer_map": check}


def _against_curve(trial: Trial, inputs: Inputs, spec: Spec, cand: Fit, evidence: dict,
                   floor: float, workers: int = 1) -> dict:
    """``evidence`` of the stops ``cand`` over ``spec`` with rule 3: added to a smooth
    transfer curve of each sensor (``Spec.output_curve``), they must still clear rules 1
    and 2 over it, pooled or on the sensors held at hard stops, or else explain everything
    the curve does (``stops_leave_curve_nothing``): the curve added to the stops does not
    clear rule 1 over them (``curve_over_stops``) and the stops alone leave a lower held-out
    gap than the curve alone. A reading that bends gently over its whole range (a nonlinear
    transfer, a misfit spread over the poses) is calibration that soft knees at both ends
    can imitate, and the curve follows it better; a stop is a bend at an end that no smooth
    curve follows, or one approached so gently that a curve follows part of it and adds
    nothing to the stops. The stops with the curve are fitted one sensor a job in
    ``workers`` processes: where the candidate did not keep its stops they are chosen again
    beside the curve, the costliest part of a named saturation's step."""
    curve = fit(trial, inputs, replace(spec, output_curve=True))
    both_spec = replace(cand.spec, output_curve=True)  # stops chosen again where not kept
    both = fit(trial, inputs, both_spec, forked_map(
        functools.partial(sensor_part, trial, inputs, both_spec), range(trial.n_sensors),
        workers))
    over = candidate_evidence(trial, curve, both, floor)
    curve_adds = rules_on_blocks(cand.block_mse, both.block_mse, floor)
    encompassed, stops_vs_curve = stops_leave_curve_nothing(cand, curve, curve_adds, floor)
    return {**evidence, "significant": over["significant"] or encompassed,
            "against_smooth_curve": {
                "curve_gap": significant(curve.gap), **over,
                "curve_over_stops": {k: curve_adds[k] for k in (
                    "delta_mse", "removed_rms", "blocks_improved", "beyond_noise")},
                "stops_alone_over_curve_alone": {k: stops_vs_curve[k] for k in (
                    "delta_mse", "blocks_improved", "blocks_needed")},
                "stops_leave_curve_nothing": encompassed}}


def _counted_refined(trial: Trial, inputs: Inputs, base: Fit, cand: Fit, evidence: dict,
                     floor: float) -> dict:
    """``evidence`` of a drift beyond the noise that improves too few blocks, with rules 1
    and 2 taken again on the drift it would become if named
    (:func:`~.candidates.refine_drift`). Degrees 1–3 only rank the candidates; a slip step
    or a random walk that they smear over the recording worsens the blocks around the step
    until a drift follows it. The drift is
    still ranked by its low-degree ΔMSE, so a flexible function of time never outranks a
    creep for its flexibility."""
    refined = candidate_evidence(trial, base, refine_drift(trial, inputs, cand), floor)
    keys = ("heldout_gap", "delta_mse", "delta_mse_without_best_block", "blocks_improved",
            "blocks_needed", "over_movements", "significant")
    alone = refined.get("on_one_sensor") or {"sensors": {}, "beyond_noise_sensors": []}
    return {**evidence, "significant": refined["significant"],
            "refined": {**{k: refined[k] for k in keys},
                        "significant_on_sensors": list(alone["sensors"]),
                        "beyond_noise_sensors": list(alone["beyond_noise_sensors"])}}


def _jumped_in_hold(trial: Trial, inputs: Inputs, base: Fit, cand: Fit, evidence: dict,
                    floor: float) -> dict:
    """``evidence`` of a drift that clears no rule on the gap, made significant where a
    sensor's reading jumps while the joint holds still (:func:`~.jumps.jumps_in_holds`: an
    offset that moved at an instant, which no pose-driven effect does) and the drift it
    would become (:func:`_counted_refined`) lowers the held-out error of all sensors
    together, without its best block too, and beyond its noise on a sensor that jumped.
    Such a drift shifts only the blocks after each jump: it may improve too few folds for
    rule 2's sign test."""
    jumps = jumps_in_holds(trial, trial.y - base.prediction, inputs.still)
    if not jumps:
        return evidence
    counted = evidence if "refined" in evidence else _counted_refined(
        trial, inputs, base, cand, evidence, floor)
    refined = counted["refined"]
    jumped = sorted({trial.sensor_names[jump.sensor] for jump in jumps})
    beyond = [name for name in jumped if name in refined["beyond_noise_sensors"]]
    if not (refined["delta_mse"] > 0 and refined["delta_mse_without_best_block"] > 0
            and beyond):
        return counted
    t0 = float(trial.t[0])
    return {**counted, "significant": True, "jumped_in_hold": {
        "sensors": beyond,
        "jumps": [{"sensor": trial.sensor_names[jump.sensor],
                   "at_s": round(jump.at_s - t0, 3), "height": significant(jump.height),
                   "robust_z": round(jump.z, 1)} for jump in jumps]}}


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
    a candidate that passes on its low degrees. Jumps in holds were looked for on the same
    model when the candidate was scored (:func:`_candidate`): where there were any the drift
    was counted then."""
    if "refined" in evidence or not np.any(_slow_part(trial, base.residual) > trial.noise**2):
        return evidence
    return _counted_refined(trial, inputs, base, cand, evidence, floor)


def _slow_part(trial: Trial, residual: np.ndarray) -> np.ndarray:
    """Mean square of the held-out ``residual`` averaged over ``DRIFT_SPAN_S`` windows, per
    sensor (sensor units²; white noise leaves σ² / frames per window of it): about the most
    a drift of one function per window can remove from each sensor's held-out error. Under
    each sensor's noise variance no refined drift can pass rule 1, pooled or on one sensor,
    and its dozen fits are spared."""
    # every sensor analysed has finite frames
    return np.nanmean(windowed_mean(trial, residual, DRIFT_SPAN_S)**2, axis=0)


def _fast_only_words(scored: list[tuple[str, Fit, dict]]) -> str:
    """The candidates of ``scored`` that rule 4 alone kept from being named
    (:func:`~.rules.over_movements`; a drift counted on its refined form, on that), as a
    clause of the progress line; empty if none."""
    fast = [kind for kind, _, e in scored
            if e.get("refined", e)["over_movements"]["fails_alone"]]
    return (f"; {', '.join(fast)} lowered the error only from frame to frame, not averaged "
            f"over {MOVEMENT_S:g} s (rule 4)" if fast else "")


def _conclusion(steps: list[dict], spec: Spec, left: dict) -> str:
    """One line: what was named, and whether the model leaves more than the noise
    (``left``, :func:`~.rules.remainder`), which none of the five effects explains."""
    # beyond the noise only with a floor above zero, so only then is there a ratio to it
    times = f"{left['gap_over_floor']:.3g}× the noise floor" if left["beyond_noise"] else ""
    if steps:
        head = f"named {', '.join(s['effect'] for s in steps)}"
    elif not [k for k in VOCABULARY if k not in spec.effects()]:
        head = "every effect of the vocabulary is already in the model; nothing to add"
    elif left["beyond_noise"]:
        return f"no candidate effect explains what the model leaves ({times}); nothing added"
    else:
        return "no candidate effect beats the noise; nothing added"
    return f"{head}; what remains ({times}) none of the five effects explains" \
        if left["beyond_noise"] else head


def _candidates(trial: Trial, inputs: Inputs, spec: Spec, base: Fit, floor: float,
                missing: list[str], workers: int) -> list[tuple[str, Fit, dict]]:
    """Each effect in ``missing`` at its best configuration added to ``spec``, with its
    evidence against ``base`` (:func:`_candidate`), in the order of ``missing``.

    The candidates are independent, and so are the lag's models (``LAG_MODELS``) and each
    sensor's share of the saturation (:func:`~.candidates.saturation_parts`): all are
    computed at once in ``workers`` processes, the costliest first (``COSTLIEST_FIRST``);
    then the lag's models are compared here (:func:`~.candidates.best_lag`), as
    :func:`~.candidates.best_candidate` compares them, and the saturation is put together
    from its sensors' shares. Choosing one sensor's stops after another in one process
    was the step's longest job (12 of a 14 s step on a four-minute recording whose map
    has local functions) while the other process had finished the other candidates.
    What a named effect is refined from comes back to this process and is kept: the
    creep's families (:func:`~.candidates.creep_families`); ŝ's slopes, which the loop in
    the pose reads, are formed here first for every process (:func:`~.model.static_slopes`).
    Each had been formed again, one after the other: 1.2 and 2.6 s of a four-minute
    recording whose map has local functions."""
    shares: dict[str, tuple] = {"lag": LAG_MODELS, "saturation": tuple(range(trial.n_sensors)),
                                "creep": ("families",)}
    if "hysteresis" in missing:  # the loop in the pose reads ŝ's slopes: formed once here,
        static_slopes(inputs, workers)  # for every process, and for the loop's refits after
    jobs = [(kind, share) for kind in sorted(missing, key=COSTLIEST_FIRST.index)
            for share in shares.get(kind, (None,))]
    done = forked_map(functools.partial(_candidate_job, trial, inputs, spec, base, floor),
                      jobs, workers)
    tried = [(kind, cand, evidence) for kind, cand, evidence in done
             if isinstance(cand, Fit) and evidence is not None]
    if "lag" in missing:
        cand = best_lag([c for kind, c, _ in done if kind == "lag" and isinstance(c, Fit)])
        tried.append(("lag", cand, candidate_evidence(trial, base, cand, floor)))
    if "creep" in missing:  # kept here, where the candidate is chosen from them and a
        # named creep is refined from them
        creep_families(trial, inputs, spec, next(
            c for kind, c, _ in done if kind == "creep" and isinstance(c, tuple)))
        tried.append(_candidate(trial, inputs, spec, base, floor, "creep"))
    if "saturation" in missing:
        parts = [part for kind, part, _ in done if kind == "saturation" and isinstance(part, list)]
        tried.append(_candidate(trial, inputs, spec, base, floor, "saturation", workers,
                                saturation_candidate(trial, inputs, spec, parts)))
    return sorted(tried, key=lambda item: missing.index(item[0]))


def _candidate_job(trial: Trial, inputs: Inputs, spec: Spec, base: Fit, floor: float,
                   job: tuple[str, str | int | None]
                   ) -> tuple[str, Fit | tuple[Fit, ...] | list[SensorPart], dict | None]:
    """One job of :func:`_candidates`: ``(kind, None)``, the candidate ``kind``
    (:func:`_candidate`); ``("lag", model)``, the best lag of that model alone;
    ``("creep", "families")``, the creep's families (:func:`~.candidates.creep_families`);
    ``("saturation", j)``, sensor j's share of the saturation (evidence None for the last
    three: the lag's models are compared, the creep's families and the saturation's shares
    put together, first)."""
    kind, share = job
    if kind == "lag" and isinstance(share, str):
        return kind, lag_model(trial, inputs, spec, share), None
    if kind == "creep" and share == "families":
        return kind, creep_families(trial, inputs, spec), None
    if kind == "saturation" and isinstance(share, int):
        return kind, saturation_parts(trial, inputs, spec, share), None
    return _candidate(trial, inputs, spec, base, floor, kind)


def _candidate(trial: Trial, inputs: Inputs, spec: Spec, base: Fit, floor: float, kind: str,
               workers: int = 1, cand: Fit | None = None) -> tuple[str, Fit, dict]:
    """The best configuration of effect ``kind`` added to ``spec`` (``cand`` where found
    already) and its evidence against ``base`` (the model without it): one candidate of a
    step, on its own (``workers``: the processes the stops' comparison with a smooth curve
    may use, :func:`_against_curve`, where a sensor is pinned at a rail). Stops that clear
    rules 1 and 2 are judged against the curve where that decides the step
    (:func:`_judged`)."""
    if cand is None:
        cand = best_candidate(trial, inputs, kind, spec)
    evidence = candidate_evidence(trial, base, cand, floor)
    if kind == "drift" and beyond_noise_somewhere(evidence) and not evidence["significant"]:
        evidence = _counted_refined(trial, inputs, base, cand, evidence, floor)
    if kind == "drift" and not evidence["significant"]:
        evidence = _jumped_in_hold(trial, inputs, base, cand, evidence, floor)
    if kind == "hysteresis" and cand.spec.hysteresis_angles and evidence["significant"]:
        cand, evidence = _pose_loop_over_richer_map(trial, inputs, spec, base, cand, evidence,
                                                    floor)
    if kind == "saturation" and not evidence["significant"]:
        evidence = _at_rail(trial, inputs, spec, base, cand, evidence, floor, workers)
    return kind, cand, evidence


def _judged(trial: Trial, inputs: Inputs, spec: Spec, floor: float, workers: int,
            item: tuple[str, Fit, dict]) -> tuple[str, Fit, dict]:
    """A step's candidate ``item`` (:func:`_candidate`) as named: stops that clear rules 1
    and 2 judged against a smooth curve as well (rule 3, :func:`_against_curve`). Asked
    only where the answer decides the step (:func:`_winner`): 3.8 of the 11.5 s of the
    first step on a four-minute recording whose map has local functions went to judging
    stops that a loop was named over."""
    kind, cand, evidence = item
    if kind == "saturation" and evidence["significant"] and (
            "against_smooth_curve" not in evidence):
        return kind, cand, _against_curve(trial, inputs, spec, cand, evidence, floor, workers)
    return item


def _winner(judge: Callable[[tuple[str, Fit, dict]], tuple[str, Fit, dict]],
            scored: list[tuple[str, Fit, dict]]) -> tuple[str, Fit, dict] | None:
    """The candidate named of ``scored`` (sorted, most explained first): the first that is
    significant once judged (``judge``, :func:`_judged`, which replaces it in ``scored``);
    None where none is."""
    for k, item in enumerate(scored):
        if item[2]["significant"]:
            scored[k] = judge(item)
            if scored[k][2]["significant"]:
                return scored[k]
    return None


def _at_rail(trial: Trial, inputs: Inputs, spec: Spec, base: Fit, cand: Fit, evidence: dict,
             floor: float, workers: int) -> dict:
    """``evidence`` of stops that clear no rule on the gap, made significant where a sensor
    is pinned at a rail (:func:`~.stops.pinned_at_rail`: its reading sits at exactly one
    value however the pose moves, which no smooth transfer and no noise does) and the stops
    leave a held-out gap no larger than ``base``'s; with ``pinned_at_rail`` and the smooth
    curve's comparison (:func:`_against_curve`), for the record."""
    rail = pinned_at_rail(trial)
    if rail is None or cand.gap > base.gap:
        return evidence
    return {**_against_curve(trial, inputs, spec, cand, evidence, floor, workers),
            "significant": True, "pinned_at_rail": rail}


def drift_kept_words(kept: float) -> str:
    """The static map's hold on time (:func:`~.model.drift_kept_heldout`) in words."""
    return (f"the poses follow time: held out, the static map keeps {kept:.1%} of a linear "
            "drift and takes the rest in as the pose's doing (poses revisited through the "
            "recording tell the two apart)")


def _resampled(trial: Trial) -> list[dict]:
    """The sensors whose readings change less from one frame to the next than noise or a
    smooth movement can (``trial.resampled`` over ``RESAMPLED_SPREAD``), each with that
    spread (JSON ``resampled_sensors``; null where the floor is 0)."""
    return [{"sensor": name, "spread": significant(float(r)) if np.isfinite(r) else None}
            for name, r in zip(trial.sensor_names, trial.resampled, strict=True)
            if r > RESAMPLED_SPREAD]


def stamped_words(scatter_s: float) -> str:
    """Frames a host stamped on arrival (``Trial.times_steady``), their times scattering
    ``scatter_s`` s RMS about a steady rate, in words, for the progress line and the
    report."""
    return f"stamped as they arrived, in bursts ({1e3 * scatter_s:.2g} ms RMS about a steady rate)"


def resampled_words(resampled: list[dict]) -> str:
    """The sensors of ``resampled_sensors`` in words, for the progress line and the report."""
    spreads = ", ".join("without limit" if item["spread"] is None else f"{item['spread']:.3g}"
                        for item in resampled)
    one = len(resampled) == 1
    return (f"{'sensor' if one else 'sensors'} {', '.join(i['sensor'] for i in resampled)} "
            f"{'changes' if one else 'change'} less from one frame to the next than noise can: "
            f"over 2–{RESAMPLED_STRIDES} frames the readings' second differences spread "
            f"{spreads} times as wide as noise or a smooth movement makes them; resampled from "
            "a slower sensor? The noise floor is their widest spread instead, about that "
            "sensor's own noise")


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
    with one_blas_thread(), memory_reused():
        first = _run(rec, name, in_model, progress, processes)
        first = _filter_again(rec, name, in_model, progress, processes, first)
        first = _offset_again(rec, name, in_model, progress, processes, first)
        return _rate_again(rec, name, in_model, progress, processes, first)


def _offset_again(rec: Recording, name: str, in_model: tuple[str, ...],
                  progress: Callable[[str], None], workers: int, first: Outcome) -> Outcome:
    """``first``, or the workflow run again from the start with the motion capture read
    later where the readings still run ahead of it once the effects are added
    (:func:`~.timing.lead_after_effects`) and the second run ends lower."""
    found = lead_after_effects(rec, name, first.trial, first.after, pooled_noise(first.trial))
    if found is None:
        return first
    read_before = first.summary["clock_offset"]
    if read_before is not None and read_before["applied"]:
        found = {**found, "read_before": _clock_read(read_before)}
    return _again_if_read_so(first, "clock_offset", found, progress, lambda: _run(
        rec, name, in_model, progress, workers, found["mocap_late_s"], found,
        _filter_after_effects(first)))


def _invalid(trial: Trial) -> str:
    """How many of the trial's frames are invalid, and why: "135 invalid (100 dropped, 35
    outside the motion capture)"."""
    why = invalid_words(trial.invalid_by_cause)
    return f"{int((~trial.valid).sum())} invalid" + (f" ({why})" if why else "")


def rail_words(rail: dict, units: str) -> str:
    """A reading pinned at a rail (``pinned_at_rail`` evidence) in words, for the progress
    line and the report: "T0 reads exactly 0 counts, its lowest value, on 10.1% of its
    valid frames"."""
    return (f"{rail['sensor']} reads exactly {rail['level']:.6g} {units}, its "
            f"{'lowest' if rail['side'] == 'low' else 'highest'} value, on "
            f"{rail['share']:.1%} of its valid frames")


def _rail_words(evidence: dict, units: str) -> str:
    """Where a saturation was named because a reading is pinned at a rail (:func:`_at_rail`),
    a clause that says so; else ""."""
    rail = evidence.get("pinned_at_rail")
    return "" if rail is None else f"; {rail_words(rail, units)}: pinned at a rail"


def _jump_words(evidence: dict, units: str) -> str:
    """Where a drift was named because a reading jumped while the joint held still
    (:func:`_jumped_in_hold`), a clause that says so; else ""."""
    held = evidence.get("jumped_in_hold")
    if held is None:
        return ""
    jumps = held["jumps"]
    first = ", ".join(f"{j['sensor']} by {j['height']:+.3g} {units} at {j['at_s']:.1f} s"
                      for j in jumps[:JUMPS_LISTED])
    more = f" and {len(jumps) - JUMPS_LISTED} more" if len(jumps) > JUMPS_LISTED else ""
    return f"; readings jumped while the joint held still: {first}{more}"


def _clock_read(clock: dict) -> dict:
    """How a run's static step read the motion capture's clock (its ``clock_offset``
    evidence, applied), for the evidence of an offset found again once the effects were
    modelled (``read_before``): the run again from the start would otherwise show only the
    last step of the way there."""
    keys = ("mocap_late_s", "gap_without", "gap_with", "searched", "with_loop")
    return {k: clock[k] for k in keys if k in clock}


def _rate_again(rec: Recording, name: str, in_model: tuple[str, ...],
                progress: Callable[[str], None], workers: int, first: Outcome) -> Outcome:
    """``first``, or the workflow run again from the start with the motion capture read at
    another clock rate where the readings' lead over it still changes with time once the
    effects are added (:func:`~.timing.rate_after_effects`) and the second run ends lower.
    The start's offset is kept as ``first`` read it: the effects took the lead's mean."""
    found = rate_after_effects(rec, name, first.trial, first.after, pooled_noise(first.trial))
    if found is None:
        return first
    return _again_if_read_so(first, "clock_skew", found, progress, lambda: _run(
        rec, name, in_model, progress, workers, first.trial.mocap_late_s,
        filter_found=_filter_after_effects(first), rate_found=found))


def _again_if_read_so(first: Outcome, key: str, found: dict, progress: Callable[[str], None],
                      again: Callable[[], Outcome]) -> Outcome:
    """``first`` with what a screen of its final model found (``found``, JSON
    ``timing_after_effects[key]``) recorded and said; where the motion capture is to be read
    so (``applied``), the lower of ``first`` and the workflow run again from the start so
    read (``again``), with that run's final gap and whether it was kept."""
    said = (f"    with {', '.join(first.summary['effects']) or 'nothing'} added "
            f"{after_effects_words(key, found, first.trial.units)}")
    if not found["applied"]:
        progress(said)
        return _recorded(first, first, key, found)
    progress(f"{said}: again from the start")
    rerun = again()
    kept = _lower(first, rerun, progress)
    return _recorded(kept, first, key, {**found, "run_again": {
        "gap_after": significant(rerun.after.gap), "kept": kept is rerun}})


def _recorded(outcome: Outcome, first: Outcome, key: str, evidence: dict) -> Outcome:
    """``outcome`` with ``evidence`` of a screen of ``first``'s final model as its JSON
    ``timing_after_effects[key]``, beside the screens ``first`` had."""
    outcome.summary["timing_after_effects"] = {
        **first.summary["timing_after_effects"], key: evidence}
    return outcome


def _filter_after_effects(first: Outcome) -> dict | None:
    """How ``first`` read its motion capture where that was chosen with the effects in place
    (:func:`_filter_again`), for a run again from the start; None: chosen again there."""
    kept = first.summary["mocap_filter"]
    return kept if kept and "after_effects" in kept else None


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
    other = None if chosen["applied"] else chosen["low_pass_hz"]
    read, inputs = read_trial(rec, name, trial.mocap_late_s, other, final.spec,
                              trial.mocap_skew)
    refit = fit(read, inputs, final.spec)
    rules = rules_on_blocks(final.block_mse, refit.block_mse, pooled_noise(trial))
    if refit.gap >= final.gap or rules["blocks_improved"] < rules["blocks_needed"]:
        return first
    gaps = (refit.gap, final.gap) if other is None else (final.gap, refit.gap)
    found = {"low_pass_hz": chosen["low_pass_hz"], "applied": other is not None,
             "gap_as_sampled": significant(gaps[0]), "gap_low_passed": significant(gaps[1]),
             "after_effects": True}
    effects = ", ".join(first.summary["effects"]) or "nothing"
    how = "low-passed" if other is not None else "read as sampled"
    progress(f"    with {effects} added, the motion capture {how} leaves {refit.gap:.4g} against "
             f"{final.gap:.4g} {trial.units}: again from the start, so read")
    return _lower(first, _run(rec, name, in_model, progress, workers, filter_found=found),
                  progress)


def _read_from_the_start(evidence: dict | None, reading: dict, after_effects: dict) -> dict:
    """The evidence of how a run from the start read its motion capture as found once the
    effects were modelled (``after_effects``): its own static step's (``evidence``) where
    that read it so too, else how it was read (``reading``), with ``after_effects``."""
    here = evidence if evidence is not None and evidence["applied"] else {
        **reading, "applied": True}
    return {**here, "after_effects": after_effects}


def rate_words(rate_hz: float, nominal_hz: float) -> str:
    """What to say where the frames' times give a rate (``rate_hz``) that disagrees with
    the recording's nominal one (its metadata's; :func:`rates_disagree`): nothing
    otherwise."""
    if not rates_disagree(nominal_hz, rate_hz):
        return ""
    return (f"the frames' times give {rate_hz:.4g} Hz where the metadata says {nominal_hz:g} "
            "Hz: are the times in seconds (recording format v1)?")


def _best_of(trial: Trial, inputs: Inputs, spec: Spec, kind: str) -> tuple[str, Fit]:
    """Effect ``kind``'s best configuration added to ``spec``, with its name."""
    return kind, best_candidate(trial, inputs, kind, spec)


def _fit_in_model(trial: Trial, inputs: Inputs, static_fit: Fit, in_model: tuple[str, ...],
                  workers: int) -> tuple[Fit, Inputs, str]:
    """The model with the effects the profile already has (``in_model``), fitted as named
    effects are: the one that lowers the held-out gap most first, each refined, the map's
    degree chosen again and driven by its own static part, so that each is fitted with the
    larger ones in place (in the profile's order, a loop fitted before the lag took
    the lag's share: the suit's own profile left 2.6 times the gap of no profile). Returns
    the fit, its inputs and the effect added last ("" for none)."""
    base, missing, previous = static_fit, list(in_model), ""
    while missing:
        tried = forked_map(functools.partial(_best_of, trial, inputs, base.spec), missing,
                           workers)
        kind, cand = min(tried, key=lambda item: item[1].gap)
        base, inputs, _, _ = _add_effect(trial, inputs, kind, cand, previous, workers)
        missing.remove(kind)
        previous = kind
    return base, inputs, previous


def _add_effect(trial: Trial, inputs: Inputs, kind: str, cand: Fit, previous: str,
                workers: int, pose_loop: bool = True
                ) -> tuple[Fit, Inputs, dict | None, tuple[tuple, tuple]]:
    """Effect ``kind``'s candidate ``cand`` made part of the model, as every effect is
    once named (or given by the profile): its shape refined, the map's degree chosen
    again, the lag or drift already in the model refitted where that is due, and the
    terms driven by the model's own static part (:func:`_own_static_part`; a loop in the
    pose only where ``pose_loop``). ``previous`` is the effect added in the step before;
    ``workers``, the processes a refinement may use. Returns the fit, the inputs it was
    made with, the own-static-part evidence and the lag and drift terms before their
    refit."""
    refined = refine(trial, inputs, kind, cand, workers)
    cand = _best_degree(trial, inputs, refined, workers)
    if kind == "lag" and cand.spec != refined.spec:  # a lag refined on the map chosen
        # without it is biased toward that map: refine it again on the map now chosen
        cand = refine_lag_delay(trial, inputs, cand)
    if kind == "drift" and cand.spec != refined.spec:  # so is a drift's basis and count
        cand = refine_drift(trial, inputs, cand)
    drift_before = cand.spec.drift_term()
    if kind != "drift" and cand.spec.drift_degree:
        cand = refine_drift(trial, inputs, cand)
    lag_before = cand.spec.lag_term()
    if previous == "lag":  # a lag named while a larger effect was
        # still missing was fitted against it: refit it once, with the next effect added
        cand = refine_lag_delay(trial, inputs, cand)
    cand, inputs, own_input = _own_static_part(trial, inputs, cand, kind == "hysteresis",
                                               workers, pose_loop)
    return cand, inputs, own_input, (lag_before, drift_before)


def _run(rec: Recording, name: str, in_model: tuple[str, ...],
         progress: Callable[[str], None], workers: int, mocap_late_s: float = 0.0,
         after_effects: dict | None = None, filter_found: dict | None = None,
         rate_found: dict | None = None) -> Outcome:
    """:func:`run` with ``workers`` processes for a step's candidates, the motion capture
    read ``mocap_late_s`` late (found by :func:`~.timing.lead_after_effects`, whose evidence is
    ``after_effects``) on a clock as fast as ``rate_found`` says (its evidence, found by
    :func:`~.timing.rate_after_effects`; None: the sensors' rate) and, given
    ``filter_found`` (by :func:`_filter_again`), filtered as it says instead of as
    :func:`~.timing.mocap_filter` would choose."""
    low_pass_hz = (filter_found["low_pass_hz"]
                   if filter_found is not None and filter_found["applied"] else None)
    trial = prepare_trial(rec, name, mocap_late_s, low_pass_hz,
                          0.0 if rate_found is None else 1e-6 * rate_found["mocap_skew_ppm"])
    floors = trial.noise
    floor = pooled_noise(trial)
    placed = "" if trial.placed_by == FRAME_COUNTER else f" (placed by {trial.placed_by})"
    sensors = f"{trial.n_sensors} sensor{'' if trial.n_sensors == 1 else 's'}"
    progress(f"[1] calibrating the static map: {sensors} ({trial.units}) from "
             f"{', '.join(trial.angle_names)} ({trial.joint}), {trial.n} frames at "
             f"{trial.rate_hz:.1f} Hz{placed}, {_invalid(trial)}; noise floor "
             f"{floor:.4g} {trial.units}")
    if trial.times_steady:
        progress(f"    the frames were {stamped_words(trial.time_scatter_s)}: the grid takes the "
                 "steady times")
    other_rate = rate_words(trial.rate_hz, rec.sensor_rate_hz)
    if other_rate:
        progress(f"    {other_rate}")
    for sensor, reason in trial.ignored:
        progress(f"    left out sensor {sensor}: it {reason}")
    if trial.spikes.any():
        progress(f"    isolated spikes, not fitted or scored: "
                 f"{spike_counts(trial.sensor_names, trial.spikes.tolist())} (readings over "
                 f"{SPIKE_SIGMAS:g} σ from the median of their {SPIKE_WINDOW} frames)")
    resampled = _resampled(trial)
    if resampled:
        progress(f"    {resampled_words(resampled)}: analyse such a stream at its sensor's rate")
    scaled = make_inputs(trial)  # one basis per map for every ridge
    uncovered = restrict_to_coverage(trial, scaled.u)
    if uncovered > 0:
        progress(f"    {uncovered:.1%} of frames are poses no other fold covers: not scored")
    static_fit = _static_map(trial, scaled, floor, workers)

    def static_map(other: Trial, inputs: Inputs) -> Fit:
        """The static map chosen for ``other``, the trial read another way."""
        return _static_map(other, inputs, floor, workers)

    if filter_found is None:
        trial, scaled, static_fit, filtered = mocap_filter(rec, name, trial, scaled,
                                                           static_fit, static_map)
    else:
        filtered = filter_found
    progress(f"    {filter_words(filtered, trial.units)}")

    def loop(other: Trial, inputs: Inputs, spec: Spec) -> Fit:
        """The hysteresis candidate added to ``spec`` on ``other``, a trial read another
        way, driven by its own static part as a named loop is (its loop in the pose reads
        ŝ's slopes: formed in ``workers`` processes)."""
        static_slopes(inputs, workers)
        return _static_input_again(other, inputs,
                                   best_candidate(other, inputs, "hysteresis", spec))[0]

    trial, scaled, static_fit, clock = refine_with_loop(
        rec, name, *clock_offset(rec, name, trial, scaled, static_fit, floor, static_map,
                                 workers),
        floor, loop, lambda other, inputs, spec: _static_input_again(
            other, inputs, fit(other, inputs, spec))[0], static_map)
    if clock is not None:
        progress(f"    {clock_words(clock, trial.units)}")
    trial, scaled, static_fit, skew = clock_skew(rec, name, trial, scaled, static_fit, floor,
                                                 static_map)
    if skew is not None:
        progress(f"    {skew_words(skew, trial.units)}")
    late = {"mocap_late_s": round(trial.mocap_late_s, 6)}
    if rate_found is not None:  # read at its rate from the start: found after the effects
        skew = _read_from_the_start(skew, {"mocap_skew_ppm": round(1e6 * trial.mocap_skew, 3),
                                           **late}, rate_found)
    if after_effects is not None:  # read late from the start: found after the effects
        clock = _read_from_the_start(clock, late, after_effects)
    inputs = make_inputs(trial, static_fit.spec)
    # previous: the effect added in the step before (the profile's last one, or none)
    base, inputs, previous = _fit_in_model(trial, inputs, static_fit, in_model, workers)
    spec = base.spec
    before = base
    runs = [trial.sensor_names[j] for j in inputs.segment_sensors]
    calibrated = _map_summary(spec, inputs, runs)
    progress(f"[2] simulated with the calibrated model ({map_words(calibrated)}"
             f"{', with ' + ', '.join(in_model) if in_model else ''}): held-out gap "
             f"{base.gap:.4g} {trial.units}")
    drift_kept = drift_kept_heldout(trial, inputs, static_fit.spec)
    if drift_kept < DRIFT_KEPT_NOTED:
        progress(f"    {drift_kept_words(drift_kept)}")
    mot = motion(trial, inputs.static)
    local_before = localise(trial, base.residual, mot)
    progress(f"[3] localised ({trial.units} RMS): by direction " + ", ".join(
        f"{d} {_rms_words(r)}" for d, r in local_before["by_direction"].items())
        + f"; during holds {_rms_words(local_before['holds']['rms'])}; by speed, slow to fast, "
        + ", ".join(_rms_words(c["rms"]) for c in local_before["by_speed"]))
    steps: list[dict] = []
    rejected: list[dict] = []
    step = 4
    while True:
        missing = [k for k in VOCABULARY if k not in spec.effects()]
        if not missing:
            break
        sig = signatures(trial, base.residual, mot, floor)
        inputs.cache["without_lag"] = base  # the lag candidates' model without the lag
        scored = _candidates(trial, inputs, spec, base, floor, missing, workers)
        judge = functools.partial(_judged, trial, inputs, spec, floor, workers)
        if not any(e["significant"] for k, _, e in scored if k != "saturation"):
            scored = [judge(item) for item in scored]  # stops alone count once judged
        if not any(e["significant"] for _, _, e in scored):
            scored = [(k, c, _last_count(trial, inputs, base, c, e, floor) if k == "drift"
                       else e) for k, c, e in scored]
        scored.sort(key=lambda item: -item[2]["delta_mse"])
        table = ", ".join(f"{k} {e['heldout_gap']:.4g}" for k, _, e in scored)
        winner = _winner(judge, scored)
        if winner is None:
            rejected = [{"effect": k, "gap": e["heldout_gap"], "evidence": {**e, **sig}}
                        for k, _, e in scored]
            progress(f"[{step}] no candidate beats the noise (gap {base.gap:.4g}, floor "
                     f"{floor:.4g}; tried {table}{_fast_only_words(scored)}): nothing added")
            break
        kind, cand, named = winner
        cand, inputs, own_input, (lag_before, drift_before) = _add_effect(
            trial, inputs, kind, cand, previous, workers,
            "loop_in_pose_over_richer_map" not in named)
        previous = kind
        evidence = candidate_evidence(trial, base, cand, floor)
        if kind == "saturation":  # judged against the smooth curve when it was named
            evidence["against_smooth_curve"] = named["against_smooth_curve"]
        for key in ("pinned_at_rail", "jumped_in_hold", "over_richer_map",
                    "loop_in_pose_over_richer_map"):
            if key in named:
                evidence[key] = named[key]
        if own_input is not None:
            evidence["own_static_input"] = own_input
        if "refined" in named:  # a drift counted on the drift it would become
            low = named
            evidence["low_degrees"] = {
                **{k: low[k] for k in ("heldout_gap", "delta_mse", "removed_rms",
                                       "blocks_improved", "blocks_needed", "beyond_noise")},
                "beyond_noise_sensors": low.get("on_one_sensor", {}).get(
                    "beyond_noise_sensors", [])}
            evidence["refined"] = low["refined"]  # the count it was named on
        spec, base = cand.spec, cand
        refit = {k: effect_params(k, cand, inputs, trial) for k, changed in
                 (("lag", cand.spec.lag_term() != lag_before),
                  ("drift", cand.spec.drift_term() != drift_before))
                 if changed}
        steps.append({"effect": kind, "gap": significant(cand.gap),
                      "params": effect_params(kind, cand, inputs, trial),
                      "evidence": {**evidence, "signature": sig, "refitted": refit,
                                   "alternatives": {k: e["heldout_gap"] for k, _, e in scored
                                                    if k != kind}}})
        own = (f"; driven by its own static part: {own_input['gap_before']:.4g} before"
               if own_input and own_input["rounds"] else "")
        refitted = "".join(f"; {k} refitted: {_shape_words(p)}" for k, p in refit.items())
        progress(f"[{step}] added {kind}: held-out gap {cand.gap:.4g} {trial.units} "
                 f"(tried {table}){own}{_rail_words(evidence, trial.units)}"
                 f"{_jump_words(evidence, trial.units)}{refitted}")
        step += 1
    after = base
    left = remainder(trial, after, floor)
    local_after = localise(trial, after.residual, mot)
    if local_after["steps"]:
        progress(f"    {steps_words(local_after['steps'], trial.units)}; see report.md")
    summary = {
        "recording": name,
        "effects": [s["effect"] for s in steps],
        "gap_before": significant(before.gap),
        "gap_after": significant(after.gap),
        "units": trial.units,
        "sensors": list(trial.sensor_names),
        "sensors_ignored": [{"sensor": sensor, "reason": reason}
                            for sensor, reason in trial.ignored],
        "sensor_gap_before": significant_list(before.sensor_gap()),
        "sensor_gap_after": significant_list(after.sensor_gap()),
        "noise_floor": significant(floor),
        "noise_floor_per_sensor": significant_list(floors),
        "joint": trial.joint,
        "angles": list(trial.angle_names),
        "mocap_low_pass_hz": trial.mocap_low_pass_hz,
        "mocap_filter": filtered,
        "rate_hz": round(trial.rate_hz, 4),
        "frames": trial.n,
        "frames_placed_by": trial.placed_by,
        "frame_time_scatter_s": significant(trial.time_scatter_s),
        "frame_times": "steady rate" if trial.times_steady else "as recorded",
        "invalid_frames": int((~trial.valid).sum()),
        "invalid_by_cause": trial.invalid_by_cause,
        "spikes": trial.spikes.tolist(),
        "resampled_sensors": resampled,
        "unscored_frames": int((trial.valid & ~trial.scored).sum()),
        "drift_kept_heldout": significant(drift_kept),
        "already_in_model": list(in_model),
        "clock_offset": clock,
        "clock_skew": skew,
        "timing_after_effects": {"clock_offset": None, "clock_skew": None},
        "static_map": _map_summary(spec, inputs, runs),
        "static_map_calibrated": calibrated,
        "heldout_blocks": int(trial.blocks.max()) + 1,
        "localisation_before": local_before,
        "localisation_after": local_after,
        "steps": steps,
        "not_added": rejected,
        "remainder": left,
        "conclusion": _conclusion(steps, spec, left),
    }
    return Outcome(trial=trial, inputs=inputs, before=before, after=after, summary=summary)
