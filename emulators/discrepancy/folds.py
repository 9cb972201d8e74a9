"""Blocked cross-validated ridge fits of one sensor on a design that is linear in its
coefficients.

A design is kept as two blocks (:class:`Design`): the static map's columns, shared by every
sensor, and the sensor's own effect columns. Frames are averaged down to about
``FIT_RATE_HZ`` (:class:`Groups`, :func:`reduce`); each held-out block gets one Gram
matrix, and a fold's system is the total less its block's (:func:`fold_coefs`), solved
with a ridge relative to each column's energy (:class:`Ridge`). :func:`fold_products`
turns the fold coefficients into held-out and full-data predictions.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import lapack

from exohil.emulators.discrepancy.data import N_BLOCKS, Trial

#: Regression rate, Hz: features are computed at the recording's rate and averaged down to
#: about this rate for the least-squares fits (predictions and gaps use the full rate).
FIT_RATE_HZ = 25.0
#: Relative ridge of the static map's columns (columns are scaled to unit norm) when none is
#: chosen: the largest of the static ridges the map tries (``model.STATIC_RIDGES``).
RIDGE = 1e-7
#: Relative ridge of the effect columns: 0.1 % of the energy each adds beyond the static map
#: (:class:`Ridge`), a negligible bias.
EFFECT_RIDGE = 1e-3
#: Row selections whose shared Gram matrices are kept (:class:`SharedGrams`), and whose
#: whole design's are (:attr:`Reduced.whole_grams`): the valid rows, and those off a
#: sensor's hard stops while they are chosen.
KEPT_GRAMS = 4


@dataclass(frozen=True)
class Design:
    """One sensor's design matrix [shared | own], (N, Ps + Pe), kept as its two blocks.

    ``shared`` is the (lagged) static basis, the same array for every sensor and every
    candidate with that lag (cached, never copied); ``own`` holds the sensor's effect
    columns (Pe ≥ 0). Every fit touches each block once at the full rate: joining them
    would copy the whole matrix per sensor per fit.
    """

    shared: np.ndarray
    own: np.ndarray

    @classmethod
    def of(cls, x: np.ndarray) -> Design:
        """A design that is one plain (N, P) matrix."""
        return cls(shared=x, own=x[:, :0])

    def times(self, coefs: np.ndarray) -> np.ndarray:
        """(N, K): the design times each row of ``coefs`` (K, P); (N,) for one (P,)."""
        ps = self.shared.shape[1]
        out = self.shared @ coefs[..., :ps].T
        if self.own.shape[1]:
            out = out + self.own @ coefs[..., ps:].T
        return out


def equilibrate(gram: np.ndarray, loading: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """``gram`` (..., P, P) with the loading (..., P) on its diagonal, its columns scaled
    to unit norm (for conditioning), and the scale (..., P). A column that is zero on every
    fitted frame (a rate limit no move reaches) gets 1 on the diagonal: coefficient 0."""
    diag = np.diagonal(gram, axis1=-2, axis2=-1)
    dead = diag <= 0
    scale = np.sqrt(np.where(dead, 1.0, diag))
    g = gram / (scale[..., :, None] * scale[..., None, :])
    on_diagonal = np.arange(gram.shape[-1])
    g[..., on_diagonal, on_diagonal] += loading / scale**2 + dead
    return g, scale


def spd_solve(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a`` (..., P, P) symmetric positive definite solved for ``b`` (..., P, K): by
    Cholesky (LAPACK ``posv``), half the work of the LU factorisation ``np.linalg.solve``
    does; by LU where a system is not positive definite in floating point."""
    out = np.empty(b.shape)
    for i in np.ndindex(a.shape[:-2]):
        # a symmetric matrix is its own transpose: passed as Fortran-ordered
        _, x, info = lapack.dposv(a[i].T, b[i], lower=1)
        out[i] = x if info == 0 else np.linalg.solve(a[i], b[i])
    return out


def ridge_solve(gram: np.ndarray, rhs: np.ndarray, loading: np.ndarray) -> np.ndarray:
    """Ridge solve with ``loading`` (..., P) added to the Gram matrix's diagonal
    (:func:`equilibrate`); ``gram`` (..., P, P) and ``rhs`` (..., P) may be stacks (one per
    fold)."""
    g, scale = equilibrate(gram, loading)
    return spd_solve(g, (rhs / scale)[..., None])[..., 0] / scale


