"""Bounded-memory streaming statistics for long runs: a log-spaced histogram.

A run may last hours (500 robot physics steps per second, 250 pipeline frames per second), so
per-sample lists are out: the robots' step times and tracking errors and the pipeline's
per-stage latencies are kept as histograms. A :class:`LogHistogram` keeps a fixed number of
counters; its quantiles are exact to one bin
(relative width ``10 ** (1 / bins_per_decade)``; 1.2 % at the default 200 per decade), and
its count, mean and maximum are exact. Units are whatever the caller adds (degrees, ms).
"""

from __future__ import annotations

import math

import numpy as np


class LogHistogram:
    """Counts of non-negative values in log-spaced bins from ``low`` to ``high``.

    Values below ``low`` (including 0) count in the first bin, values from ``high`` up in the
    last (whose quantile reads as the maximum); :meth:`quantile` never exceeds the maximum.
    """

    def __init__(self, low: float, high: float, bins_per_decade: int = 200) -> None:
        if not (0.0 < low < high) or not math.isfinite(high):
            raise ValueError(f"need 0 < low < high < inf, got low={low!r}, high={high!r}")
        if bins_per_decade < 1:
            raise ValueError(f"bins_per_decade must be >= 1, got {bins_per_decade!r}")
        self._log_low = math.log10(low)
        self._scale = float(bins_per_decade)
        n = int(math.ceil((math.log10(high) - self._log_low) * self._scale)) + 2
        self._counts = np.zeros(n, dtype=np.int64)
        self.count = 0
        self.total = 0.0
        self.max = -math.inf

    def add(self, value: float) -> None:
        """Add one sample; negative or non-finite values raise ValueError."""
        if not value >= 0.0 or not math.isfinite(value):
            raise ValueError(f"histogram samples must be finite and >= 0, got {value!r}")
        index = 0
        if value > 0.0:
            index = int((math.log10(value) - self._log_low) * self._scale) + 1
            index = min(max(index, 0), len(self._counts) - 1)
        self._counts[index] += 1
        self.count += 1
        self.total += value
        if value > self.max:
            self.max = value

    def add_many(self, values: np.ndarray) -> None:
        """Add every value of ``values`` (any shape), binned as :meth:`add` bins them (a value
        within rounding of a bin edge may land in the neighbouring bin; the sum, hence the
        mean, may differ in the last bits). Negative or non-finite values raise ValueError and
        add nothing."""
        v = np.asarray(values, dtype=np.float64).ravel()
        if v.size == 0:
            return
        if not np.all(np.isfinite(v)) or np.any(v < 0.0):
            raise ValueError("histogram samples must be finite and >= 0")
        index = np.zeros(v.size, dtype=np.int64)
        positive = v > 0.0
        # truncation toward zero, as int() in add()
        index[positive] = ((np.log10(v[positive]) - self._log_low) * self._scale).astype(
            np.int64) + 1
        np.clip(index, 0, len(self._counts) - 1, out=index)
        self._counts += np.bincount(index, minlength=len(self._counts))
        self.count += int(v.size)
        self.total += float(v.sum())
        self.max = max(self.max, float(v.max()))

    def merge(self, other: LogHistogram) -> None:
        """Add ``other``'s counts (a histogram with the same range and bins; ValueError if
        not)."""
        if (other._log_low, other._scale, len(other._counts)) != (
                self._log_low, self._scale, len(self._counts)):
            raise ValueError("can only merge histograms with the same range and bins")
        self._counts += other._counts
        self.count += other.count
        self.total += other.total
        self.max = max(self.max, other.max)

    def copy(self) -> LogHistogram:
        """An independent histogram with the same counts."""
        out = LogHistogram.__new__(LogHistogram)
        out._log_low, out._scale = self._log_low, self._scale
        out._counts = self._counts.copy()
        out.count, out.total, out.max = self.count, self.total, self.max
        return out

    @property
    def nbytes(self) -> int:
        """Bytes of its counters (fixed at construction)."""
        return int(self._counts.nbytes)

    def quantile(self, q: float) -> float | None:
        """Upper edge of the bin holding the ``q``-quantile (0 ≤ q ≤ 1), at most the maximum;
        None when empty."""
        if not 0.0 <= q <= 1.0:
            raise ValueError(f"q must be within [0, 1], got {q!r}")
        if self.count == 0:
            return None
        rank = max(1, math.ceil(q * self.count))
        index = int(np.searchsorted(np.cumsum(self._counts), rank))
        if index == len(self._counts) - 1:  # the overflow bin: only the maximum is known
            return self.max
        return min(10.0 ** (self._log_low + index / self._scale), self.max)

    def bins(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The non-empty bins: (lower edges, upper edges, counts); the first bin's lower edge
        is 0 and the last bin's upper edge the maximum."""
        index = np.flatnonzero(self._counts)
        upper = 10.0 ** (self._log_low + index / self._scale)
        lower = np.where(index > 0, 10.0 ** (self._log_low + (index - 1) / self._scale), 0.0)
        last = index == len(self._counts) - 1
        upper[last] = self.max
        return lower, upper, self._counts[index].copy()

    def summary(self, digits: int = 4) -> dict[str, float | int | None]:
        """JSON-able ``{"count", "p50", "p99", "max", "mean"}``, rounded; None when empty."""
        def r(v: float | None) -> float | None:
            return None if v is None else round(v, digits)
        empty = self.count == 0
        return {"count": self.count, "p50": r(self.quantile(0.5)), "p99": r(self.quantile(0.99)),
                "max": None if empty else r(self.max),
                "mean": None if empty else r(self.total / self.count)}
