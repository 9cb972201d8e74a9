"""Saturation: the stops of a sensor, where its reading stops following the pose.

A hard stop clips the reading at a plateau it sits on while the joint moves (the map is
fitted off it, then through it as a censored reading: :func:`fold_fits`); a soft knee
bends the reading toward an asymptote (the map is fitted through the knee by
Gauss–Newton). Which, and where, is chosen per sensor on held-out blocks
(:func:`choose_stops`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace

import numpy as np

from exohil.emulators.discrepancy.data import N_BLOCKS, Trial, quantisation_step
from exohil.emulators.discrepancy.filters import low_pass
from exohil.emulators.discrepancy.folds import (
    Reduced,
    Ridge,
    fold_coefs,
    fold_system,
    ridge_solve,
)

#: Share of moving frames a sensor must sit at an end of its range to count as a stop.
PLATEAU_SHARE = 0.02
#: Share of a sensor's valid frames that must read exactly its lowest or highest value for
#: the reading to be pinned at a rail (:func:`pinned_at_rail`).
RAIL_SHARE = 0.01
#: Knee candidates of a soft stop: the share of a sensor's valid frames beyond the knee.
KNEE_SHARES = (0.03, 0.07, 0.12, 0.2, 0.3)
#: Softness candidates of a knee, as multiples of the distance from the knee to the sensor's
#: extreme reading (the bend's asymptote lies that far beyond the knee).
KNEE_SOFTNESS = (1.0, 1.5, 2.5)
#: Knee shapes b(u) and their slopes b′(u), u ≥ 0 the depth beyond the knee in units of the
#: softness: both start with slope 1 and approach 1. ``tanh`` (u − u³/3) keeps its slope
#: for a while past the knee; ``exp`` (1 − e^−u, u − u²/2) starts bending at once. Which one
#: a knee takes is chosen on held-out blocks with its level and softness.
Bend = Callable[[np.ndarray], np.ndarray]
KNEE_BENDS: dict[str, tuple[Bend, Bend]] = {
    "tanh": (np.tanh, lambda u: 1.0 - np.tanh(u) ** 2),
    "exp": (lambda u: -np.expm1(-u), lambda u: np.exp(-u)),
}
#: Gauss–Newton iterations of a fit through soft stops: linearised at the all-block fit, then
#: at each fold's own (:func:`fit_through_stops`).
SHARED_ITERATIONS = 2
OWN_ITERATIONS = 1


@dataclass(frozen=True)
class Stops:
    """A sensor's stops: the levels where its reading stops following the pose.

    Below ``lo`` the reading bends with slope 1 at the knee toward the asymptote
    ``lo − soft_lo``: ``lo − soft_lo·b((lo − x)/soft_lo)`` with the knee shape b of
    ``shape_lo`` (:data:`KNEE_BENDS`); ``soft_lo = 0`` is a hard stop (clipped at ``lo``).
    Likewise above ``hi``. ±inf: no stop on that side.
    """

    lo: float = -math.inf
    hi: float = math.inf
    soft_lo: float = 0.0
    soft_hi: float = 0.0
    shape_lo: str = "tanh"
    shape_hi: str = "tanh"

    def __post_init__(self) -> None:
        for shape in (self.shape_lo, self.shape_hi):
            if shape not in KNEE_BENDS:
                raise ValueError(f"knee shape {shape!r} is not one of {', '.join(KNEE_BENDS)}")

    def apply(self, x: np.ndarray) -> np.ndarray:
        """x (N,) through the stops (NaN stays NaN)."""
        out = np.array(x, dtype=np.float64)
        with np.errstate(invalid="ignore"):
            below, above = out < self.lo, out > self.hi
        if self.soft_lo > 0:
            bend = KNEE_BENDS[self.shape_lo][0]
            out[below] = self.lo - self.soft_lo * bend((self.lo - out[below]) / self.soft_lo)
        else:
            out[below] = self.lo
        if self.soft_hi > 0:
            bend = KNEE_BENDS[self.shape_hi][0]
            out[above] = self.hi + self.soft_hi * bend((out[above] - self.hi) / self.soft_hi)
        else:
            out[above] = self.hi
        return out

    def slope(self, x: np.ndarray) -> np.ndarray:
        """d apply(x) / dx (1 between the stops, 0 beyond a hard one)."""
        out = np.ones_like(x)
        with np.errstate(invalid="ignore"):
            below, above = x < self.lo, x > self.hi
        out[below] = (KNEE_BENDS[self.shape_lo][1]((self.lo - x[below]) / self.soft_lo)
                      if self.soft_lo > 0 else 0.0)
        out[above] = (KNEE_BENDS[self.shape_hi][1]((x[above] - self.hi) / self.soft_hi)
                      if self.soft_hi > 0 else 0.0)
        return out

    def beyond_hard(self, x: np.ndarray) -> np.ndarray:
        """(N,) bool: x lies beyond a hard stop (NaN does not)."""
        with np.errstate(invalid="ignore"):
            return (((x < self.lo) & (self.soft_lo == 0))
                    | ((x > self.hi) & (self.soft_hi == 0)))

    @property
    def soft(self) -> bool:
        """A soft knee on either side."""
        return self.soft_lo > 0 or self.soft_hi > 0

    @property
    def hard(self) -> bool:
        """A hard stop (a plateau the reading is clipped at) on either side."""
        return ((math.isfinite(self.lo) and self.soft_lo == 0)
                or (math.isfinite(self.hi) and self.soft_hi == 0))



NO_STOPS = Stops()



def pinned_at_rail(trial: Trial) -> dict | None:
    """The sensor whose reading is pinned at a rail: on at least ``RAIL_SHARE`` of the valid
    frames it reads exactly its lowest (or highest) value, and its readings are finer than
    its noise (a quantisation step below the noise floor, :func:`~.data.quantisation_step`,
    so that no reading repeats exactly by chance or while the arm is held still); of several,
    the one pinned most. None where no sensor is.

    A converter's or a range's limit holds the reading at one value however the pose moves,
    and a limit applied after the noise removes the noise there too, so held out it may
    leave less than no limit would: the fifth blind generator's ADC floor clips (3.1–10.2 %
    of frames at exactly 0; one leaves 16.19 counts against its clean twin's 17.48) pass no
    rule on the gap. Noise spreads a free reading over values no two frames share: on every
    other benchmark recording at most 0.33 % of frames read a sensor's extreme value.
    Returns ``sensor``, ``side`` ("low" or "high"), ``level`` (sensor units) and ``share``
    (of the valid frames)."""
    count = int(trial.valid.sum())
    pinned, most = None, RAIL_SHARE
    for j, name in enumerate(trial.sensor_names):
        y = trial.y[trial.valid, j]
        if count == 0 or not quantisation_step(y) < trial.noise[j]:
            continue
        for side, level in (("low", np.min(y)), ("high", np.max(y))):
            share = float(np.sum(y == level)) / count
            if share >= most:
                pinned, most = {"sensor": name, "side": side, "level": float(level),
                                "share": round(share, 4)}, share
    return pinned


def plateaus(trial: Trial, j: int) -> tuple[float, float]:
    """Stop levels of sensor j: an end of its range where it sits (within 6 σ of noise) on
    at least ``PLATEAU_SHARE`` of the frames while the joint moves faster than 10 °/s.
    A sensor that only reaches its extreme at one pose does so for a few moving frames; a
    stop holds it there over a range of poses. ±inf where there is none. The moving frames
    depend on the trial alone and are found once per trial (cached)."""
    if "moving_fast" not in trial.cache:
        speed = np.linalg.norm(np.gradient(low_pass(trial.angles, 0.05, trial.rate_hz),
                                           axis=0), axis=1) * trial.rate_hz
        trial.cache["moving_fast"] = trial.valid & (speed > 10.0)
    moving = trial.cache["moving_fast"]
    y = trial.y[:, j]
    band = 6.0 * trial.noise[j]  # the extreme sample sits ~3.5 σ beyond a plateau's level
    lo_level, hi_level = np.min(y[trial.valid]), np.max(y[trial.valid])
    near_lo, near_hi = moving & (y <= lo_level + band), moving & (y >= hi_level - band)
    share = max(int(moving.sum()), 1)
    lo = float(np.median(y[near_lo])) if near_lo.sum() >= PLATEAU_SHARE * share else -np.inf
    hi = float(np.median(y[near_hi])) if near_hi.sum() >= PLATEAU_SHARE * share else np.inf
    return lo, hi



def off_hard_stops(y: np.ndarray, stops: Stops, sigma: float) -> np.ndarray:
    """(N,) frames a fit with ``stops`` starts from: all but those on or within 3 σ of noise
    of a hard stop (a reading on the plateau gives the map no value, only a bound); a soft
    knee's frames are fitted through it."""
    lo = stops.lo + 3.0 * sigma if stops.soft_lo == 0 else -math.inf
    hi = stops.hi - 3.0 * sigma if stops.soft_hi == 0 else math.inf
    return (y > lo) & (y < hi)



