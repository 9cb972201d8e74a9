"""The discrepancy workflow takes recordings written the way other tools write them.

Each of six recordings takes three or four changes of the kinds other loggers make
(counters, clocks, bad readings, motion capture in another order, rate or layout; every
change once) to a 30 s hidden-effect recording, round-trips it through a file where our
writer accepts it, and runs the workflow and its outputs. Every run must end in a summary
with its files written, or in a one-line :class:`DiscrepancyError`: never in another
exception. A throwaway version of this probe, 50 recordings, found a recording the model
cannot follow read as clean and figures that depended on the unit (2026-11-29).
"""

from __future__ import annotations

import functools
import json
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from tempfile import TemporaryDirectory

import numpy as np
import pytest

from exohil.emulators.discrepancy import DiscrepancyError, run, write_outputs
from exohil.emulators.discrepancy.hidden import Case, make_recording
from exohil.formats.errors import RecordingError
from exohil.formats.recording import AngleStream, Recording, SensorStream
from exohil.formats.recording_reader import read_recording
from exohil.formats.recording_writer import write_recording


@functools.cache
def _base(kind: str) -> Recording:
    return make_recording(Case(kind, "alt", 2, seed=100, duration_s=30.0))


class _Parts:
    """A recording's arrays, to change in place."""

    def __init__(self, rec: Recording) -> None:
        s, m = rec.sensors, rec.mocap["shoulder"]
        self.seq, self.t, self.v = s.seq.copy(), s.t.copy(), s.values.copy()
        self.mt, self.mnames, self.ma = m.t.copy(), list(m.names), m.angles.copy()
        self.extra: dict[str, AngleStream] = {}
        self.rec = rec

    def build(self) -> Recording:
        mocap = {**self.rec.mocap, **self.extra,
                 "shoulder": AngleStream(t=self.mt, names=tuple(self.mnames), angles=self.ma)}
        return replace(self.rec, sensors=SensorStream(seq=self.seq, t=self.t, values=self.v),
                       mocap=mocap)


def _at(p: _Parts, rng: np.random.Generator, span: int) -> slice:
    start = int(rng.integers(0, len(p.t) - span))
    return slice(start, start + span)


def _swap(p: _Parts, rng: np.random.Generator) -> None:
    i = int(rng.integers(1, len(p.t) - 2))
    for a in (p.seq, p.t, p.v):
        a[[i, i + 1]] = a[[i + 1, i]]


def _duplicate_counter(p: _Parts, rng: np.random.Generator) -> None:
    i = int(rng.integers(1, len(p.t) - 1))
    p.seq[i] = p.seq[i - 1]


def _epoch(p: _Parts, rng: np.random.Generator) -> None:
    p.t += 1.7e9
    p.mt += 1.7e9


def _unsorted(p: _Parts, rng: np.random.Generator) -> None:
    order = rng.permutation(len(p.mt))
    p.mt, p.ma = p.mt[order], p.ma[order]


def _elevation_only(p: _Parts, rng: np.random.Generator) -> None:
    keep = [p.mnames.index("shoulder_elv")]
    p.mnames, p.ma = [p.mnames[k] for k in keep], p.ma[:, keep]


def _plane_0_to_360(p: _Parts, rng: np.random.Generator) -> None:
    if "elv_angle" in p.mnames:
        k = p.mnames.index("elv_angle")
        p.ma[:, k] = np.mod(p.ma[:, k], 360.0)


def _extra_column(p: _Parts, rng: np.random.Generator) -> None:
    p.mnames.append("marker_quality")
    p.ma = np.column_stack([p.ma, rng.random(len(p.mt))])


def _late_start(p: _Parts, rng: np.random.Generator) -> None:
    keep = p.mt > p.mt[0] + 3.0
    p.mt, p.ma = p.mt[keep], p.ma[keep]


def _set(attr: str, value: Callable[[_Parts, np.random.Generator], np.ndarray]
         ) -> Callable[[_Parts, np.random.Generator], None]:
    def change(p: _Parts, rng: np.random.Generator) -> None:
        setattr(p, attr, value(p, rng))
    return change


def _nan_stretch(p: _Parts, rng: np.random.Generator) -> None:
    p.v[_at(p, rng, int(rng.integers(10, 500))), int(rng.integers(0, p.v.shape[1]))] = np.nan


