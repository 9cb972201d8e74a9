"""Bounded-memory streaming statistics for long robot runs: a log-spaced histogram.

A run may last hours at 500 physics steps per second, so per-sample lists are out. A
:class:`LogHistogram` keeps a fixed number of counters; its quantiles are exact to one bin
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