@dataclass(frozen=True)
class Ridge:
    """Relative ridge of a design whose first ``n_static`` columns are the static map.

    A static column's loading is ``static`` times its energy in the fold. An effect column's
    is ``effect`` times the energy it adds beyond the static map over every block (the
    diagonal of the Schur complement of the static block). A creep column (the low-passed
    static prediction) is nearly the static prediction itself: its energy is mostly offset
    and stretch that the map already carries, and a ridge relative to that energy shrank the
    creep term itself (a held-out gap of 0.51 mm where the term, unshrunk, leaves 0.21 mm).
    Relative to what the column adds, the ridge is the negligible bias it is meant to be, and
    a column that is nearly constant in a fold (a play operator that never reverses there)
    still cannot extrapolate with a huge coefficient.

    The static map's local functions (columns ``local``, a [start, stop) pair) all get
    ``local_ridge`` times their mean energy in the fold.

    With ``free_constant`` the first static column is the constant 1 and gets no loading,
    as ridge regression leaves its intercept: a sensor's zero is arbitrary, and a shrunk
    constant made the map depend on it. Readings centred on zero and the same readings 50
    swings away from it left 0.579 and 0.798 mm after the static map (a hysteresis case of
    the hidden-effect suite); unshrunk, every gap is the same whatever the zero.
    """

    n_static: int
    static: float = RIDGE
    effect: float = EFFECT_RIDGE
    local: tuple[int, int] = (0, 0)
    local_ridge: float = 0.0
    free_constant: bool = False

    def static_loading(self, diag: np.ndarray) -> np.ndarray:
        """(..., n_static) diagonal loading of the static columns from their energies
        ``diag`` (..., n_static)."""
        out = self.static * diag
        start, stop = self.local
        if stop > start:
            out[..., start:stop] = self.local_ridge * diag[..., start:stop].mean(
                axis=-1, keepdims=True)
        if self.free_constant:
            out[..., 0] = 0.0
        return out

    def effect_loading(self, gram_all: np.ndarray) -> np.ndarray:
        """(P − n_static,) diagonal loading of the effect columns, from the design's Gram
        matrix over every block (the same for every fold)."""
        n = self.n_static
        if gram_all.shape[0] == n:
            return np.empty(0)
        diag_all = np.diag(gram_all)
        # equilibrated as every fit is: a static column that is zero on every frame (a stop
        # no reading passes on a dead sensor) gets coefficient 0, not a singular system
        g_ss, scale = equilibrate(gram_all[:n, :n], self.static_loading(diag_all[:n]))
        g_se = gram_all[:n, n:]
        through = spd_solve(g_ss, g_se / scale[:, None]) / scale[:, None]
        return self.added_loading(g_se, diag_all[n:], through)

    def added_loading(self, g_se: np.ndarray, diag_e: np.ndarray, through: np.ndarray
                      ) -> np.ndarray:
        """(Pe,) the effect columns' loading from their products with the static columns
        over every block ``g_se`` (n_static, Pe), their energies ``diag_e`` (Pe,) and
        ``through`` = (G_ss + static loading)⁻¹ g_se: ``effect`` times the energy each adds
        beyond the static map."""
        added = diag_e - np.einsum("ij,ij->j", g_se, through)
        return self.effect * np.maximum(added, 1e-12 * diag_e)

    def loading(self, gram: np.ndarray, effect: np.ndarray) -> np.ndarray:
        """(..., P) diagonal loading for a fold's ``gram`` (..., P, P), or a stack of folds':
        the static columns' from the fold, the effect columns' ``effect``
        (:meth:`effect_loading`)."""
        diag = np.diagonal(gram, axis1=-2, axis2=-1)
        out = np.empty(diag.shape)
        out[..., :self.n_static] = self.static_loading(diag[..., :self.n_static])
        out[..., self.n_static:] = effect
        return out