def _inf(p: _Parts, rng: np.random.Generator) -> None:
    p.v[rng.integers(0, len(p.t), 5), int(rng.integers(0, p.v.shape[1]))] = np.inf


def _dead(p: _Parts, rng: np.random.Generator) -> None:
    p.v[:, int(rng.integers(0, p.v.shape[1]))] = 3.0


def _clipped(p: _Parts, rng: np.random.Generator) -> None:
    j = int(rng.integers(0, p.v.shape[1]))
    p.v[:, j] = np.minimum(p.v[:, j], np.percentile(p.v[:, j], 80))


def _mocap_nan(p: _Parts, rng: np.random.Generator) -> None:
    start = int(rng.integers(0, len(p.mt) - 300))
    p.ma[start:start + 200] = np.nan


def _mocap_duplicated(p: _Parts, rng: np.random.Generator) -> None:
    p.mt, p.ma = np.repeat(p.mt, 2), np.repeat(p.ma, 2, axis=0)


def _mocap_30hz(p: _Parts, rng: np.random.Generator) -> None:
    p.mt, p.ma = p.mt[::4], p.ma[::4]


def _extra_joint(p: _Parts, rng: np.random.Generator) -> None:
    p.extra["elbow"] = AngleStream(t=p.mt.copy(), names=("elbow_flexion",),
                                   angles=p.ma[:, :1] * 0.5)


#: what other loggers do, by name
CHANGES: dict[str, Callable[[_Parts, np.random.Generator], None]] = {
    "counter offset by 2**40": _set("seq", lambda p, rng: p.seq + 2**40),
    "millisecond counter": _set("seq", lambda p, rng: np.round(p.t * 1000).astype(np.int64)),
    "a counter repeated": _duplicate_counter,
    "two frames swapped": _swap,
    "2 ms time jitter": _set("t", lambda p, rng: p.t + rng.normal(0.0, 0.002, len(p.t))),
    "Unix-epoch times": _epoch,
    "a NaN stretch": _nan_stretch,
    "inf readings": _inf,
    "a dead sensor": _dead,
    "a clipped sensor": _clipped,
    "1-unit quantisation": _set("v", lambda p, rng: np.round(p.v)),
    "x1e4 + 1e6": _set("v", lambda p, rng: p.v * 1e4 + 1e6),
    "sign flipped": _set("v", lambda p, rng: -p.v),
    "mocap unsorted": _unsorted,
    "mocap duplicated": _mocap_duplicated,
    "mocap NaN stretch": _mocap_nan,
    "mocap at 30 Hz": _mocap_30hz,
    "mocap starts 3 s late": _late_start,
    "mocap extra column": _extra_column,
    "elevation only": _elevation_only,
    "plane of elevation in 0-360": _plane_0_to_360,
    "an elbow joint too": _extra_joint,
}


#: every change once, in six recordings of three or four changes each (a fixed shuffle)
GROUPS = [[str(name) for name in group] for group in np.array_split(
    np.random.default_rng(2026).permutation(sorted(CHANGES)), 6)]


@pytest.mark.parametrize("index", range(len(GROUPS)),
                         ids=["; ".join(group) for group in GROUPS])
def test_any_recording_other_tools_write_ends_in_a_summary_or_a_clear_error(index):
    kind = ("clean", "hysteresis", "creep", "lag")[index % 4]
    changes = GROUPS[index]
    rng = np.random.default_rng(index)
    parts = _Parts(_base(kind))
    for name in changes:
        CHANGES[name](parts, rng)
    rec = parts.build()
    with TemporaryDirectory() as tmp:
        path = Path(tmp) / "other.mcap"
        try:  # our writer refuses some of these (NaN readings, repeated counters)
            write_recording(path, rec)
            rec = read_recording(path)
        except RecordingError:
            pass
        try:
            outcome = run(rec, "other", workers=1)
        except DiscrepancyError as err:
            assert str(err) and "\n" not in str(err), changes
            return
        written = write_outputs(outcome, Path(tmp) / "out", "other", 1)
        assert {p.name for p in written} >= {"discrepancy.json", "report.md"}, changes
        summary = json.loads((Path(tmp) / "out" / "discrepancy.json").read_text())
        assert set(summary["effects"]) <= {"hysteresis", "creep", "saturation", "lag", "drift"}
        assert np.isfinite(summary["gap_before"]) and np.isfinite(summary["gap_after"]), changes
        assert summary["conclusion"], changes
