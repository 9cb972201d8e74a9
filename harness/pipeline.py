"""The real-time pipeline: frames from a :class:`FrameSource` → streaming estimator → sinks.

This is the paper's two-thread layout: the acquisition thread (inside the frame source) keeps
reading the device at 250 Hz; this loop, on the calling thread, takes each frame, runs the
estimator on it (window kept inside the engine) and hands a :class:`Sample` to each sink in
order (teleoperation, recorder, ...).

Every frame is stamped on one monotonic clock (``time.perf_counter_ns()``, system-wide on
Linux, so an emulator in the same or another process stamps on it too) at each stage of
:data:`STAGES`: the device's write (when the device can say, see ``device_clock``), host
receive, decoded, estimate done, teleoperation command issued, and all sinks done.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from exohil.harness.frame_source import Frame, FrameSource, LinkStats

#: Per-frame stamps, in order. ``device_write`` only when the device reports its write times
#: (the emulator does); ``commanded`` only when a teleoperation sink ran.
STAGES = ("device_write", "host_receive", "decoded", "estimated", "commanded", "done")
#: Stamp value of a stage that was not reached or not observable.
NOT_STAMPED = -1


class Estimator(Protocol):
    """One call per frame: sensor values (S,) → angles (A,), degrees (e.g. StreamingEstimator)."""

    def push(self, values: np.ndarray) -> np.ndarray: ...


@dataclass
class RobotCommand:
    """Joint command sent to the robot for one frame.

    Attributes:
        joints: (3,) NAO ShoulderPitch, ShoulderRoll, ElbowYaw, radians (after clamping).
        clamped: (3,) which joints hit their limit.
    """

    joints: np.ndarray
    clamped: np.ndarray


@dataclass
class Sample:
    """What each sink receives for one frame.

    Attributes:
        frame: the frame as delivered by the source.
        angles: (A,) estimates, degrees, in the estimator's target order.
        stamps: stage → ``perf_counter_ns`` (see :data:`STAGES`); sinks may add stages.
        command: the robot command, once a teleoperation sink has issued it.
    """

    frame: Frame
    angles: np.ndarray
    stamps: dict[str, int] = field(default_factory=dict)
    command: RobotCommand | None = None


class Sink(Protocol):
    """A consumer of samples (teleoperation, recorder, network). ``accept`` runs on the
    pipeline's thread for every frame and must not block; ``close`` finishes the sink's work
    (flushes files, stops threads) and is called once, after the run."""

    def accept(self, sample: Sample) -> None: ...

    def close(self) -> None: ...


#: ``seq → perf_counter_ns`` of the device's write of that frame, or None when unknown.
DeviceClock = Callable[[int], int | None]


@dataclass
class Status:
    """What the pipeline did since the previous status, for a live status line.

    Attributes:
        frames: frames processed so far.
        link: the link counters now.
        last: the latest estimate (A,), degrees, or None before the first frame.
        recent_latency_ms: end to end (device write, else host receive → robot command, else
            all sinks done) of each frame since the previous status, ms.
        recent_device_time_s / recent_estimates: those frames' device times (s) and
            estimates (N, A), degrees.
        error_deg: the running error against ground truth, when the caller knows it (the
            session fills it in), degrees.
    """

    frames: int
    link: LinkStats
    last: np.ndarray | None
    recent_latency_ms: np.ndarray
    recent_device_time_s: np.ndarray
    recent_estimates: np.ndarray
    error_deg: float | None = None


@dataclass
class PipelineRun:
    """What one run produced.

    Attributes:
        seq / device_time_s: (N,) of the frames processed, in order.
        values: (N, S) their sensor values as received, mm.
        estimates: (N, A) angle estimates, degrees.
        stamps: (N, len(STAGES)) ``perf_counter_ns`` per stage, :data:`NOT_STAMPED` where absent.
        compute_ns: (N,) estimator time per frame, ns.
        commands: (N, 3) robot joint commands, radians (NaN where none was issued).
        clamped: (N,) whether any joint of the command was clamped.
        link: the link counters at the end.
        wall_s: duration of the run, s.
    """

    seq: np.ndarray
    device_time_s: np.ndarray
    values: np.ndarray
    estimates: np.ndarray
    stamps: np.ndarray
    compute_ns: np.ndarray
    commands: np.ndarray
    clamped: np.ndarray
    link: LinkStats
    wall_s: float

    @property
    def frames(self) -> int:
        return int(self.seq.shape[0])

    def interval_ms(self, start: str, end: str) -> np.ndarray:
        """Per-frame time from stage ``start`` to ``end``, ms, over frames with both stamps."""
        a, b = self.stamps[:, STAGES.index(start)], self.stamps[:, STAGES.index(end)]
        ok = (a != NOT_STAMPED) & (b != NOT_STAMPED)
        return (b[ok] - a[ok]) / 1e6


class _Log:
    """Per-frame figures in fixed-size numpy blocks. A long run holds a few large arrays
    instead of several small objects per frame, which the garbage collector had to walk again
    and again: its full collections stalled the pipeline for tens of ms, and grew with the run.
    Integer row: seq, estimator ns, the stamps; float row: device time, values, estimates,
    command, clamped."""

    BLOCK = 4096

    def __init__(self) -> None:
        self.n = 0
        self.n_sensors = self.n_angles = 0
        self._ints: list[np.ndarray] = []
        self._floats: list[np.ndarray] = []

    def add(self, seq: int, compute_ns: int, stamps: list[int], t: float, values: np.ndarray,
            estimates: np.ndarray, command: np.ndarray, clamped: bool) -> None:
        i = self.n % self.BLOCK
        if i == 0:
            if not self._ints:
                self.n_sensors, self.n_angles = values.shape[0], estimates.shape[0]
            self._ints.append(np.empty((self.BLOCK, 2 + len(STAGES)), dtype=np.int64))
            self._floats.append(np.empty((self.BLOCK, 5 + self.n_sensors + self.n_angles)))
        ints, floats = self._ints[-1][i], self._floats[-1][i]
        ints[0], ints[1], ints[2:] = seq, compute_ns, stamps
        s, a = self.n_sensors, self.n_angles
        floats[0], floats[1:1 + s], floats[1 + s:1 + s + a] = t, values, estimates
        floats[1 + s + a:4 + s + a], floats[4 + s + a] = command, clamped
        self.n += 1

    def rows(self, since: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """(integer rows, float rows) of the frames from ``since`` on."""
        if self.n == since:
            return (np.empty((0, 2 + len(STAGES)), dtype=np.int64),
                    np.empty((0, 5 + self.n_sensors + self.n_angles)))
        first = since // self.BLOCK
        ints = np.concatenate(self._ints[first:])[since - first * self.BLOCK:self.n - first
                                                  * self.BLOCK]
        floats = np.concatenate(self._floats[first:])[since - first * self.BLOCK:self.n - first
                                                      * self.BLOCK]
        return ints, floats


_NO_COMMAND = np.full(3, np.nan)


class Pipeline:
    """Drives frames through the estimator into the sinks (see module doc).

    Args:
        source: the frames (already started by the caller).
        estimator: the streaming estimator.
        sinks: consumers, called in order for every frame.
        device_clock: when the device can tell when it wrote a frame (the emulator's
            ``write_time_ns``), the ``device_write`` stage is stamped from it.
    """

    def __init__(self, source: FrameSource, estimator: Estimator, sinks: Sequence[Sink] = (),
                 device_clock: DeviceClock | None = None) -> None:
        self.source = source
        self.estimator = estimator
        self.sinks = list(sinks)
        self.device_clock = device_clock

    def run(
        self,
        duration_s: float | None = None,
        max_frames: int | None = None,
        stop: threading.Event | None = None,
        progress: Callable[[Status], None] | None = None,
        progress_every_s: float = 1.0,
        idle_timeout_s: float | None = None,
        until_device_time_s: float | None = None,
        source_done: Callable[[], bool] | None = None,
    ) -> PipelineRun:
        """Process frames until ``duration_s`` (wall clock) or ``max_frames`` or ``stop`` is set,
        or, once frames have started to arrive, none arrived for ``idle_timeout_s``, or a frame
        stamped at or after ``until_device_time_s`` (device clock, s) was processed, or
        ``source_done()`` says the source will send nothing more and its buffer is empty (an
        emulator that has sent everything; a reader whose device never came back).
        ``progress(status)`` is called about every ``progress_every_s``. The sinks are not
        closed (their owner does)."""
        log = _Log()
        start = time.perf_counter()
        deadline = None if duration_s is None else start + duration_s
        next_progress = start + progress_every_s
        last_frame_at: float | None = None
        last: np.ndarray | None = None
        reported = 0
        while True:
            now = time.perf_counter()
            if (deadline is not None and now >= deadline) or (stop is not None and stop.is_set()):
                break
            if max_frames is not None and log.n >= max_frames:
                break
            if (idle_timeout_s is not None and last_frame_at is not None
                    and now - last_frame_at > idle_timeout_s):
                break
            if progress is not None and now >= next_progress:
                progress(self._status(log, reported, last))
                reported = log.n
                next_progress += progress_every_s
            frame = self.source.get(timeout=0.05)
            if frame is None:
                if source_done is not None and source_done():
                    break
                continue
            last_frame_at = time.perf_counter()
            sample = self._process(frame, log)
            last = sample.angles
            if until_device_time_s is not None and frame.device_time_s >= until_device_time_s:
                break
        return self._result(log, time.perf_counter() - start)

    def _process(self, frame: Frame, log: _Log) -> Sample:
        t0 = time.perf_counter_ns()
        angles = np.array(self.estimator.push(frame.values_mm), dtype=np.float64)
        t1 = time.perf_counter_ns()
        stamps = {"host_receive": frame.host_ns, "estimated": t1}
        if frame.decoded_ns:
            stamps["decoded"] = frame.decoded_ns
        if self.device_clock is not None:
            written = self.device_clock(frame.seq)
            if written is not None:
                stamps["device_write"] = written
        sample = Sample(frame, angles, stamps)
        for sink in self.sinks:
            sink.accept(sample)
        stamps["done"] = time.perf_counter_ns()
        command = sample.command
        log.add(frame.seq, t1 - t0, [stamps.get(stage, NOT_STAMPED) for stage in STAGES],
                frame.device_time_s, frame.values_mm, angles,
                _NO_COMMAND if command is None else command.joints,
                bool(command is not None and command.clamped.any()))
        return sample

    def _status(self, log: _Log, since: int, last: np.ndarray | None) -> Status:
        ints, floats = log.rows(since)
        stamps = ints[:, 2:]
        start = np.where(stamps[:, STAGES.index("device_write")] != NOT_STAMPED,
                         stamps[:, STAGES.index("device_write")],
                         stamps[:, STAGES.index("host_receive")])
        end = np.where(stamps[:, STAGES.index("commanded")] != NOT_STAMPED,
                       stamps[:, STAGES.index("commanded")], stamps[:, STAGES.index("done")])
        s, a = log.n_sensors, log.n_angles
        return Status(log.n, self.source.stats(), last, (end - start) / 1e6,
                      floats[:, 0].copy(), floats[:, 1 + s:1 + s + a].copy())

    def _result(self, log: _Log, wall_s: float) -> PipelineRun:
        ints, floats = log.rows()
        s, a = log.n_sensors, log.n_angles
        return PipelineRun(
            seq=ints[:, 0].copy(),
            device_time_s=floats[:, 0].copy(),
            values=floats[:, 1:1 + s].copy(),
            estimates=floats[:, 1 + s:1 + s + a].copy(),
            stamps=ints[:, 2:].copy(),
            compute_ns=ints[:, 1].copy(),
            commands=floats[:, 1 + s + a:4 + s + a].copy(),
            clamped=floats[:, 4 + s + a] != 0.0,
            link=self.source.stats(),
            wall_s=wall_s,
        )
