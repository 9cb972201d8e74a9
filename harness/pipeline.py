"""The real-time pipeline: frames from a :class:`FrameSource` → streaming estimator → sinks.

This is the paper's two-thread layout: the acquisition thread (inside the frame source) keeps
reading the device at 250 Hz; this loop, on the calling thread, takes each frame, runs the
estimator on it (window kept inside the engine) and hands a :class:`Sample` to each sink in
order (teleoperation, recorder, ...).

Every frame is stamped on one monotonic clock (``time.perf_counter_ns()``, system-wide on
Linux, so an emulator in the same or another process stamps on it too) at each stage of
:data:`STAGES`: the device's write (when the device can say, see ``device_clock``), host
receive, decoded, estimate done, teleoperation command issued, and all sinks done.

A run's memory does not grow with its length (a 24-hour run holds steady): the per-frame rows
are kept for the run's first and last frames only (:class:`PipelineRun`), and every frame is
folded into fixed-size totals as the run goes: per-stage latency histograms, counters, and
the callers' own streaming statistics (``observers``: accuracy, link reconciliation).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from exohil.harness.device_rate import measured_rate_hz
from exohil.harness.frame_source import Frame, FrameSource, LinkStats
from exohil.harness.robot_stats import LogHistogram

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
            all sinks done) of each frame since the previous status, ms (of those still kept:
            all of them unless statuses are further apart than ``keep_last`` frames).
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
class FrameRows:
    """Per-frame figures of frames in the order they were processed.

    Attributes:
        seq / device_time_s: (N,) of the frames.
        values: (N, S) their sensor values as received, mm.
        estimates: (N, A) angle estimates, degrees.
        stamps: (N, len(STAGES)) ``perf_counter_ns`` per stage, :data:`NOT_STAMPED` where absent.
        compute_ns: (N,) estimator time per frame, ns.
        commands: (N, 3) robot joint commands, radians (NaN where none was issued).
        clamped: (N,) whether any joint of the command was clamped.
    """

    seq: np.ndarray
    device_time_s: np.ndarray
    values: np.ndarray
    estimates: np.ndarray
    stamps: np.ndarray
    compute_ns: np.ndarray
    commands: np.ndarray
    clamped: np.ndarray

    @property
    def retained(self) -> int:
        """How many frames these rows hold."""
        return int(self.seq.shape[0])

    def interval_ms(self, start: str, end: str) -> np.ndarray:
        """Per-frame time from stage ``start`` to ``end``, ms, over frames with both stamps."""
        a, b = self.stamps[:, STAGES.index(start)], self.stamps[:, STAGES.index(end)]
        ok = (a != NOT_STAMPED) & (b != NOT_STAMPED)
        return (b[ok] - a[ok]) / 1e6


#: Range of the latency histograms, ms: from 1 µs (below reads as 1 µs) to 1000 s.
LATENCY_LOW_MS, LATENCY_HIGH_MS = 1e-3, 1e6
#: Per-frame rows a run keeps by default: its first and its last (at least) 16,384 frames,
#: 65.5 s each at 250 Hz. Everything else is folded into fixed-size totals as it goes.
KEEP_FIRST_FRAMES = KEEP_LAST_FRAMES = 1 << 14

#: Called with every frame's rows exactly once, in order, in chunks (see ``Pipeline``).
RowsObserver = Callable[[FrameRows], None]


def _histogram() -> LogHistogram:
    return LogHistogram(LATENCY_LOW_MS, LATENCY_HIGH_MS)


@dataclass
class PipelineRun(FrameRows):
    """What one run produced: totals over every frame, and the rows of a bounded window.

    Memory does not grow with the run's length: the per-frame rows (:class:`FrameRows`
    attributes) are those of the run's first frames and of its last ones (``Pipeline``'s
    ``keep_first`` / ``keep_last``); a run that fits holds every frame (:attr:`complete`).
    The totals are exact over every frame, the latency quantiles to one histogram bin.

    Attributes:
        frames: frames processed, all of them.
        head: the first ``head`` rows are the run's first frames, the others (if any) its last
            ones; ``head == retained`` when the rows are contiguous.
        first_seq / last_seq: of the first and the last frame (None without frames).
        first_device_time_s / last_device_time_s: likewise, s (NaN without frames).
        commanded: frames for which a robot command was issued.
        clamped_commands: of those, the ones with a joint at its limit.
        stamped: stage → frames stamped at that stage.
        compute_ms: the estimator's time per frame, ms (histogram).
        intervals: (start, end) stage pair → per-frame ``end - start`` over the frames stamped
            at both, ms (histogram; a pair in :data:`STAGES` order); use
            :meth:`interval_histogram`.
        link: the link counters at the end.
        wall_s: duration of the run, s.
    """

    frames: int
    head: int
    first_seq: int | None
    last_seq: int | None
    first_device_time_s: float
    last_device_time_s: float
    commanded: int
    clamped_commands: int
    stamped: dict[str, int]
    compute_ms: LogHistogram
    intervals: dict[tuple[str, str], LogHistogram]
    link: LinkStats
    wall_s: float

    @property
    def device_rate_hz(self) -> float | None:
        """The device's own frame rate over the run, Hz: sequence numbers per second of
        device time, the frames missed across a reboot included; None under
        :data:`~exohil.harness.device_rate.MIN_SPAN_S` of device time."""
        return measured_rate_hz(self.first_seq, self.last_seq, self.first_device_time_s,
                                self.last_device_time_s, self.link.dropped_in_resets)

    @property
    def complete(self) -> bool:
        """Whether the rows hold every frame of the run."""
        return self.retained == self.frames

    def interval_histogram(self, start: str, end: str) -> LogHistogram:
        """Time from stage ``start`` to ``end`` of every frame stamped at both, ms (negative
        intervals, which one monotonic clock never gives, count as 0)."""
        if STAGES.index(start) >= STAGES.index(end):
            raise ValueError(f"stage {start!r} does not come before {end!r} in {STAGES}")
        return self.intervals[(start, end)]


class _Log:
    """Per-frame figures in fixed-size numpy blocks, with bounded memory.

    A long run holds a few large arrays instead of several small objects per frame, which the
    garbage collector had to walk again and again (its full collections stalled the pipeline
    for tens of ms, and grew with the run). Integer row: seq, estimator ns, the stamps; float
    row: device time, values, estimates, command, clamped.

    Logged rows are *folded*, in order and in steps of at most :attr:`FOLD` rows, into totals
    of fixed size (histograms, counters) and handed to the observers; the pipeline folds while
    the source has nothing waiting. Blocks are kept while they hold the run's first
    ``keep_first`` frames or its last ``keep_last``; an older block, once folded, is reused for
    the next frames. Memory is at most ``head_blocks + tail_blocks`` blocks plus the totals,
    whatever the run's length.
    """

    BLOCK = 4096
    FOLD = 1024

    def __init__(self, keep_first: int = KEEP_FIRST_FRAMES, keep_last: int = KEEP_LAST_FRAMES,
                 observers: Sequence[RowsObserver] = ()) -> None:
        if keep_first < 0 or keep_last < 0:
            raise ValueError(f"keep_first and keep_last must be >= 0, got {keep_first!r}, "
                             f"{keep_last!r}")
        self.head_blocks = -(-keep_first // self.BLOCK)
        self.tail_blocks = -(-keep_last // self.BLOCK) + 1  # + the block being filled
        self.observers = list(observers)
        self.n = 0
        self.folded = 0
        self.n_sensors = self.n_angles = 0
        self._blocks: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._current: tuple[np.ndarray, np.ndarray] | None = None
        # totals over the folded frames
        self.intervals = {(a, b): _histogram() for i, a in enumerate(STAGES)
                          for b in STAGES[i + 1:]}
        self._pairs = [(STAGES.index(a), STAGES.index(b), h) for (a, b), h in
                       self.intervals.items()]
        self.compute_ms = _histogram()
        self.stamped = np.zeros(len(STAGES), dtype=np.int64)
        self.commanded = self.clamped_commands = 0
        self.first_seq: int | None = None
        self.last_seq: int | None = None
        self.first_t = self.last_t = float("nan")

    # ---- logging -------------------------------------------------------------------------
    def add(self, seq: int, compute_ns: int, stamps: list[int], t: float, values: np.ndarray,
            estimates: np.ndarray, command: np.ndarray, clamped: bool) -> None:
        block, i = divmod(self.n, self.BLOCK)
        if i == 0:
            self._start_block(block, values.shape[0], estimates.shape[0])
        assert self._current is not None
        ints, floats = self._current[0][i], self._current[1][i]
        ints[0], ints[1], ints[2:] = seq, compute_ns, stamps
        s, a = self.n_sensors, self.n_angles
        floats[0], floats[1:1 + s], floats[1 + s:1 + s + a] = t, values, estimates
        floats[1 + s + a:4 + s + a], floats[4 + s + a] = command, clamped
        self.n += 1

    def _start_block(self, block: int, n_sensors: int, n_angles: int) -> None:
        if not self._blocks:
            self.n_sensors, self.n_angles = n_sensors, n_angles
        arrays = None
        old = block - self.tail_blocks
        if old >= self.head_blocks and old in self._blocks:  # left the window: reuse it
            self.fold(until=(old + 1) * self.BLOCK)
            arrays = self._blocks.pop(old)
        if arrays is None:
            arrays = (np.empty((self.BLOCK, 2 + len(STAGES)), dtype=np.int64),
                      np.empty((self.BLOCK, 5 + self.n_sensors + self.n_angles)))
        self._blocks[block] = self._current = arrays

    # ---- folding -------------------------------------------------------------------------
    @property
    def backlog(self) -> int:
        """Frames logged but not folded yet."""
        return self.n - self.folded

    def fold(self, until: int | None = None) -> None:
        """Fold the frames before ``until`` (default: every frame logged)."""
        until = self.n if until is None else min(until, self.n)
        while self.folded < until:
            self.fold_step(until - self.folded)

    def fold_step(self, most: int | None = None) -> None:
        """Fold the next at most :attr:`FOLD` (or ``most``) frames, within one block."""
        block, i = divmod(self.folded, self.BLOCK)
        k = min(self.n - self.folded, self.FOLD, self.BLOCK - i,
                self.FOLD if most is None else most)
        if k <= 0:
            return
        ints, floats = self._blocks[block]
        rows = self._rows(ints[i:i + k], floats[i:i + k])
        self._tally(rows)
        for observe in self.observers:
            observe(rows)
        self.folded += k

    def _tally(self, rows: FrameRows) -> None:
        stamps = rows.stamps
        ok = stamps != NOT_STAMPED
        self.stamped += ok.sum(axis=0)
        for a, b, hist in self._pairs:
            both = ok[:, a] & ok[:, b]
            if both.any():
                hist.add_many(np.maximum(stamps[both, b] - stamps[both, a], 0) / 1e6)
        self.compute_ms.add_many(np.maximum(rows.compute_ns, 0) / 1e6)
        self.commanded += int(np.count_nonzero(np.all(np.isfinite(rows.commands), axis=1)))
        self.clamped_commands += int(np.count_nonzero(rows.clamped))
        if self.first_seq is None:
            self.first_seq, self.first_t = int(rows.seq[0]), float(rows.device_time_s[0])
        self.last_seq, self.last_t = int(rows.seq[-1]), float(rows.device_time_s[-1])

    # ---- reading -------------------------------------------------------------------------
    def _rows(self, ints: np.ndarray, floats: np.ndarray) -> FrameRows:
        """Views (not copies) of the columns of ``ints`` / ``floats`` rows."""
        s, a = self.n_sensors, self.n_angles
        return FrameRows(seq=ints[:, 0], device_time_s=floats[:, 0], values=floats[:, 1:1 + s],
                         estimates=floats[:, 1 + s:1 + s + a], stamps=ints[:, 2:],
                         compute_ns=ints[:, 1], commands=floats[:, 1 + s + a:4 + s + a],
                         clamped=floats[:, 4 + s + a] != 0.0)

    def rows(self, since: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """(integer rows, float rows) of the kept frames from ``since`` on (copies)."""
        ints, floats = [], []
        for block in sorted(self._blocks):
            start = block * self.BLOCK
            lo, hi = max(since, start), min(start + self.BLOCK, self.n)
            if lo < hi:
                ints.append(self._blocks[block][0][lo - start:hi - start])
                floats.append(self._blocks[block][1][lo - start:hi - start])
        if not ints:
            return (np.empty((0, 2 + len(STAGES)), dtype=np.int64),
                    np.empty((0, 5 + self.n_sensors + self.n_angles)))
        return np.concatenate(ints), np.concatenate(floats)

    @property
    def head(self) -> int:
        """Kept frames contiguous from the run's first one."""
        kept = 0
        for block in sorted(self._blocks):
            if block * self.BLOCK != kept:
                break
            kept = min((block + 1) * self.BLOCK, self.n)
        return kept

    @property
    def nbytes(self) -> int:
        """Bytes of the kept rows and of the totals' histograms."""
        rows = sum(i.nbytes + f.nbytes for i, f in self._blocks.values())
        return rows + sum(h.nbytes for h in self.intervals.values()) + self.compute_ms.nbytes