@dataclass(frozen=True)
class Groups:
    """How a trial's frames are averaged into fit rows, the same for every design.

    Rows average the valid frames of a group of ``m`` consecutive grid frames in one
    held-out block: a group that straddles a block boundary gives one row per block, or
    the fit that predicts a block would hold some of its frames. A row is fit to use
    (``whole``) when at least half of its frames are valid, or, in a recording that holds
    fewer than half of its frames, 90 % of the recording's share of valid frames (else a
    link that drops three of five frames leaves no row). Rows are sorted by block.

    Attributes:
        m: frames per group.
        n: grid frames covered (whole groups; a trailing partial group is dropped).
        weights: (G + K, m) each row's weight on its group's frames, in group order; rows
            G… are the second halves of the K groups ``split`` across a block edge.
        split: (K,) the groups split across a block edge.
        order: (M,) the rows (as in ``weights``) sorted by block.
        group: (M,) the group (grid frames ``group·m … group·m + m − 1``) of each row.
        frames: (M, m) bool, the valid frames of its group each row averages.
        bd: (M,) the held-out block of each row (−1: no valid frame), ascending: each
            block's rows are contiguous.
        whole: (M,) bool, rows fit to use.
    """

    m: int
    n: int
    weights: np.ndarray
    split: np.ndarray
    order: np.ndarray
    group: np.ndarray
    frames: np.ndarray
    bd: np.ndarray
    whole: np.ndarray

    @functools.cached_property
    def bounds(self) -> np.ndarray:
        """(N_BLOCKS + 1,) block b's rows are ``bounds[b]:bounds[b + 1]`` (rows of no
        block, −1, come first)."""
        return np.searchsorted(self.bd, np.arange(N_BLOCKS + 1))

    def mean(self, a: np.ndarray) -> np.ndarray:
        """(M, P) each row's mean of ``a`` (N, P), finite on every valid frame."""
        g = self.n // self.m
        a3 = a[: self.n].reshape(g, self.m, a.shape[1])
        out = np.concatenate([np.einsum("gk,gkp->gp", self.weights[:g], a3),
                              np.einsum("gk,gkp->gp", self.weights[g:], a3[self.split])])
        return out[self.order]

    def usable(self, mask: np.ndarray) -> np.ndarray:
        """(M,) rows fit to use whose averaged frames are all in ``mask`` (N,)."""
        inside = mask[: self.n].reshape(-1, self.m)
        return self.whole & ~np.any(self.frames & ~inside[self.group], axis=1)


@dataclass(frozen=True)
class Reduced:
    """A design and measurement averaged down to about ``FIT_RATE_HZ`` for the fits.

    The design is kept as its two blocks, like :class:`Design`: the shared block's
    average is the same array for every sensor of a fit (joining them copied it per sensor
    per fit).

    Attributes:
        xs: (M, Ps) the shared block of the design, mean of each row's valid frames.
        xe: (M, Pe) the sensor's own columns, the same rows.
        yd: (M,) measurement, same rows.
        rows: how the rows were formed (:class:`Groups`).
        shared_grams: the per-block Gram matrices of ``xs``, by the rows they were formed on
            (:func:`block_grams`); None: every Gram matrix is formed anew.
        whole_grams: the per-block Gram matrices of the whole design [xs | xe], unweighted,
            and their sum, by the rows they were formed on (:func:`block_grams`): a fit
            through a stop weights the rows anew at every Gauss–Newton step, yet only those
            in its knees.
    """

    xs: np.ndarray
    xe: np.ndarray
    yd: np.ndarray
    rows: Groups
    shared_grams: SharedGrams | None = None
    # not an argument: a copy with another design (dataclasses.replace) starts empty
    whole_grams: dict[bytes, tuple[np.ndarray, np.ndarray]] = field(
        default_factory=dict, init=False, repr=False, compare=False)

    @property
    def n_columns(self) -> int:
        """P = Ps + Pe."""
        return self.xs.shape[1] + self.xe.shape[1]

    @functools.cached_property
    def joined(self) -> np.ndarray:
        """(M, P) the design [xs | xe] in one array, for the rows a stop's knee takes out of
        the Gram matrices (:func:`_knee_rows`): gathered at every Gauss–Newton step."""
        return np.hstack([self.xs, self.xe])

    def times(self, coef: np.ndarray, rows: slice = slice(None)) -> np.ndarray:
        """The design's ``rows`` times ``coef`` (P,)."""
        ps = self.xs.shape[1]
        return self.xs[rows] @ coef[:ps] + self.xe[rows] @ coef[ps:]


