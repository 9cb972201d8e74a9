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
#: Frames a play operator runs at once in each of its chunks (:func:`play`).
PLAY_CHUNK = 256
#: Frames a low-pass or a delay writes at a time (:func:`low_pass`, :func:`delay`): the
#: chunk and its temporaries stay in cache, and the temporaries are made once. A design of
#: 244 columns over a four-minute recording is 120 MB; made and filled whole, every
#: temporary of that size was fresh memory the kernel had to clear.
FILTER_ROWS = 512


def play(x: np.ndarray, thresholds: np.ndarray) -> np.ndarray:
    """Play (backlash) operators, relaxed at the first sample.

    Each frame clamps the operator's last output into [x − r, x + r]. Clamps compose into
    clamps (the clamp into [a₂, b₂] after the clamp into [a₁, b₁] is the clamp into the
    first interval's ends clamped by the second), so the frames are run a chunk of
    ``PLAY_CHUNK`` at a time, every chunk at once: each chunk's clamps composed, then each
    chunk's first output from the one before, then every output from its chunk's. Only
    minima and maxima are taken, so every output is the frame-by-frame loop's exactly, in a
    few hundred array steps instead of one per frame (0.13 s a call on a four-minute
    recording, a dozen calls before its first effect is named).

    Args:
        x: (N, S) inputs.
        thresholds: (S, K) half-widths, same units as x.

    Returns:
        (N, S, K) operator outputs.
    """
    n, s = x.shape
    k = thresholds.shape[1]
    if n <= 1:
        return np.broadcast_to(x[:, :, None], (n, s, k)).copy()
    chunks = -(-(n - 1) // PLAY_CHUNK)
    out = np.empty((1 + chunks * PLAY_CHUNK, s, k))  # the chunks padded at the end
    out[0] = x[0][:, None]
    # each later frame's clamp, laid out by place in its chunk ([i]: every chunk's frame i,
    # contiguous); the padding's clamps keep every value
    later = np.zeros((chunks * PLAY_CHUNK, s))
    later[:n - 1] = x[1:]
    later = np.ascontiguousarray(later.reshape(chunks, PLAY_CHUNK, s).swapaxes(0, 1))
    lower = later[:, :, :, None] - thresholds
    upper = later[:, :, :, None] + thresholds
    padded = n - 1 - (chunks - 1) * PLAY_CHUNK  # the last chunk's first padding frame
    lower[padded:, -1] = -np.inf
    upper[padded:, -1] = np.inf
    for i in range(1, PLAY_CHUNK):  # the clamps of each chunk's frames 0…i, composed
        np.minimum(np.maximum(lower[i - 1], lower[i]), upper[i], out=lower[i])
        np.minimum(np.maximum(upper[i - 1], lower[i]), upper[i], out=upper[i])
    entry = np.empty((chunks, s, k))  # each chunk's output before its first frame
    entry[0] = out[0]
    for c in range(1, chunks):
        entry[c] = np.minimum(np.maximum(entry[c - 1], lower[-1, c - 1]), upper[-1, c - 1])
    by_chunk = out[1:].reshape(chunks, PLAY_CHUNK, s, k).swapaxes(0, 1)  # a view
    np.minimum(np.maximum(entry, lower, out=lower), upper, out=by_chunk)
    return out[:n]


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
    # FILTER_ROWS frames at a time within a stretch (the filter carried on exactly from
    # its state), masked straight into ``out`` through buffers made once
    magnitude = np.empty((min(FILTER_ROWS, x.shape[0]),) + x.shape[1:])
    kept = np.empty(magnitude.shape, dtype=bool)
    for start in range(0, x.shape[0], stretch):
        stop = min(start + stretch, x.shape[0])
        for first in range(start, stop, FILTER_ROWS):
            last = min(first + FILTER_ROWS, stop)
            part, state = lfilter(b, a, x[first:last], axis=0, zi=state)
            mask = kept[:last - first]
            np.greater_equal(np.abs(part, out=magnitude[:last - first]), NEGLIGIBLE, out=mask)
            np.multiply(part, mask, out=out[first:last])
        state *= np.abs(state) >= NEGLIGIBLE
    return out


def delay(x: np.ndarray, delay_s: float, rate_hz: float) -> np.ndarray:
    """x delayed by ``delay_s`` (fractional samples by linear interpolation; the ends hold)."""
    samples = delay_s * rate_hz
    k = int(math.floor(samples))
    frac = samples - k
    # out[i] = Σ w·x[i − by], the source row held at the ends: (1 − frac)·x[i − k] +
    # frac·x[i − k − 1], or x[i − k] alone
    weights = [(k, 1.0)] if frac == 0 else [(k, 1.0 - frac), (k + 1, frac)]
    n = x.shape[0]
    out = np.empty_like(x)
    # rows whose every source lies inside x: FILTER_ROWS frames at a time, the second
    # product through a buffer made once
    lo, hi = min(max(k + len(weights) - 1, 0), n), min(n, n + k)
    buffer = np.empty((min(FILTER_ROWS, n),) + x.shape[1:])
    for first in range(lo, hi, FILTER_ROWS):
        last = min(first + FILTER_ROWS, hi)
        for m, (by, weight) in enumerate(weights):
            np.multiply(x[first - by:last - by], weight,
                        out=out[first:last] if m == 0 else buffer[:last - first])
        if len(weights) > 1:
            out[first:last] += buffer[:last - first]
    rows = np.arange(n)
    ends = np.concatenate([rows[:lo], rows[max(hi, lo):]])
    held = [x[np.clip(ends - by, 0, n - 1)] * weight for by, weight in weights]
    out[ends] = held[0] if len(held) == 1 else held[0] + held[1]
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
