"""Offset jumps while the joint holds still: the physical signature of a stepping drift.

A loose connector, a contact that opens and closes, or a tendon slipping one notch in its
clamp shifts a reading's offset at an instant, whatever the arm does, and the new level
holds. While the joint holds still the static map's prediction holds too, and none of the
other effects moves a reading at an instant there: a lag has settled within a fraction of
a second, a creep relaxes smoothly over seconds, a loop and a stop only change with the
pose. A reading that steps while the pose holds is an offset that moved.

Such a drift is hard to name on the held-out blocks alone: it shifts the blocks after each
jump and leaves the others, so it may improve too few folds to pass rule 2's sign test
(:mod:`~.rules`), which asks a physical effect to act wherever the motion shows it.
:func:`jumps_in_holds` finds the jumps; the workflow takes one as that evidence instead.

The search reads a sensor's residual (measurement less the model's full-data prediction,
sensor units; one set of coefficients, so no fold's block edge makes a step) averaged over
``JUMP_BIN_S`` bins: at each bin the median of the ``JUMP_WINDOW_S`` after it less the
median of the window before. A jump is where that difference

1. is taken with the joint still over twice the window on each side (all the frames of
   those bins valid and still),
2. exceeds ``JUMP_SIGMAS`` robust standard deviations of the same difference over every
   such still instant of the sensor (what noise, coloured or not, makes of it there),
3. is sharp: ``JUMP_SHARPNESS`` times the difference one window before and one after (a
   relaxation differs about as much one window on; a step only at its instant),
4. and exceeds the sensor's noise floor (smaller shifts matter to no one).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from exohil.emulators.discrepancy.data import Trial

#: Bins the residual is averaged over, s.
JUMP_BIN_S = 0.05
#: Each side's window of the level difference, s.
JUMP_WINDOW_S = 0.5
#: A jump's level difference in robust standard deviations (1.4826 × the median absolute
#: deviation) of the difference over the sensor's still instants. Over a minute of holds a
#: sensor's difference takes about sixty independent values; a Gaussian one passes eight
#: deviations once in 10¹⁵.
JUMP_SIGMAS = 8.0
#: How many times larger than the difference one window before and one window after it a
#: jump's difference is.
JUMP_SHARPNESS = 3.0
#: Fewest still instants (in windows) the spread of the difference is measured over.
MIN_STILL_WINDOWS = 4


@dataclass(frozen=True)
class Jump:
    """An offset jump of one sensor while the joint held still.

    Attributes:
        sensor: the sensor's column.
        at_s: when, s on the recording's clock (the bin where the new level starts).
        height: the level after less the level before, sensor units.
        z: ``height`` in robust standard deviations of the level difference over the
            sensor's still instants.
    """

    sensor: int
    at_s: float
    height: float
    z: float


def jumps_in_holds(trial: Trial, residual: np.ndarray, still: np.ndarray) -> list[Jump]:
    """Every offset jump of every sensor while the joint holds still, in time order.

    Args:
        trial: the trial (its times, rate, valid frames and noise floors).
        residual: (N, S) measurement less a full-data prediction, sensor units.
        still: (N,) bool, the joint holds still (:func:`~.model.holding_still`).
    """
    per_bin = max(1, int(round(JUMP_BIN_S * trial.rate_hz)))
    window = max(2, int(round(JUMP_WINDOW_S * trial.rate_hz / per_bin)))
    n = trial.n // per_bin
    if n < 4 * window:
        return []
    steady = (trial.valid & still)[:n * per_bin].reshape(n, per_bin).all(axis=1)
    # at bin k: the 2·window bins before k and after it are steady
    run = sliding_window_view(steady, 4 * window).all(axis=1)
    eligible = np.zeros(n, dtype=bool)
    eligible[2 * window:n - 2 * window + 1] = run
    if eligible.sum() < MIN_STILL_WINDOWS * window:
        return []
    found = []
    for j in range(residual.shape[1]):
        r = residual[:n * per_bin, j].reshape(n, per_bin).mean(axis=1)
        diff = _level_difference(r, window)
        spread = 1.4826 * float(np.median(np.abs(diff[eligible] - np.median(diff[eligible]))))
        if not spread > 0:
            continue
        z = np.where(eligible, np.abs(diff) / spread, 0.0)
        for k in np.flatnonzero(z > JUMP_SIGMAS):
            neighbours = np.abs(diff[[k - window, k + window]])  # eligible: both exist
            sharp = abs(diff[k]) >= JUMP_SHARPNESS * np.max(neighbours)
            # the extreme of its neighbourhood, the first of equals
            extreme = z[k] > np.max(z[k - window:k]) and z[k] >= np.max(z[k + 1:k + window + 1])
            if sharp and extreme and abs(diff[k]) > trial.noise[j]:
                found.append(Jump(sensor=j, at_s=float(trial.t[k * per_bin]),
                                  height=float(diff[k]), z=float(z[k])))
    return sorted(found, key=lambda jump: (jump.at_s, jump.sensor))


def _level_difference(bins: np.ndarray, window: int) -> np.ndarray:
    """(n,) at bin k: the median of bins k … k + window − 1 less that of bins k − window …
    k − 1; NaN where either side is cut by an end or holds a NaN."""
    n = bins.size
    with warnings.catch_warnings():  # NaN where a side holds a NaN: never eligible
        warnings.simplefilter("ignore", RuntimeWarning)
        level = np.median(sliding_window_view(bins, window), axis=1)  # row i: bins i…
    diff = np.full(n, np.nan)
    diff[window:n - window + 1] = level[window:] - level[:n - 2 * window + 1]
    return diff