_NO_COMMAND = np.full(3, np.nan)


class Pipeline:
    """Drives frames through the estimator into the sinks (see module doc).

    Args:
        source: the frames (already started by the caller).
        estimator: the streaming estimator.
        sinks: consumers, called in order for every frame.
        device_clock: when the device can tell when it wrote a frame (the emulator's
            ``write_time_ns``), the ``device_write`` stage is stamped from it.
        keep_first / keep_last: per-frame rows the run keeps of its first and (at least) of its
            last frames, rounded up to whole blocks of 4,096 (:class:`PipelineRun`).
        observers: called with the rows of every frame exactly once, in order, in chunks of
            at most 1,024 frames, on the pipeline's thread while the source has nothing waiting
            (or once a backlog of 4,096 frames built up, and at the end of the run): streaming
            statistics that must see every frame. The rows are views, valid during the call.
    """

    def __init__(self, source: FrameSource, estimator: Estimator, sinks: Sequence[Sink] = (),
                 device_clock: DeviceClock | None = None, *,
                 keep_first: int = KEEP_FIRST_FRAMES, keep_last: int = KEEP_LAST_FRAMES,
                 observers: Sequence[RowsObserver] = ()) -> None:
        self.source = source
        self.estimator = estimator
        self.sinks = list(sinks)
        self.device_clock = device_clock
        self.keep_first, self.keep_last = keep_first, keep_last
        self.observers = list(observers)

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
        log = _Log(self.keep_first, self.keep_last, self.observers)
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
            folding = log.backlog >= log.FOLD  # fold while nothing is waiting
            frame = self.source.get(timeout=0.0 if folding else 0.05)
            if frame is None:
                if folding:
                    log.fold_step()
                    continue
                if source_done is not None and source_done():
                    break
                continue
            last_frame_at = time.perf_counter()
            sample = self._process(frame, log)
            last = sample.angles
            if log.backlog > log.BLOCK:  # a source that never pauses
                log.fold_step()
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
        log.fold()
        ints, floats = log.rows()
        rows = log._rows(ints, floats)
        return PipelineRun(
            seq=rows.seq.copy(),
            device_time_s=rows.device_time_s.copy(),
            values=rows.values.copy(),
            estimates=rows.estimates.copy(),
            stamps=rows.stamps.copy(),
            compute_ns=rows.compute_ns.copy(),
            commands=rows.commands.copy(),
            clamped=rows.clamped,
            frames=log.n,
            head=log.head,
            first_seq=log.first_seq,
            last_seq=log.last_seq,
            first_device_time_s=log.first_t,
            last_device_time_s=log.last_t,
            commanded=log.commanded,
            clamped_commands=log.clamped_commands,
            stamped={stage: int(n) for stage, n in zip(STAGES, log.stamped, strict=True)},
            compute_ms=log.compute_ms,
            intervals=log.intervals,
            link=self.source.stats(),
            wall_s=wall_s,
        )