@dataclass
class SharedGrams:
    """The per-block Gram matrices (N_BLOCKS, Ps, Ps) of the averaged shared block
    (:attr:`Reduced.xs`, ``ps`` columns), kept for the last ``KEPT_GRAMS`` row selections:
    every sensor of a fit asks for the same ones; and for as many row selections and
    static ridges, each fold's static system factored (:meth:`factored`)."""

    ps: int
    by_rows: dict[bytes, np.ndarray] = field(default_factory=dict)
    factors: dict[tuple, StaticFactors | None] = field(default_factory=dict)

    def of(self, xs: np.ndarray, ok: np.ndarray, bounds: np.ndarray) -> np.ndarray:
        """(N_BLOCKS, Ps, Ps) for the rows ``ok`` (M,) of the averaged shared block ``xs``
        (M, Ps), rows sorted by block between ``bounds``."""
        key = ok.tobytes()
        grams = self.by_rows.get(key)
        if grams is None:
            if len(self.by_rows) >= KEPT_GRAMS:
                del self.by_rows[next(iter(self.by_rows))]
            grams = np.empty((N_BLOCKS, self.ps, self.ps))
            for b in range(N_BLOCKS):
                rows = xs[bounds[b]:bounds[b + 1]][ok[bounds[b]:bounds[b + 1]]]
                grams[b] = rows.T @ rows
            self.by_rows[key] = grams
        return grams

    def factored(self, xs: np.ndarray, ok: np.ndarray, bounds: np.ndarray, ridge: Ridge
                 ) -> StaticFactors | None:
        """Each fold's static system for the rows ``ok`` with ``ridge``'s static loading,
        factored; None where one is not positive definite in floating point."""
        key = (ok.tobytes(), ridge.static, ridge.local, ridge.local_ridge)
        if key not in self.factors:
            if len(self.factors) >= KEPT_GRAMS:
                del self.factors[next(iter(self.factors))]
            grams = self.of(xs, ok, bounds)
            folds = fold_sums(grams, grams.sum(axis=0))
            diag = np.diagonal(folds, axis1=-2, axis2=-1)
            g, scale = equilibrate(folds, ridge.static_loading(diag))
            try:
                inverse = triangular_inverse(np.linalg.cholesky(g))
            except np.linalg.LinAlgError:
                self.factors[key] = None
            else:
                self.factors[key] = StaticFactors(scale=scale, inverse_chol=inverse)
        return self.factors[key]


def triangular_inverse(lower: np.ndarray) -> np.ndarray:
    """L⁻¹ of each lower triangular L in ``lower`` (..., P, P), overwritten (LAPACK
    ``trtri``: a third of the work of a general inverse)."""
    for i in np.ndindex(lower.shape[:-2]):
        # Lᵀ is L Fortran-ordered: (Lᵀ)⁻¹ = (L⁻¹)ᵀ is formed in place, without a copy
        inverse, info = lapack.dtrtri(lower[i].T, lower=0, overwrite_c=1)
        if info != 0:  # a zero on the diagonal: not reached from a Cholesky factor
            raise np.linalg.LinAlgError(f"singular triangular factor (trtri info {info})")
        lower[i] = inverse.T  # the same memory, unless LAPACK's wrapper made a copy
    return lower


@dataclass(frozen=True)
class StaticFactors:
    """The static block A = L·Lᵀ of each fold's ridge system (:func:`equilibrate`): its
    scale (N_BLOCKS + 1, Ps) and the inverse of its Cholesky factor L⁻¹ (N_BLOCKS + 1,
    Ps, Ps), the last the all-block fit's. The factor is inverted once
    (:func:`triangular_inverse`) and applied as two products: NumPy has no triangular
    solve, and every sensor and candidate that shares the block applies it again."""

    scale: np.ndarray
    inverse_chol: np.ndarray

    def solve(self, f: int, rhs: np.ndarray) -> np.ndarray:
        """Fold f's equilibrated static system solved for ``rhs`` (Ps, K): L⁻ᵀ(L⁻¹ rhs)."""
        inverse = self.inverse_chol[f]
        return inverse.T @ (inverse @ rhs)


def fold_sums(per_block: np.ndarray, total: np.ndarray) -> np.ndarray:
    """(N_BLOCKS + 1, ...) each fold's sum of ``per_block`` (N_BLOCKS, ...), whose sum over
    the blocks is ``total``: fold b's without block b, the last every block's (``total``)."""
    return np.concatenate([total - per_block, total[None]])


