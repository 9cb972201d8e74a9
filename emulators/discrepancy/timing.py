"""How the motion capture is read against the readings: its clock offset, its clock rate
and its filter.

Each is calibration of the recording, not an effect of the suit, and each is chosen by the
sensors on held-out blocks. Readings that run ahead of the motion capture mean its clock is
late (:func:`clock_offset`, and once the effects are modelled :func:`lead_after_effects`);
a lead that grows or shrinks steadily over the recording means the two clocks run at
different rates (:func:`clock_skew`);
angles that hold more above a cutoff (``MOCAP_CUTOFFS_HZ``) than the readings follow are a
tracker's noise and are low-passed (:func:`mocap_filter`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from exohil.emulators.discrepancy.data import (
    MOCAP_CUTOFFS_HZ,
    Trial,
    mocap_samples,
    prepare_trial,
    smooth_angles,
)
from exohil.emulators.discrepancy.figures import significant
from exohil.emulators.discrepancy.folds import block_mse
from exohil.emulators.discrepancy.model import (
    Fit,
    Inputs,
    Spec,
    fit,
    legendre_products,
    make_inputs,
    map_inputs,
    restrict_to_coverage,
)
from exohil.emulators.discrepancy.rules import pooled_noise, rules_on_blocks
from exohil.emulators.discrepancy.workers import forked_map
from exohil.formats.alignment import in_mocap_gap
from exohil.formats.recording import Recording

#: A static map chosen for a trial and its scaled inputs (the workflow's calibration step).
MapFit = Callable[[Trial, Inputs], Fit]
#: A loop added to a spec on a trial and its inputs, driven by its own static part (the
#: workflow's hysteresis candidate; or the loop of a spec refitted), for a clock read with
#: it (:func:`refine_with_loop`).
LoopFit = Callable[[Trial, Inputs, Spec], Fit]
#: Readings that run ahead of the motion capture are a clock offset (:func:`clock_offset`),
#: corrected when it explains at least this share of what the static map leaves above the
#: noise, found in at most ``CLOCK_STEPS`` static refits.
CLOCK_SHARE = 0.5
CLOCK_STEPS = 3
#: A lead too long for the first order to read (:func:`lead_search`): leads up to
#: ``SEARCH_MAX_S`` (and a quarter of the recording) each way are tried every
#: ``SEARCH_STEP_S``, then every ``SEARCH_FINE_S`` about the shortest of the best, each
#: scored by a polynomial of degree ``SEARCH_DEGREE`` in the map's inputs (one less for more
#: than three inputs) fitted to a frame every ``SEARCH_ROW_S``. A lead ahead of
#: ``SEARCH_MIN_S`` or more that removes at least ``CLOCK_SHARE`` of what that polynomial
#: leaves at the stamped times is where :func:`clock_offset` starts reading the clock.
SEARCH_MAX_S = 30.0
SEARCH_STEP_S = 0.1
SEARCH_FINE_S = 0.01
SEARCH_ROW_S = 0.1
SEARCH_DEGREE = 3
SEARCH_MIN_S = 0.1
#: Frames (leads × rows) that :func:`lead_search` scores at once: a few megabytes each array.
SEARCH_BATCH_ROWS = 20_000
#: Leads whose cubic leaves at most this many times the least are as good as the best to
#: :func:`lead_search`, which keeps the shortest of them.
SEARCH_ALIAS = 1.25
#: Readings the search finds this much behind the motion capture or more are where
#: :func:`clock_offset` starts reading its clock early: no suit lags its pose by a second
#: (the lag candidates' longest low-pass and delay are 0.2 and 0.15 s).
SEARCH_BEHIND_S = 1.0


def lead_s(trial: Trial, model: Fit) -> tuple[float, np.ndarray]:
    """How far the readings run ahead of the motion capture, s (negative: behind), and the
    rate of change dŝ/dt (N, S) of ``model``'s full prediction ŝ, per second: the lead is
    the least-squares d of the held-out residual on d·dŝ/dt over the scored frames, each
    sensor weighted by the inverse of its noise variance. A reading ahead by d is
    ŝ(t + d) ≈ ŝ + d·dŝ/dt."""
    slope, _, aa, ar = _lead_terms(trial, model)
    den = float(aa.sum())
    return (float(ar.sum()) / den if den > 0 else 0.0), slope


def _lead_terms(trial: Trial, model: Fit) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                   np.ndarray]:
    """What the readings' lead is fitted from: the rate dŝ/dt (N, S) of ``model``'s
    prediction, τ (N,) = t − the grid's first time (s), and per frame Σ w·(dŝ/dt)² and
    Σ w·(dŝ/dt)·r (N,) over the sensors of its scored held-out residual r, each sensor
    weighted by the inverse of its noise variance."""
    slope = np.gradient(model.prediction, axis=0) * trial.rate_hz
    tau = trial.t - trial.t[0]
    scored = np.isfinite(model.residual)
    weight = 1.0 / np.maximum(trial.noise, np.finfo(float).tiny) ** 2
    a = np.where(scored, slope, 0.0)
    aa = np.sum(a * a * weight, axis=1)
    ar = np.sum(a * np.where(scored, model.residual, 0.0) * weight, axis=1)
    return slope, tau, aa, ar


def _line(tau: np.ndarray, aa: np.ndarray, ar: np.ndarray) -> tuple[float, float]:
    """Least-squares d0, d1 of the lead d0 + d1·τ from the per-frame sums of the rows given
    (0, 0 where they cannot tell a line)."""
    gram = np.array([[aa.sum(), (aa * tau).sum()], [(aa * tau).sum(), (aa * tau**2).sum()]])
    if np.linalg.det(gram) <= 1e-12 * gram[0, 0] * gram[1, 1]:
        return 0.0, 0.0
    d0, d1 = np.linalg.solve(gram, np.array([ar.sum(), (ar * tau).sum()]))
    return float(d0), float(d1)


def lead_trend(trial: Trial, model: Fit) -> tuple[float, float]:
    """The readings' lead over the motion capture as a line in time, d0 + d1·τ (d0 in s, d1
    in s per s, τ = t − the grid's first time, s): least squares of the held-out residual
    on dŝ/dt and τ·dŝ/dt over the scored frames (:func:`_lead_terms`)."""
    _, tau, aa, ar = _lead_terms(trial, model)
    return _line(tau, aa, ar)


def held_out_trend(trial: Trial, model: Fit, floor: float) -> dict:
    """Rules 1 and 2 (``floor``: the pooled noise floor) for the lead as a line in time over
    the lead as a constant, each fitted to first order on the other folds and removed from
    each held-out block: whether the lead changes with time in most blocks, told apart from
    the noise that a line fitted to the same frames would follow."""
    slope, tau, aa, ar = _lead_terms(trial, model)
    constant, line = np.zeros(trial.n), np.zeros(trial.n)
    for b in range(int(trial.blocks.max()) + 1):
        out = trial.blocks == b
        train = ~out
        constant[out] = ar[train].sum() / aa[train].sum() if aa[train].sum() > 0 else 0.0
        d0, d1 = _line(tau[train], aa[train], ar[train])
        line[out] = d0 + d1 * tau[out]
    return rules_on_blocks(block_mse(trial, model.residual - constant[:, None] * slope),
                           block_mse(trial, model.residual - line[:, None] * slope), floor)


def lead_search(rec: Recording, trial: Trial, workers: int = 1) -> dict:
    """Where a coarse search finds the readings match the motion capture best when it is read
    later (or earlier) than ``trial`` reads it: ``lead_s``, s (positive: the readings run
    ahead of it; negative: behind), and ``share``, the part of what a cubic map leaves at
    ``trial``'s reading that reading it so removes (0 … 1).

    The first order (:func:`lead_s`) reads a lead of tens of milliseconds; a clock that
    is a second off leaves readings that no longer resemble the motion's derivative, and it
    reads nothing there. The search needs no model of the suit: at each lead tried, the
    readings of a frame every ``SEARCH_ROW_S`` are fitted by a polynomial of degree
    ``SEARCH_DEGREE`` in the static map's inputs (:func:`~.model.map_inputs`; degree
    ``SEARCH_DEGREE`` − 1 for more than three, as with the axial rotation), each sensor
    scaled to unit variance. Of the leads whose fit leaves at most ``SEARCH_ALIAS`` times
    the least, the shortest is kept (then refined every ``SEARCH_FINE_S``): a movement that
    repeats matches its motion capture a period later nearly as well, and a suit's lag of
    tens of milliseconds must not be read as a clock a period off. Leads that leave less
    than half of the frames with motion capture are not tried, and where the stamped times
    do, nothing is searched (``lead_s`` and ``share`` 0): what is left at leads over other
    frames is no measure of what reading so removes.
    """
    stream = rec.mocap[trial.joint]
    t_mocap, raw = mocap_samples(stream)
    raw, _ = smooth_angles(t_mocap, raw, trial.mocap_low_pass_hz)
    raw = raw[:, [stream.names.index(angle) for angle in trial.angle_names]]
    lo, hi = raw.min(axis=0), raw.max(axis=0)
    rows = np.arange(0, len(trial.t), max(1, round(trial.rate_hz * SEARCH_ROW_S)))
    rows = rows[np.all(np.isfinite(trial.y[rows]), axis=1)]
    t, y = trial.t[rows], trial.y[rows]
    read0 = t + trial.mocap_late_s + trial.mocap_skew * (t - trial.t[0])

    def left(leads: np.ndarray) -> np.ndarray:
        """What the polynomial leaves with the motion capture read each of ``leads`` s
        later: mean square over the frames it covers and the sensors that vary there, in
        units of each sensor's variance; inf where less than half the frames are covered.
        Scored in batches of ``SEARCH_BATCH_ROWS`` frames in ``workers`` processes: the
        same scores in any number."""
        size = max(1, SEARCH_BATCH_ROWS // max(1, len(rows)))
        batches = [leads[first:first + size] for first in range(0, len(leads), size)]
        return np.concatenate(forked_map(left_in_batch, batches, workers))

    def left_in_batch(leads: np.ndarray) -> np.ndarray:
        """:func:`left` of a batch of leads: each lead's frames that the motion capture
        does not cover weighted 0, which sums what reading them apart would."""
        read = read0[None, :] + leads[:, None]  # (L, R)
        inside = ((read >= t_mocap[0]) & (read <= t_mocap[-1])
                  & ~in_mocap_gap(read.ravel(), t_mocap).reshape(read.shape))
        scores = np.full(len(leads), np.inf)
        enough = np.flatnonzero(2 * inside.sum(axis=1) >= max(1, len(rows)))
        if enough.size:
            scores[enough] = left_covered(read[enough], inside[enough])
        return scores

    def left_covered(read: np.ndarray, inside: np.ndarray) -> np.ndarray:
        """:func:`left` of the leads whose reading times are ``read`` (L, R), of which the
        motion capture covers ``inside`` (L, R), at least half of each."""
        angles = np.stack([np.interp(read, t_mocap, raw[:, k]) for k in range(raw.shape[1])],
                          axis=-1).reshape(-1, raw.shape[1])
        u = map_inputs(angles, trial.angle_names, lo, hi)[0]
        basis = legendre_products(u, SEARCH_DEGREE - (u.shape[1] > 3))[0]
        basis = basis.reshape(read.shape + (-1,))  # (L, R, P)
        w = inside.astype(float)
        n = w.sum(axis=1)  # (L,)
        dev = y[None] - ((w @ y) / n[:, None])[:, None, :]  # (L, R, S) about each mean
        scale = np.sqrt(np.einsum("lr,lrs->ls", w, dev * dev) / n[:, None])
        varies = scale > 0
        z = dev * (w[..., None] / np.where(varies, scale, 1.0)[:, None, :])  # 0 outside
        weighted = basis * w[..., None]
        # normal equations: a least-squares solver is 10x slower
        gram = np.swapaxes(weighted, 1, 2) @ basis
        ridge = 1e-9 * np.trace(gram, axis1=1, axis2=2) / gram.shape[1]
        gram[:, np.arange(gram.shape[1]), np.arange(gram.shape[1])] += ridge[:, None]
        coef = np.linalg.solve(gram, np.swapaxes(weighted, 1, 2) @ z)
        rest = (z - weighted @ coef) * varies[:, None, :]
        cells = n * varies.sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(cells > 0, np.sum(rest * rest, axis=(1, 2)) / cells, np.inf)

    steps = int(min(SEARCH_MAX_S, 0.25 * float(trial.t[-1] - trial.t[0])) / SEARCH_STEP_S
                + 1e-9)
    coarse = SEARCH_STEP_S * np.arange(-steps, steps + 1)
    scores = left(coarse)
    stamped = float(scores[steps])
    if steps < 1 or not 0.0 < stamped < np.inf:
        return {"lead_s": 0.0, "share": 0.0}
    near = coarse[scores <= SEARCH_ALIAS * scores.min()]
    pick = float(near[int(np.argmin(np.abs(near)))])
    fine = pick + SEARCH_FINE_S * np.arange(-round(SEARCH_STEP_S / SEARCH_FINE_S),
                                            round(SEARCH_STEP_S / SEARCH_FINE_S) + 1)
    fine_scores = np.where(np.abs(fine) < 1e-12, stamped, left(fine))
    best = int(np.argmin(fine_scores))
    return {"lead_s": round(float(fine[best]), 3),
            "share": round(max(0.0, 1.0 - float(fine_scores[best]) / stamped), 4)}


def first_order_lead(trial: Trial, model: Fit, floor: float) -> float | None:
    """The lead of ``model``'s readings (:func:`lead_s`) where it is positive and removing
    it from the held-out residual to first order clears rules 1 and 2; else None."""
    lead, slope = lead_s(trial, model)
    if lead <= 0.0:
        return None
    shifted = block_mse(trial, model.residual - lead * slope)
    return lead if rules_on_blocks(model.block_mse, shifted, floor)["significant"] else None


def read_later(rec: Recording, name: str, trial: Trial, lead: float, spec: Spec | None,
                refit: Callable[[Trial, Inputs], Fit]) -> tuple[Trial, Inputs, Fit]:
    """The recording read as ``trial`` was (its motion capture filtered and its clock rate
    taken alike) but ``lead`` s later, and refitted (``refit``, on inputs scaled for
    ``spec``), up to ``CLOCK_STEPS`` times, each adding the lead that remains, until it is
    within a tenth of a frame."""
    late = trial.mocap_late_s
    for _ in range(CLOCK_STEPS):
        late += lead
        shifted, inputs = read_trial(rec, name, late, trial.mocap_low_pass_hz, spec,
                                     trial.mocap_skew)
        model = refit(shifted, inputs)
        lead, _ = lead_s(shifted, model)
        if abs(lead) * shifted.rate_hz < 0.1:
            break
    return shifted, inputs, model


def read_trial(rec: Recording, name: str, late: float, low_pass_hz: float | None,
          spec: Spec | None, skew: float = 0.0) -> tuple[Trial, Inputs]:
    """The recording on its grid with the motion capture read ``late`` s late, its clock
    running ``skew`` s per s fast, low-passed at ``low_pass_hz`` (None: as sampled), and its
    inputs scaled for ``spec``, held-out frames scored where the other folds cover their
    pose."""
    trial = prepare_trial(rec, name, late, low_pass_hz, skew)
    inputs = make_inputs(trial, spec)
    restrict_to_coverage(trial, inputs.u)
    return trial, inputs


def mocap_filter(rec: Recording, name: str, trial: Trial, scaled: Inputs, static: Fit,
                 static_map: MapFit) -> tuple[Trial, Inputs, Fit, dict | None]:
    """The trial with its motion capture low-passed at a cutoff of ``MOCAP_CUTOFFS_HZ`` where
    that predicts the held-out readings better, or as sampled, with its scaled inputs and
    static map; the evidence (None: the motion capture samples too slowly to filter).

    What the motion capture holds above a cutoff is either a tracker's noise, which the
    suit never felt, or movement the tendons followed (a tremor; joint angles solved from
    markers frame by frame and replayed). Only the sensors can tell: the map of
    ``trial`` (read as sampled) is refitted on the angles low-passed at the first cutoff,
    kept where its held-out gap is smaller. A lower cutoff is tried only where the one
    above it was kept, and kept only where it clears rules 1 and 2 against it, as an effect
    must: a zero-phase low-pass of the pose at a few Hz also smooths what a suit's lag or
    loop does to the readings, and on exact angles with a loop the static map's gap fell
    by 0.0002 mm at 6 Hz while the final model's rose by 0.004 mm. A low-passed trial then
    gets its static map chosen again (``static_map``).
    """
    floor = pooled_noise(trial)
    tried: dict[str, float] = {}
    kept: tuple[Trial, Inputs, float] | None = None
    above, below = static, {}
    for cutoff_hz in MOCAP_CUTOFFS_HZ:
        filtered = prepare_trial(rec, name, trial.mocap_late_s, cutoff_hz, trial.mocap_skew)
        if filtered.mocap_low_pass_hz is None:  # too close to the mocap's Nyquist
            break
        inputs = make_inputs(filtered)
        restrict_to_coverage(filtered, inputs.u)
        same_map = fit(filtered, inputs, static.spec)
        tried[f"{cutoff_hz:g}"] = significant(same_map.gap)
        if kept is None:
            lower = same_map.gap < above.gap
        else:
            rules = rules_on_blocks(above.block_mse, same_map.block_mse, floor)
            below = {"lower_cutoff_rules": {"low_pass_hz": cutoff_hz, **rules}}
            lower = rules["significant"]
        if not lower:
            break
        kept, above = (filtered, inputs, cutoff_hz), same_map
    if not tried:
        return trial, scaled, static, None
    low_pass_hz = MOCAP_CUTOFFS_HZ[0] if kept is None else kept[2]
    evidence = {"low_pass_hz": low_pass_hz, "applied": kept is not None,
                "gap_as_sampled": significant(static.gap),
                "gap_low_passed": tried[f"{low_pass_hz:g}"], "gaps_low_passed": tried, **below}
    if kept is None:
        return trial, scaled, static, evidence
    filtered, inputs, _ = kept
    return filtered, inputs, static_map(filtered, inputs), evidence


def filter_words(evidence: dict | None, units: str) -> str:
    """How the motion capture was read (:func:`mocap_filter`, :func:`~.workflow._filter_again`), in
    words."""
    if evidence is None:
        return "motion capture read as sampled (too slow to low-pass)"
    model = "final model" if "after_effects" in evidence else "static map"
    low, raw = f"{evidence['gap_low_passed']:.4g}", f"{evidence['gap_as_sampled']:.4g}"
    hz = f"{evidence['low_pass_hz']:g} Hz"
    rules = evidence.get("lower_cutoff_rules")
    refused = ("" if rules is None or rules["significant"] else f"{rules['low_pass_hz']:g}")
    others = "".join(f"; at {other} Hz {gap:.4g}"
                     + (", not lower by rules 1 and 2" if other == refused else "")
                     for other, gap in evidence.get("gaps_low_passed", {}).items()
                     if other != f"{evidence['low_pass_hz']:g}")
    if low == raw:  # no difference the figures show: no claim of what lies above the cutoff
        how, which = ((f"low-passed at {hz}, zero phase", "smaller low-passed, beyond the "
                       "digits shown") if evidence["applied"]
                      else ("read as sampled", f"low-passed at {hz}, no smaller"))
        return (f"motion capture {how}: the {model}'s held-out gap is {low} {units} either way "
                f"({which}{others}), so the readings cannot tell what it holds above {hz}")
    gaps = f"the {model}'s held-out gap {low} against {raw} {units} as sampled{others}"
    if evidence["applied"]:
        return (f"motion capture low-passed at {hz}, zero phase: {gaps}; what it held above "
                "that the readings do not follow")
    return (f"motion capture read as sampled: low-passed at {hz}, {gaps}; the readings follow "
            "what it holds above that")


def reread_evidence(without: Fit, reread: Fit, floor: float) -> dict:
    """Rules 1 and 2 for the motion capture read another way (``reread``) over ``without``,
    the share of ``without``'s residual above the noise it explains, and whether that
    reading is kept (``applied``: both rules and at least ``CLOCK_SHARE``)."""
    rules = rules_on_blocks(without.block_mse, reread.block_mse, floor)
    excess = without.gap**2 - floor**2
    share = (without.gap**2 - reread.gap**2) / excess if excess > 0 else 0.0
    return {"applied": bool(rules["significant"] and share >= CLOCK_SHARE),
            "gap_without": significant(without.gap), "gap_with": significant(reread.gap),
            "share_of_excess": round(share, 4), **rules}


def earliest_reading(trial: Trial) -> float:
    """How early, s late, the motion capture of ``trial`` may be read by a screen that
    finds it ahead or moves it with a clock rate: never earlier than stamped, nor than an
    offset the search already read it early by (:func:`_searched_clock`)."""
    return min(0.0, trial.mocap_late_s)


def offset_evidence(late: float, without: Fit, later: Fit, floor: float,
                    earliest: float = 0.0) -> dict:
    """:func:`reread_evidence` for the motion capture read ``late`` s late (``later``),
    kept only where that is later than ``earliest``, s (:func:`earliest_reading`)."""
    evidence = reread_evidence(without, later, floor)
    return {"mocap_late_s": round(late, 6), **evidence,
            "applied": bool(late > earliest and evidence["applied"])}


def _searched_clock(searched: dict) -> bool:
    """Whether :func:`clock_offset` reads the clock from the search's lead
    (:func:`lead_search`): ahead by ``SEARCH_MIN_S`` or more, or behind by
    ``SEARCH_BEHIND_S`` or more, removing at least ``CLOCK_SHARE`` of what its cubic map
    leaves."""
    lead = searched["lead_s"]
    return (lead >= SEARCH_MIN_S or lead <= -SEARCH_BEHIND_S) and (
        searched["share"] >= CLOCK_SHARE)


def clock_offset(rec: Recording, name: str, trial: Trial, scaled: Inputs, static: Fit,
                 floor: float, static_map: MapFit, workers: int = 1
                 ) -> tuple[Trial, Inputs, Fit, dict | None]:
    """The trial read with the motion capture's clock offset where the readings run ahead
    of it (or a second or more behind it), with its scaled inputs and static map
    (``static_map``, refitted on the trial so read); the evidence (None: nothing found;
    ``floor``: the pooled noise floor).

    A suit cannot answer a move before it is made, so readings ahead of the motion capture
    mean its samples are stamped late: calibration, like a gain or an offset, not an effect
    of the suit. (Readings behind it are a lag or a clock offset the other way, which the
    data cannot tell apart: ``lag`` is the candidate for both, up to ``SEARCH_BEHIND_S``,
    longer than any suit lags its pose.) Where the search over leads (:func:`lead_search`)
    finds one ahead by ``SEARCH_MIN_S`` or more, or behind by ``SEARCH_BEHIND_S`` or more,
    that removes at least ``CLOCK_SHARE`` of what its cubic map leaves
    (:func:`_searched_clock`), the motion capture
    is read that much later (or earlier) and the map refitted, refining it to first order
    (:func:`read_later`); where that is not kept, or the search found nothing, the lead is
    estimated from the static map's residual (:func:`lead_s`), and where removing it to
    first order clears rules 1 and 2, the motion capture is read that much later and the map
    refitted the same way. The offset is kept where the refitted map clears rules 1 and 2
    over the first and explains at least ``CLOCK_SHARE`` of what the first map left above
    the noise: an offset moves every sensor by its own speed alike and, where it is the
    cause, explains nearly all of it, while an effect whose loop reads a little ahead (a
    Bouc–Wen loop on the hidden suite reads 7 ms ahead) keeps most of its residual. The
    evidence holds the search's ``searched`` where it led the way. The search runs in
    ``workers`` processes.
    """
    tried, searched = None, lead_search(rec, trial, workers)
    if _searched_clock(searched):
        shifted, inputs, refit = read_later(rec, name, trial, searched["lead_s"], None,
                                            static_map)
        tried = {**offset_evidence(shifted.mocap_late_s, static, refit, floor, -np.inf),
                 "searched": searched}
        if tried["applied"]:
            return shifted, inputs, refit, tried
    lead = first_order_lead(trial, static, floor)
    if lead is None:
        return trial, scaled, static, tried
    shifted, inputs, refit = read_later(rec, name, trial, lead, None, static_map)
    evidence = offset_evidence(shifted.mocap_late_s, static, refit, floor,
                               earliest_reading(trial))
    if evidence["applied"]:
        return shifted, inputs, refit, evidence
    return trial, scaled, static, evidence


def refine_with_loop(rec: Recording, name: str, trial: Trial, scaled: Inputs, static: Fit,
                     clock: dict | None, floor: float, loop: LoopFit, loop_again: LoopFit,
                     static_map: MapFit) -> tuple[Trial, Inputs, Fit, dict | None]:
    """A clock offset that :func:`clock_offset` found (``clock``: read, or found to first
    order and left to the effects) read again with a loop in the pose modelled (``loop``;
    ``loop_again``, its spec refitted), with the trial, its scaled inputs, static map and
    evidence (``with_loop``); as they are where no offset was found.

    A loop trails its pose on every branch, as a lag does, so a static map takes part of
    it for the clock's lead. The fixture's suit stamped 1.5 s early was read 1.567 s early
    by the search and the static map's first order, where its final model found 1.555 s
    and, run again from the start so read, ended at 0.238 mm against 0.618 (twice the
    time); a loop (hidden suite, lib, m1, seed 100) with its motion capture 15 ms late read
    9.2 ms to first order, which the static map did not keep, and nothing was named
    (0.632 mm). Here the loop is fitted at the clock as the trial reads it and its lead read
    to first order (:func:`lead_s`), then refined as the static map's was
    (:func:`read_later`), the loop refitted, each fit driven by its own static part as a
    named loop is (fitted on the first ŝ, a loop of the hidden suite, lib, m2, seed 100,
    stamped 1.5 s early was read 1.7 ms off: 0.170 mm left, against 0.162 so). The read is
    kept by the offset's rules (:func:`offset_evidence`: rules 1 and 2 and at least
    ``CLOCK_SHARE`` of what the loop left above the noise; later than the trial reads it
    where the static map kept no offset, as a clock is read to first order only where the
    readings run ahead), and the static map is chosen again on the trial so read. The
    fixture 1.5 s early is read 1.552 s early and ends at 0.2086 mm in one run; the loop
    14.2 ms late and named, 0.162 mm (0.155 on time). A lead within a tenth of a frame is
    left as read."""
    if clock is None:
        return trial, scaled, static, clock
    looped = loop(trial, make_inputs(trial, static.spec), static.spec)
    lead, _ = lead_s(trial, looped)
    if abs(lead) * trial.rate_hz < 0.1:
        return trial, scaled, static, clock
    shifted, _, refit = read_later(rec, name, trial, lead, looped.spec,
                                   lambda tr, inp: loop_again(tr, inp, looped.spec))
    earliest = -np.inf if clock["applied"] else earliest_reading(trial)
    evidence = {"static_read_s": clock["mocap_late_s"], "static_applied": clock["applied"],
                **offset_evidence(shifted.mocap_late_s, looped, refit, floor, earliest)}
    if not evidence["applied"]:
        return trial, scaled, static, {**clock, "with_loop": evidence}
    # the trial the last refit read (read as this one was, at the kept clock), scaled anew
    trial, scaled = shifted, make_inputs(shifted)
    static = static_map(trial, scaled)
    evidence["static_gap"] = significant(static.gap)
    return trial, scaled, static, {**clock, "mocap_late_s": evidence["mocap_late_s"],
                                   "applied": True, "with_loop": evidence}


def clock_skew(rec: Recording, name: str, trial: Trial, scaled: Inputs, static: Fit,
               floor: float, static_map: MapFit) -> tuple[Trial, Inputs, Fit, dict | None]:
    """The trial read with the motion capture's clock rate where the readings' lead over it
    changes steadily with time, with its scaled inputs and static map (``static_map``,
    refitted on the trial so read); the evidence (None: no such trend).

    Two devices that stamp their samples with clocks of their own (a sensor board that
    counts its frames at a nominal rate, a camera system with its own crystal) drift apart
    by their rate difference: 100 ppm is 24 ms over four minutes, a lead that grows through
    the recording where a suit's lag stays the same. The lead is fitted as a line in time
    (:func:`lead_trend`); where removing that line to first order improves most held-out
    blocks over removing a constant lead (:func:`held_out_trend`; the first order can fall
    well short of what reading the motion capture so would remove, so rule 1 waits for the
    refit), the motion capture is read with that rate (its offset at the start moved with
    it, but never read earlier than stamped, or than an offset found early, as in
    :func:`clock_offset` (:func:`earliest_reading`): readings behind the motion capture may
    be a lag), the map
    refitted, up to ``CLOCK_STEPS`` times until what remains is within a tenth of a frame
    at the recording's ends. The rate is kept where the refitted map clears rules 1
    and 2 over the first and explains at least ``CLOCK_SHARE`` of what it left above the
    noise (:func:`reread_evidence`).
    """
    if not trend_passes(held_out_trend(trial, static, floor)):
        return trial, scaled, static, None
    shifted, inputs, refit = read_at_rate(rec, name, trial, static, None, static_map,
                                          earlier=False)
    skew, late = shifted.mocap_skew, shifted.mocap_late_s
    evidence = {"mocap_skew_ppm": round(1e6 * skew, 3), "mocap_late_s": round(late, 6),
                **reread_evidence(static, refit, floor)}
    if evidence["applied"]:
        return shifted, inputs, refit, evidence
    return trial, scaled, static, evidence


def trend_passes(trend: dict) -> bool:
    """Whether a lead that changes with time (:func:`held_out_trend`) passes the screen:
    it improves most held-out blocks over a constant lead, also without its best block (rule
    2; rule 1 waits for the refit, since the first order can fall well short of it)."""
    return trend["blocks_improved"] >= trend["blocks_needed"] and bool(
        trend["delta_mse_without_best_block"] > 0)


def read_at_rate(rec: Recording, name: str, trial: Trial, model: Fit, spec: Spec | None,
                 refit: MapFit, earlier: bool) -> tuple[Trial, Inputs, Fit]:
    """The recording read as ``trial`` was (its motion capture filtered alike), with the
    motion capture's clock rate and offset moved by ``model``'s lead line
    (:func:`lead_trend`), and refitted (``refit``, on inputs scaled for ``spec``), up to
    ``CLOCK_STEPS`` times, each adding the line that remains, until it is within a tenth of
    a frame at the recording's ends. ``earlier``: whether the motion capture may be read
    earlier than :func:`earliest_reading` (never before any effect: readings behind it may
    be a lag;
    once a lag is modelled, it took the line's mean, so the line is read whole)."""
    d0, d1 = lead_trend(trial, model)
    late, skew = trial.mocap_late_s, trial.mocap_skew
    span = float(trial.t[-1] - trial.t[0])

    def moved(late: float, d0: float) -> float:
        return late + d0 if earlier else max(late + d0, earliest_reading(trial))

    for _ in range(CLOCK_STEPS):
        late = moved(late, d0)
        skew += d1
        shifted, inputs = read_trial(rec, name, late, trial.mocap_low_pass_hz, spec, skew)
        fitted = refit(shifted, inputs)
        d0, d1 = lead_trend(shifted, fitted)
        if abs(moved(late, d0) - late) * shifted.rate_hz < 0.1 and (
                abs(d1) * span * shifted.rate_hz < 0.1):
            break
    return shifted, inputs, fitted


def skew_words(skew: dict, units: str) -> str:
    """The clock rate's evidence (:func:`clock_skew`) as one sentence."""
    ppm = skew["mocap_skew_ppm"]
    head = (f"the readings' lead over the motion capture changes with time: the motion "
            f"capture's clock runs {abs(ppm):.3g} ppm {'fast' if ppm > 0 else 'slow'} against "
            f"the sensors'")
    later = skew.get("after_effects")
    if later is not None:
        head += (f" (found once the effects were modelled: read so, the model explained "
                 f"{later['share_of_excess']:.0%} of what it left above the noise)")
    if skew["applied"]:
        gaps = (f" (the static map's held-out gap {skew['gap_without']:.4g} -> "
                f"{skew['gap_with']:.4g} {units})" if "gap_without" in skew else "")
        return (f"{head}, and is read at that rate from {offset_words(skew['mocap_late_s'])} "
                f"at the start{gaps}; the recording's timing, not the suit's")
    return (f"{head} to first order, but read so the static map explains "
            f"{skew['share_of_excess']:.0%} of what it left above the noise "
            f"({skew['blocks_improved']} blocks improved of {skew['blocks_needed']} needed): "
            f"left to the effects")


def lead_after_effects(rec: Recording, name: str, trial: Trial, final: Fit, floor: float
                       ) -> dict | None:
    """Where the readings of ``trial`` still run ahead of the motion capture once the
    effects are added (``final``, the final model; ``floor``, the pooled noise floor), the
    clock offset and its evidence (:func:`offset_evidence`); None where they do not.

    A lead that a larger effect hid from the static map's residual (:func:`clock_offset`)
    shows in the final model's, and is found the same way, the final model refitted with
    the motion capture read later (its effects' shapes kept, the coefficients refitted).
    Judged on that refit, not to first order: the effects were fitted against the lead."""
    lead = first_order_lead(trial, final, floor)
    if lead is None:
        return None
    shifted, _, refit = read_later(rec, name, trial, lead, final.spec,
                                   lambda tr, inp: fit(tr, inp, final.spec))
    return offset_evidence(shifted.mocap_late_s, final, refit, floor,
                           earliest_reading(trial))


def rate_after_effects(rec: Recording, name: str, trial: Trial, final: Fit, floor: float
                       ) -> dict | None:
    """Where the readings' lead over the motion capture of ``trial`` still changes steadily
    with time once the effects are added (``final``, the final model; ``floor``, the pooled
    noise floor), the clock rate and its evidence (:func:`reread_evidence`); None where no
    trend passes the screen (:func:`trend_passes`).

    A rate that a larger effect hid from the static map's residual (:func:`clock_skew`)
    shows in the final model's, and is found the same way, the final model refitted with
    the motion capture read at that rate (its effects' shapes kept, the coefficients
    refitted). The line is read whole, earlier than stamped where it says so: a lag fitted
    against a rate took the mean of its lead, which the refit keeps. Judged on that refit;
    where kept, the workflow starts again with the rate alone (the offset at the start as
    it was), so that the effects are fitted on the recording read at its rate."""
    if not trend_passes(held_out_trend(trial, final, floor)):
        return None
    shifted, _, refit = read_at_rate(rec, name, trial, final, final.spec,
                                     lambda tr, inp: fit(tr, inp, final.spec), earlier=True)
    return {"mocap_skew_ppm": round(1e6 * shifted.mocap_skew, 3),
            **reread_evidence(final, refit, floor)}


def after_effects_words(key: str, found: dict, units: str) -> str:
    """What a screen of the final model's timing found (``key``: ``clock_offset``,
    :func:`lead_after_effects`, or ``clock_skew``, :func:`rate_after_effects`), in words,
    from "the readings" on: how far the motion capture would be read, and whether that was
    kept."""
    if key == "clock_offset":
        head = f"the readings run {side_words(found['mocap_late_s'])} the motion capture"
    else:
        ppm = found["mocap_skew_ppm"]
        head = (f"the readings' lead over the motion capture changes with time: its clock runs "
                f"{abs(ppm):.3g} ppm {'fast' if ppm > 0 else 'slow'}")
    if not found["applied"]:
        return (f"{head} to first order, but read so the model explains "
                f"{found['share_of_excess']:.0%} of what it left above the noise "
                f"({found['blocks_improved']} blocks improved of {found['blocks_needed']} "
                f"needed): left as it is")
    gaps = (f"read so the model leaves {found['gap_with']:.4g} against "
            f"{found['gap_without']:.4g} {units}")
    again = found.get("run_again")
    if again is None:
        return f"{head} ({gaps})"
    if again["kept"]:
        return f"{head} ({gaps}); the workflow ran again from the start, so read"
    return (f"{head} ({gaps}), but the workflow run again from the start, so read, ended at "
            f"{again['gap_after']:.4g} {units}: the first run was kept")


def clock_words(clock: dict, units: str) -> str:
    """The clock offset's evidence (:func:`clock_offset`, :func:`lead_after_effects`) as
    one sentence."""
    late_s = clock["mocap_late_s"]
    head = f"the readings run {side_words(late_s)} the motion capture"
    searched = clock.get("searched")
    looped = clock.get("with_loop")
    first = ""
    if looped is not None and looped["applied"]:  # the static map's gaps are the first read's
        first = (f", {offset_words(looped['static_read_s'])}, where the static map's held-out "
                 f"gap went {clock['gap_without']:.4g} -> {clock['gap_with']:.4g} {units}"
                 f"{'' if looped['static_applied'] else ', not kept'}")
    read_so = first + ("" if looped is None else loop_words(looped, units))
    if searched is not None:
        head += f" ({search_words(searched)}; refined to first order{read_so})"
    elif read_so:
        head += f" (to first order{read_so})"
    later = clock.get("after_effects")
    if later is not None:
        head += (f" (found once the effects were modelled: read so late, the model explained "
                 f"{later['share_of_excess']:.0%} of what it left above the noise"
                 f"{read_before_words(later.get('read_before'), units)})")
    if clock["applied"]:
        gaps = (f" (the static map's held-out gap {clock['gap_without']:.4g} -> "
                f"{clock['gap_with']:.4g} {units})" if "gap_without" in clock and not first
                else "")
        why = ("which no suit can do" if late_s >= 0.0 else
               "longer than any suit lags its pose")
        return (f"{head}, {why}: its clock is taken as {offset_words(late_s)} and read "
                f"so{gaps}; the recording's timing, not the suit's")
    reading = f"reading the motion capture so much {'later' if late_s >= 0.0 else 'earlier'}"
    if clock["share_of_excess"] < CLOCK_SHARE:
        why = (f"{reading} explains only {clock['share_of_excess']:.0%} of what the static map "
               f"leaves above the noise")
    else:
        why = (f"{reading} does not clear rules 1 and 2 (removed RMS "
               f"{clock['removed_rms']:.4g} {units}, {clock['blocks_improved']} blocks "
               f"improved of {clock['blocks_needed']} needed)")
    return (f"{head}{'' if searched or read_so else ' to first order'}, but {why}: left to the "
            f"effects")


def loop_words(looped: dict, units: str) -> str:
    """How the clock read with a loop in the pose modelled (:func:`refine_with_loop`'s
    ``with_loop``) went, as a clause after "refined to first order"."""
    gaps = f"{looped['gap_without']:.4g} -> {looped['gap_with']:.4g} {units}"
    if not looped["applied"]:
        share = looped["share_of_excess"]
        return (f"; with the loop in the pose modelled it read "
                f"{offset_words(looped['mocap_late_s'])}, not kept: the loop's held-out gap "
                f"{gaps}, {f'{share:.0%} of' if share > 0 else 'none of'} its excess")
    return (f"; then with the loop in the pose modelled, "
            f"{offset_words(looped['mocap_late_s'])}, where the loop's held-out gap went "
            f"{gaps} and the static map's is {looped['static_gap']:.4g} {units}: a static map "
            f"takes part of a loop's lag for the clock's")


def search_words(searched: dict) -> str:
    """What the search over leads (:func:`lead_search`) found, in words."""
    lead = searched["lead_s"]
    return (f"a search over leads found the readings best matched {late_words(abs(lead))} "
            f"{'ahead' if lead > 0 else 'behind'}, removing {searched['share']:.0%} of what a "
            f"cubic map leaves at the stamped times")


def read_before_words(read_before: dict | None, units: str) -> str:
    """How the run before the offset was found again had read the clock
    (``read_before``, :func:`~.workflow._clock_read`), as a clause after a semicolon; ""
    where it read it as stamped."""
    if read_before is None:
        return ""
    how = (f": {search_words(read_before['searched'])}, and" if "searched" in read_before
           else " to first order, and")
    first, loop = read_before["mocap_late_s"], ""
    looped = read_before.get("with_loop")
    if looped is not None and looped["applied"]:  # the static map read it first
        first = looped["static_read_s"]
        loop = (f", then {offset_words(looped['mocap_late_s'])} with the loop in the pose "
                f"modelled (the loop's held-out gap {looped['gap_without']:.4g} -> "
                f"{looped['gap_with']:.4g} {units})")
    return (f"; the run before had read it {offset_words(first)}{how} "
            f"its static map's held-out gap went {read_before['gap_without']:.4g} -> "
            f"{read_before['gap_with']:.4g} {units}{loop}")


def side_words(late_s: float) -> str:
    """How far the readings run ahead of (``late_s`` ≥ 0) or behind the motion capture read
    ``late_s`` s late, e.g. "42 ms ahead of", "3.06 s behind"."""
    return (f"{late_words(late_s)} ahead of" if late_s >= 0.0
            else f"{late_words(-late_s)} behind")


def offset_words(late_s: float) -> str:
    """The motion capture's clock read ``late_s`` s late in words, e.g. "42 ms late",
    "3.06 s early"."""
    return f"{late_words(abs(late_s))} {'late' if late_s >= 0.0 else 'early'}"


def late_words(seconds: float) -> str:
    """A clock offset in words: milliseconds under a second (3 significant digits), else
    seconds."""
    if abs(seconds) < 1.0:
        return f"{1000.0 * seconds:.3g} ms"
    return f"{seconds:.3g} s" if abs(seconds) < 100.0 else f"{seconds:.0f} s"
