"""The real-time pipeline: frames from a :class:`FrameSource` → streaming estimator → sinks.

This is the paper's two-thread layout: the acquisition thread (inside the frame source) keeps
reading the device at 250 Hz; this loop, on the calling thread, takes each frame, runs the
estimator on it (window kept inside the engine) and hands the angles to the sinks (teleop,
recorder, ...). Per frame it measures the estimator's compute time and the end-to-end latency
from the host receiving the frame's bytes to the last sink returning (``perf_counter_ns``).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from exohil.harness.frame_source import Frame, FrameSource, LinkStats


class Estimator(Protocol):
    """One call per frame: sensor values (S,) → angles (A,), degrees (e.g. StreamingEstimator)."""

    def push(self, values: np.ndarray) -> np.ndarray: ...


#: A sink receives each frame with its angle estimates (degrees, estimator order).
Sink = Callable[[Frame, np.ndarray], None]


@dataclass
class PipelineRun:
    """What one run produced.

    Attributes:
        seq / device_time_s: (N,) of the frames processed, in order.
        estimates: (N, A) angle estimates, degrees.
        compute_ns: (N,) estimator time per frame, ns.
        latency_ns: (N,) host receive → all sinks done, ns.
        link: the link counters at the end.
        wall_s: duration of the run, s.
    """

    seq: np.ndarray
    device_time_s: np.ndarray
    estimates: np.ndarray
    compute_ns: np.ndarray
    latency_ns: np.ndarray
    link: LinkStats
    wall_s: float

    @property
    def frames(self) -> int:
        return int(self.seq.shape[0])


@dataclass
class _Log:
    seq: list[int] = field(default_factory=list)
    t: list[float] = field(default_factory=list)
    est: list[np.ndarray] = field(default_factory=list)
    compute: list[int] = field(default_factory=list)
    latency: list[int] = field(default_factory=list)


class Pipeline:
    """Drives frames through the estimator into the sinks (see module doc)."""

    def __init__(self, source: FrameSource, estimator: Estimator, sinks: Sequence[Sink] = ()):
        self.source = source
        self.estimator = estimator
        self.sinks = list(sinks)

    def run(
        self,
        duration_s: float | None = None,
        max_frames: int | None = None,
        stop: threading.Event | None = None,
        progress: Callable[[int, LinkStats, np.ndarray | None], None] | None = None,
        progress_every_s: float = 1.0,
        idle_timeout_s: float | None = None,
    ) -> PipelineRun:
        """Process frames until ``duration_s`` (wall clock) or ``max_frames`` or ``stop`` is set,
        or no frame arrived for ``idle_timeout_s``. ``progress(frames, link, last)`` is called
        about every ``progress_every_s``. The frame source must already be started."""
        log = _Log()
        start = time.perf_counter()
        deadline = None if duration_s is None else start + duration_s
        next_progress = start + progress_every_s
        last_frame_at = start
        last: np.ndarray | None = None
        while True:
            now = time.perf_counter()
            if (deadline is not None and now >= deadline) or (stop is not None and stop.is_set()):
                break
            if max_frames is not None and len(log.seq) >= max_frames:
                break
            if idle_timeout_s is not None and now - last_frame_at > idle_timeout_s:
                break
            if progress is not None and now >= next_progress:
                progress(len(log.seq), self.source.stats(), last)
                next_progress += progress_every_s
            frame = self.source.get(timeout=0.05)
            if frame is None:
                continue
            last_frame_at = time.perf_counter()
            t0 = time.perf_counter_ns()
            angles = self.estimator.push(frame.values_mm)
            t1 = time.perf_counter_ns()
            last = angles.copy()
            for sink in self.sinks:
                sink(frame, last)
            done = time.perf_counter_ns()
            log.seq.append(frame.seq)
            log.t.append(frame.device_time_s)
            log.est.append(last)
            log.compute.append(t1 - t0)
            log.latency.append(done - frame.host_ns)
        n_angles = 0 if last is None else last.shape[0]
        estimates = np.asarray(log.est, dtype=np.float64).reshape(len(log.est), n_angles)
        return PipelineRun(
            seq=np.asarray(log.seq, dtype=np.int64),
            device_time_s=np.asarray(log.t, dtype=np.float64),
            estimates=estimates,
            compute_ns=np.asarray(log.compute, dtype=np.int64),
            latency_ns=np.asarray(log.latency, dtype=np.int64),
            link=self.source.stats(),
            wall_s=time.perf_counter() - start,
        )


def percentiles_us(ns: np.ndarray) -> dict[str, float]:
    """p50 / p99 / max of nanosecond samples, in µs (NaN when empty)."""
    if ns.size == 0:
        return {"p50_us": float("nan"), "p99_us": float("nan"), "max_us": float("nan")}
    us = ns / 1e3
    return {
        "p50_us": round(float(np.percentile(us, 50)), 1),
        "p99_us": round(float(np.percentile(us, 99)), 1),
        "max_us": round(float(us.max()), 1),
    }