def fit_groups(trial: Trial) -> Groups:
    """The trial's fit rows (see :class:`Groups`), computed once per trial."""
    kept = trial.cache.get("groups")
    if kept is not None:
        return kept
    m = max(1, int(round(trial.rate_hz / FIT_RATE_HZ)))
    n = (trial.n // m) * m
    valid = trial.valid[:n].reshape(-1, m)
    blocks = trial.blocks[:n].reshape(-1, m)
    first = np.where(valid, blocks, N_BLOCKS).min(axis=1)
    last = np.where(valid, blocks, -1).max(axis=1)
    # a block holds ≥ 2.5 s, a group 40 ms: a group meets at most two blocks
    split = np.flatnonzero((first != last) & (last >= 0))
    group = np.concatenate([np.arange(valid.shape[0]), split])
    bd = np.concatenate([np.where(last >= 0, first, -1), last[split]])
    in_block = blocks[group] == bd[:, None]
    frames = valid[group] & in_block
    count = frames.sum(axis=1)
    weights = frames / np.maximum(count, 1)[:, None]  # each row's mean over its valid frames
    order = np.argsort(bd, kind="stable")  # each block's rows contiguous (fold_coefs)
    # at least half its frames; where the recording holds fewer than half of them (a link
    # that drops most frames), 90 % of the recording's share, which a typical group holds
    held = float(trial.valid.mean())
    share = 0.5 if held >= 0.5 else 0.9 * held
    whole = (count > 0) & (count >= share * in_block.sum(axis=1))
    groups = Groups(m=m, n=n, weights=weights, split=split, order=order, group=group[order],
                    frames=frames[order], bd=bd[order], whole=whole[order])
    trial.cache["groups"] = groups
    return groups


def reduce(trial: Trial, x: Design, y: np.ndarray) -> Reduced:
    """The design x (finite on every valid frame) and measurement y (N,), which may be NaN
    where invalid, averaged to about ``FIT_RATE_HZ`` (a trailing partial group is dropped).
    The shared block's average is kept for the next design that shares it."""
    groups = fit_groups(trial)
    kept = trial.cache.get("shared")
    if kept is None or kept[0] is not x.shared:
        kept = (x.shared, groups.mean(x.shared), SharedGrams(ps=x.shared.shape[1]))
        trial.cache["shared"] = kept
    yd = groups.mean(np.where(trial.valid, y, 0.0)[:, None])[:, 0]
    return Reduced(xs=kept[1], xe=groups.mean(x.own), yd=yd, rows=groups,
                   shared_grams=kept[2])


def fit_coefs(trial: Trial, x: Design, y: np.ndarray, ridge: Ridge | None = None,
              ) -> np.ndarray:
    """Blocked CV and full-data fit of one sensor on design x (N, P) and measurement y (N,)
    over the valid frames, with the relative ridge ``ridge`` (default: ``RIDGE`` on every
    column): the (N_BLOCKS + 1, P) fold coefficients (:func:`fold_coefs`), whose held-out
    and full-data predictions :func:`fold_products` forms."""
    red = reduce(trial, x, y)
    ridge = Ridge(n_static=red.n_columns) if ridge is None else ridge
    return fold_coefs(red, red.rows.usable(trial.valid), ridge)


def block_grams(red: Reduced, ok: np.ndarray, weights: np.ndarray | None = None,
                target: np.ndarray | None = None, static: bool = True,
                ) -> tuple[np.ndarray, np.ndarray]:
    """Per-block Gram matrices (N_BLOCKS, P, P) and right-hand sides (N_BLOCKS, P) of the
    rows ``ok`` (M,) of the averaged design, each row times ``weights`` (M,; default 1; at
    most 1: the slopes of a stop), against ``target`` (M,; default the averaged
    measurement). Unweighted, the shared columns' Gram matrices come formed
    (``red.shared_grams``, the same for every sensor of a fit). Every row is read here:
    :func:`fold_coefs` forms a weighted fit's systems with shared columns from the whole
    design's unweighted matrices instead (:func:`_knee_folds`). With ``static`` False
    (unweighted only), the shared columns' block is left unset, for a caller that has it
    factored."""
    y = red.yd if target is None else target
    ps = red.xs.shape[1]
    p = red.n_columns
    grams = np.empty((N_BLOCKS, p, p))
    rhs = np.empty((N_BLOCKS, p))
    bounds = red.rows.bounds
    shared = red.shared_grams if weights is None else None  # the shared block's, formed
    if static and shared is not None:
        grams[:, :ps, :ps] = shared.of(red.xs, ok, bounds)
    for b in range(N_BLOCKS):
        rows = slice(bounds[b], bounds[b + 1])
        xs, xe, yb, keep = red.xs[rows], red.xe[rows], y[rows], ok[rows]
        wb = None if weights is None else weights[rows]
        if not keep.all():  # views where every row counts (no copy)
            xs, xe, yb = xs[keep], xe[keep], yb[keep]
            wb = None if wb is None else wb[keep]
        if static and shared is None:
            xw = xs if wb is None else xs * wb[:, None]
            grams[b, :ps, :ps] = xw.T @ xw
        own = xe if wb is None else xe * (wb**2)[:, None]  # Σ w²·x·xₑᵀ
        yw = yb if wb is None else yb * wb  # Σ w·x·t: the rows times w, not the target
        grams[b, :ps, ps:] = xs.T @ own
        grams[b, ps:, ps:] = xe.T @ own
        grams[b, ps:, :ps] = grams[b, :ps, ps:].T
        rhs[b, :ps] = xs.T @ yw
        rhs[b, ps:] = xe.T @ yw
    return grams, rhs


def _whole_grams(red: Reduced, ok: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The whole design's unweighted per-block Gram matrices (N_BLOCKS, P, P) over the rows
    ``ok`` and their sum (P, P), formed once per row selection (:attr:`Reduced.whole_grams`)."""
    key = ok.tobytes()
    kept = red.whole_grams.get(key)
    if kept is None:
        if len(red.whole_grams) >= KEPT_GRAMS:
            del red.whole_grams[next(iter(red.whole_grams))]
        whole = block_grams(red, ok)[0]
        kept = (whole, whole.sum(axis=0))
        red.whole_grams[key] = kept
    return kept


def _knee_rows(red: Reduced, knee: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(K, P) the design's rows ``knee`` (K,) times √(1 − w²): zᵀz is their share of the
    unweighted Gram matrix that their weights take out."""
    return red.joined[knee] * np.sqrt(1.0 - weights[knee] ** 2)[:, None]


def fold_system(red: Reduced, ok: np.ndarray, weights: np.ndarray, target: np.ndarray,
                without: int) -> tuple[np.ndarray, np.ndarray]:
    """The Gram matrix (P, P) and right-hand side (P,) of :func:`block_grams` summed over
    every block but ``without`` (``N_BLOCKS``: every block), the rows weighted by
    ``weights`` (at most 1) against ``target``. One fold's own system, as the last
    Gauss–Newton step through a stop forms it for each fold (:mod:`.stops`): the unweighted
    total less the left-out block's, less the rows in the knees, at once."""
    if red.shared_grams is None:
        grams, rhs = block_grams(red, ok, weights, target)
        others = np.arange(N_BLOCKS) != without
        return grams[others].sum(axis=0), rhs[others].sum(axis=0)
    whole, total = _whole_grams(red, ok)
    gram = total - whole[without] if without < N_BLOCKS else total.copy()
    rows = ok & (red.rows.bd >= 0) & (red.rows.bd != without)
    tw = np.where(rows, target * weights, 0.0)
    rhs = np.concatenate([red.xs.T @ tw, red.xe.T @ tw])
    knee = np.flatnonzero(rows & (weights != 1.0))
    if knee.size:
        z = _knee_rows(red, knee, weights)
        gram -= z.T @ z
    return gram, rhs


def _knee_corrected(red: Reduced, ok: np.ndarray, weights: np.ndarray, y: np.ndarray
                    ) -> tuple[list[np.ndarray], np.ndarray]:
    """:func:`block_grams` with ``weights`` (at most 1), each block's Gram matrix apart:
    Σ w²·x·xᵀ is the unweighted Gram matrix (formed once for the rows ``ok``,
    :func:`_whole_grams`) less the share 1 − w² of each row whose weight is not 1. A fit
    through a stop (:mod:`.stops`) forms these at every Gauss–Newton step, for every fold,
    with a knee holding a few percent to a third of the rows: the other rows are not touched
    again, and a block without a knee is the kept matrix itself (read only, never copied:
    with a local map each block's is half a megabyte)."""
    whole = _whole_grams(red, ok)[0]
    ps = red.xs.shape[1]
    grams: list[np.ndarray] = list(whole)
    rhs = np.empty((N_BLOCKS, red.n_columns))
    yw = np.where(ok, y * weights, 0.0)  # Σ w·x·t over the rows ok
    bent = ok & (weights != 1.0)
    bounds = red.rows.bounds
    for b in range(N_BLOCKS):
        rows = slice(bounds[b], bounds[b + 1])
        rhs[b, :ps] = red.xs[rows].T @ yw[rows]
        rhs[b, ps:] = red.xe[rows].T @ yw[rows]
        knee = bounds[b] + np.flatnonzero(bent[rows])
        if knee.size:
            z = _knee_rows(red, knee, weights)
            grams[b] = grams[b] - z.T @ z  # zᵀz of one array: a symmetric rank-k update
    return grams, rhs


def _knee_folds(red: Reduced, ok: np.ndarray, weights: np.ndarray, y: np.ndarray,
                folds: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The weighted fit's systems from :func:`_knee_corrected`'s blocks: each fold's Gram
    matrix (N_BLOCKS + 1, P, P; with ``folds`` False only the all-block one, (1, P, P)) and
    right-hand side, and the all-block Gram matrix and right-hand side. The same numbers as
    :func:`fold_sums` of the stacked blocks, without stacking them: the blocks are summed
    in their order (as a sum over the stack's first axis is), and each fold's matrix is
    written once."""
    per_block, rhs = _knee_corrected(red, ok, weights, y)
    gram_all = per_block[0].copy()
    for gram in per_block[1:]:
        gram_all += gram
    rhs_all = rhs.sum(axis=0)
    if not folds:
        return gram_all[None], rhs_all[None], gram_all, rhs_all
    fold_grams = np.empty((N_BLOCKS + 1,) + gram_all.shape)
    for b, gram in enumerate(per_block):
        np.subtract(gram_all, gram, out=fold_grams[b])
    fold_grams[-1] = gram_all
    return fold_grams, fold_sums(rhs, rhs_all), gram_all, rhs_all


def fold_coefs(red: Reduced, ok: np.ndarray, ridge: Ridge, weights: np.ndarray | None = None,
               target: np.ndarray | None = None, folds: bool = True) -> np.ndarray:
    """(N_BLOCKS + 1, P) ridge coefficients: row b fitted without block b, the last row on
    every block (one Gram matrix per block, :func:`block_grams`; a fold's is the total
    minus its block's); with ``folds`` False, only the last row, (1, P). Without weights,
    the shared static block's factors are reused (:func:`_fold_coefs_factored`)."""
    shared = red.shared_grams
    if weights is None and shared is not None and shared.ps == ridge.n_static:
        factors = shared.factored(red.xs, ok, red.rows.bounds, ridge)
        if factors is not None:
            return _fold_coefs_factored(red, ok, ridge, factors, target, folds)
    if weights is not None and shared is not None:
        y = red.yd if target is None else target
        fold_grams, fold_rhs, gram_all, rhs_all = _knee_folds(red, ok, weights, y, folds)
    else:
        grams, rhs = block_grams(red, ok, weights, target)
        gram_all, rhs_all = grams.sum(axis=0), rhs.sum(axis=0)
        # fold b's Gram matrix is the total minus block b's; the last is the total
        fold_grams = fold_sums(grams, gram_all) if folds else gram_all[None]
        fold_rhs = fold_sums(rhs, rhs_all) if folds else rhs_all[None]
    effect = ridge.effect_loading(gram_all)
    return ridge_solve(fold_grams, fold_rhs, ridge.loading(fold_grams, effect))


def _fold_coefs_factored(red: Reduced, ok: np.ndarray, ridge: Ridge, factors: StaticFactors,
                         target: np.ndarray | None, folds: bool = True) -> np.ndarray:
    """:func:`fold_coefs` by block elimination: each fold's static block is factored once
    for every sensor and candidate that shares it (``factors``), so a fit solves only its
    effect columns' Schur complement, of their count, instead of the whole system.

    With the equilibrated system [[A, B], [Bᵀ, C]] [βs; βe] = [rs; re] (A the static
    block): (C − Bᵀ A⁻¹ B) βe = re − Bᵀ A⁻¹ rs, then βs = A⁻¹ (rs − B βe). The effect
    columns' ridge uses the all-block A as :meth:`Ridge.effect_loading` does.
    """
    ps = factors.scale.shape[1]
    grams, rhs = block_grams(red, ok, target=target, static=False)
    cross_all, rhs_all = grams[:, :, ps:].sum(axis=0), rhs.sum(axis=0)
    cross = fold_sums(grams[:, :, ps:], cross_all)  # (N_BLOCKS + 1, P, Pe)
    fold_rhs = fold_sums(rhs, rhs_all)
    n_folds, pe = cross.shape[0], cross.shape[2]
    coefs = np.empty(fold_rhs.shape)
    order = range(n_folds) if folds else [n_folds - 1]
    effect = np.empty(0)
    if pe:  # the effect columns' ridge: the energy each adds beyond the static map
        scale_all = factors.scale[-1][:, None]
        g_se = cross_all[:ps]
        through = factors.solve(-1, g_se / scale_all) / scale_all  # A_all⁻¹ g_se, unscaled
        effect = ridge.added_loading(g_se, np.diagonal(cross_all[ps:]), through)
    for f in order:
        s_s = factors.scale[f]
        r_s = fold_rhs[f, :ps] / s_s
        if not pe:
            coefs[f] = factors.solve(f, r_s[:, None])[:, 0] / s_s
            continue
        c, s_e = equilibrate(cross[f, ps:], effect)
        b = cross[f, :ps] / (s_s[:, None] * s_e[None, :])
        z = factors.solve(f, np.column_stack([b, r_s]))  # A⁻¹ [B | rs]
        schur = c - b.T @ z[:, :pe]
        beta_e = np.linalg.solve(schur, fold_rhs[f, ps:] / s_e - b.T @ z[:, pe])
        coefs[f, :ps] = (z[:, pe] - z[:, :pe] @ beta_e) / s_s
        coefs[f, ps:] = beta_e / s_e
    return coefs if folds else coefs[-1:]


def block_runs(trial: Trial) -> tuple[np.ndarray, np.ndarray]:
    """The trial's runs of consecutive frames held out by one block: (R + 1,) frame bounds
    and (R,) the block of each run."""
    kept = trial.cache.get("block_runs")
    if kept is None:
        bounds = np.concatenate([[0], np.flatnonzero(np.diff(trial.blocks)) + 1, [trial.n]])
        kept = trial.cache["block_runs"] = (bounds, trial.blocks[bounds[:-1]])
    return kept


def fold_products(trial: Trial, designs: Sequence[Design], coefs: Sequence[np.ndarray],
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Each design times its fold coefficients (N_BLOCKS + 1, P): (held, full), each (N, K)
    for K designs: every frame times the row of the fold that held it out, and every frame
    times the last row. A shared block is read once, a run of one held-out block at a time
    (:func:`block_runs`, in place: no sorted copy), in one product for every design that
    shares it (all sensors of one fit) and both rows, formed transposed (coefficients times
    the run's transpose: the faster BLAS product for this narrow a result)."""
    bounds, run_block = block_runs(trial)
    out = np.empty((2, len(designs), trial.n))  # [0]: held, [1]: full
    sharing: dict[int, list[int]] = {}
    for k, x in enumerate(designs):
        sharing.setdefault(id(x.shared), []).append(k)
    for members in sharing.values():
        ps = designs[members[0]].shared.shape[1]
        run_t = designs[members[0]].shared.T  # (Ps, N), a view
        # per block b, (2·members, Ps): the fold without block b, then the full fit, of each
        full = [coefs[k][-1, :ps] for k in members]
        pairs = [np.stack([coefs[k][b, :ps] for k in members] + full) for b in range(N_BLOCKS)]
        for start, stop, b in zip(bounds[:-1], bounds[1:], run_block, strict=True):
            product = (pairs[b] @ run_t[:, start:stop]).reshape(2, len(members), -1)
            if len(members) == len(designs):  # members is 0 … K − 1
                out[:, :, start:stop] = product
            else:
                out[:, members, start:stop] = product
    frames = np.arange(trial.n)
    for k, x in enumerate(designs):
        if x.own.shape[1]:
            own = x.own @ coefs[k][:, x.shared.shape[1]:].T  # (N, N_BLOCKS + 1), narrow
            out[0, k] += own[frames, trial.blocks]
            out[1, k] += own[:, -1]
    return out[0].T, out[1].T


def block_mse(trial: Trial, residual: np.ndarray) -> np.ndarray:
    """(N_BLOCKS,) mean squared held-out ``residual`` (N, any sensors) per block over its
    scored frames (NaN where it is not); NaN for a block with no scored frame."""
    out = np.full(N_BLOCKS, np.nan)
    for b in range(N_BLOCKS):
        r = residual[trial.blocks == b]
        r = r[np.isfinite(r)]
        if r.size:
            out[b] = np.mean(r**2)
    return out