def fit_through_stops(red: Reduced, ok: np.ndarray, ridge: Ridge, stops: Stops,
                      coefs: np.ndarray, shared: int = SHARED_ITERATIONS,
                      own: int = OWN_ITERATIONS, censored: np.ndarray | None = None
                      ) -> np.ndarray:
    """Refit every fold through its stops by Gauss–Newton from ``coefs`` (N_BLOCKS + 1, P).

    Linearised at the current prediction ŝ, the stop's output is h(ŝ) + h′(ŝ)·X(β − β₀): a
    ridge solve with the rows weighted by the slope h′ (1 between the stops, → 0 deep in a
    soft stop). Unlike a fit on the frames between the stops, the map is fitted on the
    frames in the knees too, where it would otherwise be extrapolated.

    ``censored`` (M,): the rows whose reading sits on a hard stop's plateau, where the
    reading bounds the map's value instead of giving it. Beyond a hard stop, where h′ is 0
    and the rows would leave the map free, each row is fitted with weight 1 instead: a
    censored row to ŝ itself (it agrees with the stop there, as an expectation-maximisation
    step of a censored regression takes it), any other to its reading (it is off the
    plateau, so the map is not beyond the stop there). A censored row the map passes the
    stop at is fitted to its reading, which pulls the map back to the stop.

    The first ``shared`` iterations linearise every fold at the all-block fit's prediction
    (one Gram matrix per block, as in :func:`~.folds.fold_coefs`); the last ``own``
    linearise each fold at its own prediction, so that no fold's fit depends on its held-out
    block. Every shared iteration but the last needs only the all-block fit (the next is
    linearised at it).
    """
    def linearised(coef: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each row's weight h′(ŝ) and target y − h(ŝ) + h′(ŝ)·ŝ, at ŝ = x·coef (beyond a
        hard stop given ``censored``, 1 and ŝ or y)."""
        pred = red.times(coef)
        slope = stops.slope(pred)
        target = red.yd - stops.apply(pred) + slope * pred
        if censored is not None:
            beyond = stops.beyond_hard(pred)
            slope[beyond] = 1.0
            target[beyond] = np.where(censored[beyond], pred[beyond], red.yd[beyond])
        return slope, target

    full = coefs[-1]
    for _ in range(shared - 1):
        full = fold_coefs(red, ok, ridge, *linearised(full), folds=False)[-1]
    coefs = fold_coefs(red, ok, ridge, *linearised(full)) if shared else coefs.copy()
    for _ in range(own):
        grams = np.empty(coefs.shape + coefs.shape[1:])
        rhs = np.empty(coefs.shape)
        for b in range(N_BLOCKS + 1):  # every block for the last row
            grams[b], rhs[b] = fold_system(red, ok, *linearised(coefs[b]), without=b)
        # the effect columns' ridge from the all-block fit's system (the last row's)
        coefs = ridge_solve(grams, rhs, ridge.loading(grams, ridge.effect_loading(grams[-1])))
    return coefs



def choose_stops(trial: Trial, y: np.ndarray, ridge: Ridge, j: int, red: Reduced,
                 plain: np.ndarray) -> Stops:
    """Sensor j's stops, chosen on the held-out blocks.

    Each end's stop is one of: none, the plateau the sensor sits on while the joint moves (a
    hard stop, :func:`plateaus`), or a soft knee at one of the ``KNEE_SHARES`` quantiles of
    the reading with one of the ``KNEE_SOFTNESS`` softnesses: a tanh knee, then at the best
    quantile and its neighbours the other ``KNEE_BENDS`` shapes, then halfway from the best
    of them to its neighbours with its shape. A compressive end of range without a plateau
    is thus told from a hard stop by the data, not assumed. Each option is scored with the
    map fitted through it (:func:`fold_fits`, without the iteration at each fold's own
    prediction). Each end's knee is searched with the other
    end as found without knees; the better end is kept and the other end's knee searched
    again given it.
    """
    sigma = float(trial.noise[j])
    seen = y[trial.valid]
    extremes = float(np.min(seen)), float(np.max(seen))
    best: tuple[float, Stops] | None = None
    # options are compared on the averaged groups (as the fits see them) of scored frames
    bounds = red.rows.bounds
    blocks = [slice(bounds[b], bounds[b + 1]) for b in range(N_BLOCKS)]
    scored = red.rows.usable(trial.scored)[bounds[0]:]
    measured = red.yd[bounds[0]:][scored]

    def heldout_mse(coefs: np.ndarray, stops: Stops) -> float:
        held = np.concatenate([red.times(coefs[b], rows) for b, rows in enumerate(blocks)])
        return float(np.mean((measured - stops.apply(held[scored])) ** 2))

    def consider(options: list[Stops]) -> tuple[float, Stops]:
        """Score every option, the map fitted through it with the shared iterations alone
        (:func:`fold_fits`); the best score and its option."""
        nonlocal best
        scores = [heldout_mse(fold_fits(trial, y, ridge, stop, sigma, red, plain, own=0),
                              stop) for stop in options]
        k = int(np.argmin(scores))
        if best is None or scores[k] < best[0]:
            best = (scores[k], options[k])
        return scores[k], options[k]

    def side(end: int, other: Stops) -> None:
        """Knees at the lower (0) or upper (1) end, the other end as in ``other``: the
        ``KNEE_SHARES`` grid with the first of the ``KNEE_BENDS``; then, if a knee beat
        ``other`` with no stop at this end, the other shapes at the best share and its
        neighbours, and the shares halfway (geometrically) from the best to its neighbours
        with the best knee's shape.

        A knee is shaped wherever it beats no stop at this end, not only where it beats a
        plateau ``other`` has there: the first shape can be far from a knee's (a bend
        that starts at once, fitted with a tanh knee, left 4 times the mean square of an
        exponential one on saturation/other/m1/s100's second sensor, 60 s), so a plateau
        that beats the first shape's knees may lose to another shape's. Where the plateau
        beats them, the other shapes are tried at the best share first, and the knee is
        shaped further only where one beats the plateau: shaping every such end cost 13–16 %
        more time on the fixture (in one process), and the plateau mostly wins."""
        knee: tuple[float, Stops | None] = (math.inf, None)  # the best knee at this end

        def at(share: float, shapes: Iterable[str]) -> float:
            nonlocal knee
            level = float(np.quantile(seen, share if end == 0 else 1.0 - share))
            reach = abs(level - extremes[end])
            if reach <= 3.0 * sigma:
                return math.inf
            knees = [(f * reach, shape) for shape in shapes for f in KNEE_SOFTNESS]
            # only this end changes: the other keeps its level, softness and shape as found
            found = consider([replace(other, lo=level, soft_lo=soft, shape_lo=shape)
                              if end == 0 else
                              replace(other, hi=level, soft_hi=soft, shape_hi=shape)
                              for soft, shape in knees])
            knee = min(knee, found, key=lambda item: item[0])
            return found[0]

        free = (replace(other, lo=-math.inf, soft_lo=0.0) if end == 0 else
                replace(other, hi=math.inf, soft_hi=0.0))  # no stop at this end
        assert best is not None
        without = best[0] if free == other else consider([free])[0]
        beaten = best[0]  # the best so far: below ``without`` where a plateau here beats it
        grid = list(KNEE_SHARES)
        first, *others = KNEE_BENDS
        scores = [at(share, [first]) for share in grid]
        k = int(np.argmin(scores))
        if scores[k] >= without:  # no knee helps here
            return
        # a knee helps here: shape it, then place it better; another shape may prefer a
        # neighbouring level (an exponential bend starts at once, so its knee sits nearer
        # the extreme than a tanh's)
        near = [n for n in (k - 1, k, k + 1) if 0 <= n < len(grid)]
        shaped: set[int] = set()  # the levels whose other shapes are tried
        if scores[k] >= beaten:  # a plateau here beats the first shape's knees: shaped
            # further only where another shape beats it at the best level
            scores[k] = min(scores[k], at(grid[k], others))
            if scores[k] >= beaten:
                return
            shaped.add(k)
        for n in near:
            if n not in shaped:
                scores[n] = min(scores[n], at(grid[n], others))
        k = min(near, key=lambda n: scores[n])
        assert knee[1] is not None
        shape = knee[1].shape_lo if end == 0 else knee[1].shape_hi
        for n in (k - 1, k + 1):
            if 0 <= n < len(grid):
                at(math.sqrt(grid[k] * grid[n]), [shape])

    consider([NO_STOPS])
    consider([Stops(*plateaus(trial, j))])
    assert best is not None
    start = best
    firsts = []
    for end in (0, 1):
        best = start
        side(end, start[1])
        firsts.append(best)
    best = min(firsts, key=lambda item: item[0])
    if best is not start:  # the other end, given the better one's knee
        side(1 - firsts.index(best), best[1])
    return best[1]



def fit_with_stops(trial: Trial, y: np.ndarray, ridge: Ridge, stops: Stops, sigma: float,
                   red: Reduced, plain: np.ndarray) -> np.ndarray:
    """:func:`~.folds.fit_coefs`'s fold coefficients for a sensor with ``stops``
    (:func:`fold_fits`)."""
    return fold_fits(trial, y, ridge, stops, sigma, red, plain, OWN_ITERATIONS)


def fold_fits(trial: Trial, y: np.ndarray, ridge: Ridge, stops: Stops, sigma: float,
              red: Reduced, plain: np.ndarray, own: int) -> np.ndarray:
    """A sensor's fold coefficients (N_BLOCKS + 1, P) with ``stops`` (``y``: its readings;
    ``plain``: its fold fits without stops; ``sigma``: its noise).

    With soft knees only, the map is fitted through them (:func:`fit_through_stops`) from
    ``plain``, ``own`` iterations at each fold's own prediction after the shared ones. With
    a hard stop, it is fitted off the plateau first (:func:`off_hard_stops`; ``plain`` is
    pulled toward the plateau, where a fit off it extrapolates), then through the stops on
    every valid frame, the plateau's rows censored, with the iterations of a soft knee.
    Fitted off the plateau alone, a fold is free over the poses where the reading sits on
    it: extrapolated there, it left one held-out block 7.7 mm RMS where the noise is 0.15
    (the sensor 2.6 mm; a hard stop of the hidden-effect sweep, saturation/lib/m1/s1003)."""
    if not stops.hard:
        if not stops.soft:
            return plain
        ok = red.rows.usable(trial.valid & off_hard_stops(y, stops, sigma))
        return fit_through_stops(red, ok, ridge, stops, plain, own=own)
    off_plateau = off_hard_stops(y, stops, sigma)
    off = fold_coefs(red, red.rows.usable(trial.valid & off_plateau), ridge)
    return fit_through_stops(red, red.rows.usable(trial.valid), ridge, stops, off, own=own,
                             censored=~red.rows.usable(off_plateau))
