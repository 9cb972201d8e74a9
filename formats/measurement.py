"""Measurements with units, limits and verdicts, in the spirit of OpenHTF.

One type carries every figure exohil reports: the demo summary, the benchmarks and the
conformance checks. A :class:`Measurement` is a name, a value in a named unit, an optional
:class:`Limit` and the verdict that follows from them. It serialises to JSON
(:meth:`Measurement.to_dict`) and to JUnit properties (:meth:`Measurement.junit_properties`).

Units come from a closed vocabulary (:data:`UNITS`): a limit may be stated in another unit of
the same quantity (a latency limit in ms for a value in µs) and is converted; an unknown unit
or a unit of another quantity is a ValueError.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np

#: unit → (quantity, factor to the quantity's base unit).
UNITS: dict[str, tuple[str, float]] = {
    "deg": ("angle", 1.0),
    "rad": ("angle", 180.0 / math.pi),
    "s": ("time", 1.0),
    "ms": ("time", 1e-3),
    "us": ("time", 1e-6),
    "ns": ("time", 1e-9),
    "mm": ("length", 1.0),
    "Hz": ("frequency", 1.0),
    "count": ("count", 1.0),
    "B": ("memory", 1.0),
    "KiB": ("memory", 1024.0),
    "MiB": ("memory", 1024.0**2),
    "ratio": ("ratio", 1.0),
    "%": ("ratio", 0.01),
    "x": ("factor", 1.0),
}


def check_unit(unit: str) -> str:
    """``unit`` itself; ValueError naming the allowed units when it is not one of them."""
    if unit not in UNITS:
        raise ValueError(f"unknown unit {unit!r}; allowed: {', '.join(UNITS)}")
    return unit


def convert(value: float, unit: str, to: str) -> float:
    """``value`` in ``unit`` expressed in ``to`` (same quantity; ValueError otherwise)."""
    (q_from, f_from), (q_to, f_to) = UNITS[check_unit(unit)], UNITS[check_unit(to)]
    if q_from != q_to:
        raise ValueError(f"cannot compare {unit!r} ({q_from}) with {to!r} ({q_to})")
    return value * f_from / f_to


class Verdict(StrEnum):
    """The outcome of one measurement."""

    PASS = "pass"
    FAIL = "fail"
    SKIP = "skip"  #: not measured (no reference, feature absent); never counts as passed
    INFO = "info"  #: measured, no limit


@dataclass(frozen=True)
class Limit:
    """Bounds on a value, in ``unit``: ``low <= value`` and ``value < high`` (``high`` is
    exclusive unless ``inclusive``); either bound may be None."""

    low: float | None = None
    high: float | None = None
    unit: str = "count"
    inclusive: bool = False

    def __post_init__(self) -> None:
        check_unit(self.unit)
        if self.low is None and self.high is None:
            raise ValueError("a limit needs a low or a high bound")
        for bound in (self.low, self.high):
            if bound is not None and math.isnan(bound):
                raise ValueError("a limit's bound must be a number, not NaN (it would pass "
                                 "every value)")
        if self.low is not None and self.high is not None and self.low > self.high:
            raise ValueError(f"a limit's low bound {self.low:g} is above its high bound "
                             f"{self.high:g}: no value could pass")

    def holds(self, value: float, unit: str) -> bool:
        """Whether ``value`` (in ``unit``) is within the limit; NaN never is."""
        v = convert(value, unit, self.unit)
        if math.isnan(v):
            return False
        if self.low is not None and v < self.low:
            return False
        if self.high is not None and (v > self.high if self.inclusive else v >= self.high):
            return False
        return True

    def describe(self) -> str:
        """``< 3 deg``, ``>= 0.99 ratio``, ``0 .. 5 ms``."""
        hi = "<=" if self.inclusive else "<"
        if self.low is None:
            return f"{hi} {self.high:g} {self.unit}"
        if self.high is None:
            return f">= {self.low:g} {self.unit}"
        return f"{self.low:g} .. {self.high:g} {self.unit}"

    def to_dict(self) -> dict[str, Any]:
        return {"low": self.low, "high": self.high, "unit": self.unit,
                "inclusive": self.inclusive}


@dataclass(frozen=True)
class Measurement:
    """One named figure (see module doc).

    Attributes:
        name: dotted name, e.g. ``accuracy.rmse.shoulder_elv``.
        value: the figure in ``unit`` (NaN when it could not be computed).
        unit: one of :data:`UNITS`.
        limit: the bound it must meet, or None (verdict ``info``).
        verdict: pass / fail / skip / info.
        note: why it was skipped, or what it covers (frames, conditions).
    """

    name: str
    value: float
    unit: str
    limit: Limit | None = None
    verdict: Verdict = Verdict.INFO
    note: str = ""

    @classmethod
    def judge(cls, name: str, value: float, unit: str, limit: Limit | None = None,
              note: str = "") -> Measurement:
        """A measurement whose verdict follows from ``limit`` (info without one)."""
        check_unit(unit)
        value = float(value)
        if limit is None:
            verdict = Verdict.INFO
        else:
            verdict = Verdict.PASS if limit.holds(value, unit) else Verdict.FAIL
        return cls(name, value, unit, limit, verdict, note)

    @classmethod
    def skipped(cls, name: str, unit: str, why: str, limit: Limit | None = None) -> Measurement:
        """A measurement that could not be taken; ``why`` says so."""
        return cls(name, math.nan, check_unit(unit), limit, Verdict.SKIP, why)

    @property
    def failed(self) -> bool:
        return self.verdict is Verdict.FAIL

    def describe(self, with_note: bool = True) -> str:
        """One line: ``name = value unit (limit) VERDICT; note`` (without the note when
        ``with_note`` is False)."""
        value = "—" if math.isnan(self.value) else _figure(self.value)
        limit = f" (limit {self.limit.describe()})" if self.limit else ""
        note = f"; {self.note}" if self.note and with_note else ""
        return f"{self.name} = {value} {self.unit}{limit} {self.verdict.value.upper()}{note}"

    def to_dict(self) -> dict[str, Any]:
        """JSON-able; NaN becomes None (JSON has no NaN)."""
        return {
            "name": self.name,
            "value": None if math.isnan(self.value) else self.value,
            "unit": self.unit,
            "limit": None if self.limit is None else self.limit.to_dict(),
            "verdict": self.verdict.value,
            "note": self.note,
        }

    def junit_properties(self) -> list[tuple[str, str]]:
        """``(name, value)`` pairs for a JUnit ``<properties>`` block."""
        props = [(f"{self.name}[{self.unit}]", "nan" if math.isnan(self.value)
                  else f"{self.value:.6g}"), (f"{self.name}.verdict", self.verdict.value)]
        if self.limit is not None:
            props.append((f"{self.name}.limit", self.limit.describe()))
        return props


#: the three figures of a distribution of per-frame samples
DISTRIBUTION_STATS = ("p50", "p99", "max")


def distribution(name: str, samples: Iterable[float] | np.ndarray, unit: str,
                 limits: Mapping[str, Limit] | None = None, note: str = "") -> list[Measurement]:
    """p50, p99 and max of ``samples`` (in ``unit``) as measurements ``name.p50`` etc.;
    ``limits`` maps a statistic name (p50, p99, max) to its limit. NaN samples are left out
    (no sample); an infinite one counts, so a limit on the maximum fails on it. Empty samples
    give skipped measurements."""
    a = np.asarray(list(samples) if not isinstance(samples, np.ndarray) else samples,
                   dtype=np.float64)
    a = a[~np.isnan(a)]
    limits = limits or {}
    unknown = sorted(set(limits) - set(DISTRIBUTION_STATS))
    if unknown:
        raise ValueError(f"limits on {', '.join(unknown)}: a distribution has "
                         f"{', '.join(DISTRIBUTION_STATS)}")
    if a.size == 0:
        return [Measurement.skipped(f"{name}.{stat}", unit, "no samples", limits.get(stat))
                for stat in DISTRIBUTION_STATS]
    if np.isfinite(a).all():
        p50, p99 = np.percentile(a, 50), np.percentile(a, 99)
    else:  # an infinite sample has no interpolation with its neighbour: take the one above
        p50, p99 = np.percentile(a, 50, method="higher"), np.percentile(a, 99, method="higher")
    values = {"p50": float(p50), "p99": float(p99), "max": float(a.max())}
    counted = f"{a.size} samples" + (f"; {note}" if note else "")
    return [Measurement.judge(f"{name}.{stat}", values[stat], unit, limits.get(stat), counted)
            for stat in DISTRIBUTION_STATS]


def _figure(value: float) -> str:
    """``value`` to 4 significant digits, written out where it is of a size a person reads
    that way (10580 ms, not 1.058e+04 ms; 0.0001234), in powers of ten beyond."""
    if value == 0 or not math.isfinite(value) or not 1e-4 <= abs(value) < 1e6:
        return f"{value:.4g}"
    return np.format_float_positional(value, precision=4, unique=False, fractional=False,
                                      trim="-")
