"""Signal operators of the effect terms, along axis 0 (time) at a fixed frame rate: play
(backlash) operators for hysteresis, a first-order low-pass, a delay and a slew-rate limit
for lag (:func:`apply_lag`)."""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import lfilter, lfilter_zi

#: Magnitude below which a low-passed value is set to zero (:func:`low_pass`): far below
#: any term it is summed with, and above the square root of the smallest normal number, so
#: that products of kept values never turn subnormal.
NEGLIGIBLE = 1e-150


def play(x: np.ndarray, thresholds: np.ndarray) -> np.ndarray:
    """Play (backlash) operators, relaxed at the first sample.

    Args:
        x: (N, S) inputs.
        thresholds: (S, K) half-widths, same units as x.

    Returns:
        (N, S, K) operator outputs.
    """
    n, s = x.shape
    k = thresholds.shape[1]
    lower = x[:, :, None] - thresholds[None]
    upper = x[:, :, None] + thresholds[None]
    out = np.empty((n, s, k))
    out[0] = x[0][:, None]
    for i in range(1, n):
        np.maximum(out[i - 1], lower[i], out=out[i])
        np.minimum(out[i], upper[i], out=out[i])
    return out


def low_pass(x: np.ndarray, tau_s: float, rate_hz: float) -> np.ndarray:
    """First-order low-pass along axis 0 (step-invariant), starting at rest at x[0].

    A column that falls to zero (a local function of step 2 away from its poses) decays
    geometrically behind the filter, and within seconds into subnormal numbers, on which
    x86 arithmetic is tens of times slower: every product of the lagged design (its Gram
    matrices, its predictions) and the filter itself crawled (a seven-tendon map's Gram
    matrix 7.4 s instead of 0.14 s). So the filter runs in stretches over which nothing
    above ``NEGLIGIBLE`` can decay below the smallest normal number, and magnitudes below
    ``NEGLIGIBLE`` are set to zero after each, output and state alike (nothing they are
    summed with notices them; the results are the same), and the product of two that are
    kept is still a normal number.
    """
    if tau_s <= 0:
        return x.copy()
    pole = math.exp(-1.0 / (rate_hz * tau_s))
    b, a = [0.0, 1.0 - pole], [1.0, -pole]
    state = lfilter_zi(b, a)[:, None] * x[0][None, :]
    # frames for a decay from NEGLIGIBLE to the smallest normal number, less a tenth
    stretch = max(1, int(0.9 * math.log(NEGLIGIBLE / np.finfo(float).tiny) / -math.log(pole))
                  if pole > 0.0 else x.shape[0])
    out = np.empty(x.shape)
    for start in range(0, x.shape[0], stretch):
        part, state = lfilter(b, a, x[start:start + stretch], axis=0, zi=state)
        part *= np.abs(part) >= NEGLIGIBLE  # in place: three times faster than indexing
        state *= np.abs(state) >= NEGLIGIBLE
        out[start:start + stretch] = part
    return out


def delay(x: np.ndarray, delay_s: float, rate_hz: float) -> np.ndarray:
    """x delayed by ``delay_s`` (fractional samples by linear interpolation; the ends hold)."""
    samples = delay_s * rate_hz
    k = int(math.floor(samples))
    frac = samples - k

    def shifted(by: int, weight: float) -> np.ndarray:
        """x shifted ``by`` frames (its ends held) times ``weight``, in one pass."""
        out = np.empty_like(x)
        if by >= 0:
            np.multiply(x[:x.shape[0] - by], weight, out=out[by:])
            out[:by] = x[0] * weight
        else:
            np.multiply(x[-by:], weight, out=out[:by])
            out[by:] = x[-1] * weight
        return out

    if frac == 0:
        return shifted(k, 1.0)
    out = shifted(k, 1.0 - frac)  # (1 − frac)·x[i − k] + frac·x[i − k − 1]
    out += shifted(k + 1, frac)
    return out


def rate_limit(x: np.ndarray, rate: float, rate_hz: float) -> np.ndarray:
    """x (N,) through a slew-rate limit: the output follows x but changes by at most
    ``rate`` (units/s) per second, starting at x[0]."""
    step = rate / rate_hz
    out = np.array(x, dtype=float)  # on the target wherever it has kept up
    values = out.tolist()  # floats: a numpy scalar per frame is 10× slower
    # the frames a reading on the target one frame before cannot reach: only from these
    # on does it fall behind, and the loop runs until it has caught up
    behind = np.flatnonzero((out[1:] > out[:-1] + step) | (out[1:] < out[:-1] - step)) + 1
    i, n = 0, len(values)
    while True:
        k = int(np.searchsorted(behind, i))
        if k == len(behind):
            return out
        i = int(behind[k])
        y = values[i - 1]
        while i < n:
            target = values[i]
            if target > y + step:
                y += step
            elif target < y - step:
                y -= step
            else:  # caught up: on the target from here to the next frame out of reach
                i += 1
                break
            out[i] = y
            i += 1


def apply_lag(x: np.ndarray, kind: str, value_s: float, rate_hz: float,
              delay_s: float = 0.0) -> np.ndarray:
    """The lag term applied to the columns of x (N, P): a first-order low-pass of time
    constant ``value_s``, a delay of ``value_s``, or (``first_order_delay``) the low-pass
    followed by a delay of ``delay_s``. A rate limit is not applied column by column (it
    is a column of its own, :func:`~.model.rate_limit_column`): x as it is."""
    if kind == "first_order":
        return low_pass(x, value_s, rate_hz)
    if kind == "delay":
        return delay(x, value_s, rate_hz)
    if kind == "first_order_delay":
        return delay(low_pass(x, value_s, rate_hz), delay_s, rate_hz)
    return x
