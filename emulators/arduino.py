"""The software Arduino: replays sensor frames over a virtual serial port, with faults.

``ArduinoEmulator`` runs in a thread. Frame ``k`` (unwrapped sequence number ``seq0 + k``) is
sampled at device time ``k / rate_hz`` s, stamped ``t_us0 + round(k * 1e6 / rate_hz)`` µs
(mod 2**32) and sent at the absolute deadline ``t0 + k / rate_hz`` on the host's
``perf_counter`` clock, so the mean rate does not drift. Replaying a recording, the device
keeps the recording's own clock and numbering: ``seq0`` and ``t_us0`` are its first frame's,
and sequence numbers the recording lacks are not sent (logged ``drop``, reason ``absent from
the recording``), so a host can align its frames with the recording's motion capture by
device time or by sequence number. Like the real device it streams
whether or not a host is reading; frames that cannot be handed over are logged as
``not_read``. Every fault and loss is in :attr:`ArduinoEmulator.fault_log` (docs/emulator.md).

    with ArduinoEmulator.from_recording(rec, faults="drop:rate=0.01") as emu:
        source = SerialFrameSource(emu.port)  # any pyserial client
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from typing import Any

import numpy as np

from exohil.emulators.effects import Signal
from exohil.emulators.fault_spec import FaultPlan, check_sensor_count, fault_plan
from exohil.emulators.faults import FaultRecord, FrameFaultInjector
from exohil.emulators.pty_port import VirtualSerialPort
from exohil.formats.recording import Recording
from exohil.formats.recording_messages import first_non_finite
from exohil.formats.wire import (
    MM_PER_LSB,
    SEQ_MODULUS,
    TIME_MODULUS_US,
    WireFrame,
    encode_frame,
    off_the_wire,
)
from exohil.realtime import SPIN_S, request_realtime, sleep_until

_IDLE_POLL_S = 0.001
#: How often a stream started with ``begin(when_attached=True)`` looks for a host, s.
_ATTACH_POLL_S = 0.005
#: How many of the frames last written keep their bytes, to tell which ones a host had not
#: read when the port vanishes (a pty holds about 1000 frames).
_RECENT_FRAMES = 8192
#: ``not_read`` reasons of frames lost after they were written to the port
_PORT_CLOSED = "port closed"
_HOST_CLOSED = "host closed the port"
#: How many recent frames keep their write time for :meth:`ArduinoEmulator.write_time_ns`
#: (2**16 frames: 262 s at 250 Hz).
_WRITE_TIMES = 1 << 16


class ArduinoEmulator:
    """A device that streams wire protocol v1 on a pty; a context manager (see module doc).

    Args:
        values_mm: (N, S) sensor values to replay, mm (S = 1..16), or a recording whose
            sensor values (mm) to replay.
        rate_hz: frame rate (250 for the real device; tests may run several kHz).
        loop: replay the values cyclically.
        duration_s: stop after this much device time (default: end of the values, or never
            when looping).
        faults: a :class:`FaultPlan`, a spec string or a TOML path (see fault_spec).
        seed: seeds every random fault and effect.
        seq0: sequence number of the first frame (wire value is mod 65536); default: the
            recording's first, else 0.
        t_us0: device timestamp of the first frame, µs (wire value is mod 2**32); default: the
            recording's first sensor time, else 0.
        autostart: start streaming as soon as the port exists; otherwise wait for
            :meth:`begin` (tests use it to start once their reader is attached).
        attach_grace_s: after a host opens the port, frames are not handed over until it has
            flushed its input queue (pyserial does at the end of ``open()``; anything written
            before that flush is discarded by the host), or for clients that never flush, until
            this many seconds have passed. Such frames are logged ``not_read``.
        drain_timeout_s: at a disconnect, how long to wait for the host to read what was
            already written before the port vanishes (frames still unread then are logged
            lost); also how long the end of the stream waits for the host to catch up (what
            it has not read when :meth:`stop` closes the port is logged lost there).
        record_send_times: keep (seq, perf_counter_ns) of every write (benchmarks).
        spin_s: pacing spins on the clock for the last ``spin_s`` seconds before each deadline.
        realtime: run the emulator thread under SCHED_FIFO (needs CAP_SYS_NICE; when refused,
            :attr:`realtime_error` says why and the thread keeps its normal policy).
    """

    def __init__(
        self,
        values_mm: np.ndarray | Recording,
        *,
        rate_hz: float = 250.0,
        loop: bool = False,
        duration_s: float | None = None,
        faults: FaultPlan | str | None = None,
        seed: int = 0,
        seq0: int | None = None,
        t_us0: int | None = None,
        autostart: bool = True,
        attach_grace_s: float = 0.5,
        drain_timeout_s: float = 1.0,
        record_send_times: bool = False,
        spin_s: float = SPIN_S,
        realtime: bool = False,
    ) -> None:
        if not math.isfinite(rate_hz) or rate_hz <= 0:
            raise ValueError("rate_hz must be a positive number")
        if duration_s is not None and not 0 < duration_s < math.inf:
            raise ValueError(f"duration_s must be a finite number of seconds > 0, got "
                             f"{duration_s!r}")
        self.rate_hz = float(rate_hz)
        present = None
        if isinstance(values_mm, Recording):
            recording = values_mm
            why = off_the_wire(recording.sensor_units)
            if why is not None:
                raise ValueError(why)
            if recording.sensors.values.shape[0] == 0:
                raise ValueError("the recording has no sensor frames")
            # not looping, with a duration: only the frames streamed, so a recording whose
            # sequence jumps by 10**12 needs no grid of 10**12 rows to stream its first second
            values_mm, present = _on_sequence_grid(
                recording.sensors.seq, recording.sensors.values,
                None if loop or duration_s is None else max(1, round(duration_s * rate_hz)))
            seq0 = int(recording.sensors.seq[0]) if seq0 is None else seq0
            t_us0 = round(float(recording.sensors.t[0]) * 1e6) if t_us0 is None else t_us0
        values = np.asarray(values_mm, dtype=np.float64)
        if values.ndim != 2 or values.shape[0] == 0 or not 1 <= values.shape[1] <= 16:
            raise ValueError(f"values must be (N>0, 1..16) mm, got shape {values.shape}")
        bad = first_non_finite(values)
        if bad is not None:  # the wire has no NaN: it would go out as 0 mm
            raise ValueError(f"values must be finite: frame {bad[0]}, sensor {bad[1]} is "
                             f"{values[bad]}")
        self.plan = faults if isinstance(faults, FaultPlan) else fault_plan(faults)
        check_sensor_count(self.plan, int(values.shape[1]))
        self.seed = int(seed)
        self.seq0 = int(seq0 or 0)
        self.t_us0 = int(t_us0 or 0)
        self.attach_grace_s = attach_grace_s
        self.drain_timeout_s = drain_timeout_s
        self.n_frames = self._frame_count(values.shape[0], loop, duration_s)
        self._raw, self._keep = self._prepare(values, loop)
        self._present = (np.ones(self._raw.shape[0], dtype=bool) if present is None
                         else np.resize(present, self._raw.shape[0]))
        self.sensor_count = int(values.shape[1])

        self._port = VirtualSerialPort()
        self.port = self._port.path
        self._log: list[FaultRecord] = []
        self._recent: deque[tuple[int, bytes]] = deque(maxlen=_RECENT_FRAMES)
        self.send_times: list[tuple[int, int]] | None = [] if record_send_times else None
        self._write_seq = np.full(_WRITE_TIMES, -1, dtype=np.int64)
        self._write_ns = np.zeros(_WRITE_TIMES, dtype=np.int64)
        self.frames_generated = 0
        self.frames_written = 0
        self.bytes_written = 0
        self.error: BaseException | None = None
        self.realtime = realtime
        self.spin_s = spin_s
        self.realtime_error: str | None = None
        self._attached_at: float | None = None
        self._host_ready = False
        self._ready = threading.Event()
        self._go = threading.Event()
        self._when_attached = False
        self._stop = threading.Event()
        self._finished = threading.Event()
        if autostart:
            self._go.set()
        self._thread = threading.Thread(target=self._run, name="arduino-emulator", daemon=True)

    @classmethod
    def from_recording(cls, recording: Recording, **kwargs: Any) -> ArduinoEmulator:
        """An emulator replaying ``recording``'s sensor values (mm); kwargs as ``__init__``."""
        return cls(recording, **kwargs)

    # ---- lifecycle -------------------------------------------------------------------
    def __enter__(self) -> ArduinoEmulator:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def start(self) -> None:
        """Create the port and start the emulator thread; returns once ``port`` exists.
        RuntimeError for an emulator started or stopped before: one runs once."""
        if self._thread.ident is not None or self._stop.is_set():
            raise RuntimeError("this emulator was started or stopped before: an emulator "
                               "runs once; make a new one")
        self._thread.start()
        self._ready.wait()
        if self.error is not None:
            raise RuntimeError(f"emulator failed to start: {self.error}") from self.error

    def begin(self, when_attached: bool = False) -> None:
        """Start streaming (only needed with ``autostart=False``); with ``when_attached``,
        only once a host has the port open (device time starts then, so a fault at
        ``at_s`` meets a host however long it took to open the port)."""
        self._when_attached = when_attached
        self._go.set()

    def stop(self, timeout_s: float = 5.0) -> None:
        """Stop streaming, join the thread (bounded by ``timeout_s``) and remove the port;
        frames an attached host has not read by then are logged ``not_read`` (reason
        ``port closed``), so :attr:`fault_log` is complete once this returns."""
        self._stop.set()
        self._go.set()
        if self._thread.is_alive():
            self._thread.join(timeout_s)
        if not self._thread.is_alive() and self._port.host_attached():
            self._log_unread("not_read", reason=_PORT_CLOSED)
        self._port.close()

    def wait_finished(self, timeout_s: float | None = None) -> bool:
        """Block until every frame has been sent and an attached host has read them (or
        ``drain_timeout_s`` passed); the port stays up until :meth:`stop`. RuntimeError for
        an emulator never started (it would wait for ever)."""
        if self._thread.ident is None:
            raise RuntimeError("the emulator was never started: call start() (or use it as "
                               "a context manager) first")
        return self._finished.wait(timeout_s)

    @property
    def finished(self) -> bool:
        return self._finished.is_set()

    @property
    def frames_read(self) -> int:
        """Frames written to the port that the host received whole: ``frames_written`` less
        those logged lost after they were written (the port vanishing or closing with them
        unread, a frame whose tail was never written). Exact once :meth:`stop` has returned,
        but for frames a host discards itself by closing the port with them unread, which
        the emulator cannot see."""
        return self.frames_written - sum(1 for r in self._log if _lost_after_written(r))

    @property
    def fault_log(self) -> list[FaultRecord]:
        """A copy of the fault log so far: complete once :meth:`stop` has returned (once
        finished, only frames a host has still not read when the port closes are added)."""
        return list(self._log)

    def write_time_ns(self, seq: int) -> int | None:
        """When frame ``seq`` (unwrapped) began to be written to the port, on the
        ``time.perf_counter_ns()`` clock (system-wide monotonic on Linux); None for a frame not
        written (yet) or older than the last 65,536 frames."""
        slot = seq % _WRITE_TIMES
        if self._write_seq[slot] != seq:
            return None
        return int(self._write_ns[slot])

    @property
    def wire_values_mm(self) -> np.ndarray:
        """(M, S) values as frame ``k`` carries them (row ``k % M``): after value-level
        effects and quantisation to 0.01 mm, in mm."""
        return self._raw * MM_PER_LSB

    @property
    def clipped_values(self) -> int:
        """Values outside 0..655.35 mm that were clipped to the wire's range."""
        return self._clipped

    # ---- preparation -----------------------------------------------------------------
    def _frame_count(self, n_values: int, loop: bool, duration_s: float | None) -> int | None:
        by_duration = None if duration_s is None else max(1, round(duration_s * self.rate_hz))
        if loop:
            return by_duration
        return n_values if by_duration is None else min(n_values, by_duration)

    def _prepare(self, values: np.ndarray, loop: bool) -> tuple[np.ndarray, np.ndarray]:
        """Apply value-level effects and quantise to wire units: (raw (M, S), keep (M,))."""
        if loop and self.n_frames is not None:
            values = np.resize(values, (self.n_frames, values.shape[1]))
        elif self.n_frames is not None:
            values = values[: self.n_frames]
        keep = np.ones(values.shape[0], dtype=bool)
        if self.plan.value_effects:
            t = np.arange(values.shape[0]) / self.rate_hz
            signal = self.plan.effect_chain.apply(Signal(t=t, values=values, keep=keep), self.seed)
            values, keep = signal.values, signal.keep
        raw = np.rint(values / MM_PER_LSB)
        self._clipped = int(np.count_nonzero((raw < 0) | (raw > 0xFFFF) | ~np.isfinite(raw)))
        raw = np.clip(np.nan_to_num(raw, nan=0.0), 0, 0xFFFF).astype(np.int64)
        return raw, keep

    # ---- the device loop ---------------------------------------------------------------
    def _log_fault(self, seq: int, kind: str, **details: Any) -> None:
        self._log.append(FaultRecord(seq=seq, kind=kind, details=details))

    def _run(self) -> None:
        if self.realtime:
            self.realtime_error = request_realtime()
        try:
            self._port.connect()
        except BaseException as exc:  # reported by start()
            self.error = exc
            self._ready.set()
            return
        self._ready.set()
        try:
            self._go.wait()
            while (self._when_attached and not self._stop.is_set()
                   and not self._port.host_attached()):
                self._stop.wait(_ATTACH_POLL_S)
            if not self._stop.is_set():
                self._stream()
            if self._port.connected and self._port.host_attached():
                self._port.drain(self.drain_timeout_s)
        except BaseException as exc:
            self.error = exc
        finally:
            self._finished.set()
        while not self._stop.wait(_IDLE_POLL_S):
            if self._port.connected:
                self._port.flush_pending()

    def _stream(self) -> None:
        injector = FrameFaultInjector(self.plan.frame_faults, self.seed, self.rate_hz)
        for effect in self.plan.value_effects:
            self._log_fault(self.seq0, "effect", name=effect.name, params=vars(effect).copy())
        held: list[tuple[int, bytes]] = []
        stall_window: int | None = None
        self._host_ready = self._port.host_attached()  # attached before streaming: settled
        self._attached_at = -math.inf if self._host_ready else None
        period = 1.0 / self.rate_hz
        t0 = time.perf_counter()
        k = 0
        while self.n_frames is None or k < self.n_frames:
            sleep_until(t0 + k * period, self.spin_s, self._stop)
            if self._stop.is_set():
                return
            seq = self.seq0 + k
            self.frames_generated = k + 1
            outage = injector.in_outage(k)
            dropped = injector.drop(k)
            if outage is not None:
                if self._port.connected:
                    for held_seq, _ in held:
                        self._log_fault(held_seq, "disconnect", held_by_stall=True)
                    held.clear()
                    self._go_offline()
                self._log_fault(seq, "disconnect", at_s=outage.at_s, for_s=outage.for_s)
                k += 1
                continue
            if not self._port.connected:
                self._port.connect()
                self._attached_at = None
                self._host_ready = False
            row = k % self._raw.shape[0]
            if dropped is not None or not self._keep[row] or not self._present[row]:
                if dropped is not None:
                    details = dropped
                elif not self._present[row]:
                    details = {"reason": "absent from the recording"}
                else:
                    details = {"effect": "dropout"}
                self._log_fault(seq, "drop", **details)
                k += 1
                continue
            frame = WireFrame(seq=seq % SEQ_MODULUS,
                              t_us=(self.t_us0 + round(k * 1e6 / self.rate_hz)) % TIME_MODULUS_US,
                              raw=tuple(int(v) for v in self._raw[row]))
            data, applied = injector.mangle(encode_frame(frame))
            for kind, details in applied:
                self._log_fault(seq, kind, **details)
            stall = injector.stall_window(k)
            if stall is not None:
                if stall[0] != stall_window:
                    self._release(held, stall_window)
                    stall_window = stall[0]
                held.append((seq, data))
                k += 1
                continue
            self._release(held, stall_window)
            stall_window = None
            self._deliver(seq, data)
            k += 1
        self._release(held, stall_window)

    def _release(self, held: list[tuple[int, bytes]], window: int | None) -> None:
        """Send the frames held by a stall in one burst."""
        if not held:
            return
        self._log_fault(held[0][0], "stall", window=window, frames_held=len(held),
                        duration_ms=round(len(held) * 1000.0 / self.rate_hz, 3))
        for seq, data in held:
            self._deliver(seq, data)
        held.clear()

    def _go_offline(self) -> None:
        """Disconnect: let the host read what it already has, then make the port vanish."""
        if self._port.host_attached() and not self._port.drain(self.drain_timeout_s):
            self._log_unread("disconnect", in_flight=True)
        lost = self._port.disconnect()
        if lost is not None:
            self._log_fault(lost, "disconnect", in_flight=True)
        self._recent.clear()  # written to a port that is gone

    def _log_unread(self, kind: str, **details: Any) -> None:
        """Take the bytes the host has not read out of the port and log the frames it can
        no longer receive whole as ``kind`` (:func:`_frames_not_received`): the port is
        about to vanish. Without a second open of the slave only a frame whose tail was
        never written is logged."""
        pieces = self._port.take_unread() or []
        unsent = self._port.pending_bytes
        self._port.discard_pending()
        for seq in _frames_not_received(list(self._recent), pieces, unsent):
            self._log_fault(seq, kind, **details)

    def _deliver(self, seq: int, data: bytes) -> None:
        if not self._port.host_attached():
            if self._attached_at is not None:
                lost = self._port.discard_pending()
                if lost is not None:
                    self._log_fault(lost, "not_read", reason=_HOST_CLOSED)
            self._attached_at = None
            self._host_ready = False
            self._log_fault(seq, "not_read", reason="no host")
            return
        now = time.perf_counter()
        if self._attached_at is None:
            self._attached_at = now
        flushed = self._port.host_flushed()
        if not self._host_ready:
            self._host_ready = flushed or now >= self._attached_at + self.attach_grace_s
            if not self._host_ready:
                self._log_fault(seq, "not_read", reason="host attaching")
                return
        slot = seq % _WRITE_TIMES
        self._write_ns[slot] = time.perf_counter_ns()
        self._write_seq[slot] = seq
        if not self._port.send(data, seq):
            self._log_fault(seq, "not_read", reason="buffer full")
            return
        self.frames_written += 1
        self.bytes_written += len(data)
        self._recent.append((seq, data))
        if self.send_times is not None:
            self.send_times.append((seq, time.perf_counter_ns()))


def _lost_after_written(record: FaultRecord) -> bool:
    """Whether ``record`` logs a frame lost after it was written to the port."""
    return ((record.kind == "disconnect" and bool(record.details.get("in_flight")))
            or (record.kind == "not_read"
                and record.details.get("reason") in (_PORT_CLOSED, _HOST_CLOSED)))


def _frames_not_received(recent: list[tuple[int, bytes]], pieces: list[bytes],
                         unsent: int) -> list[int]:
    """Of the frames ``recent`` ((seq, bytes), in the order written; the last one's final
    ``unsent`` bytes never written), the seqs of those a host cannot have received whole,
    ascending: each with a byte among ``pieces`` (what was read out of the port, in order;
    the host may have read between them) and the one not all written.

    Each piece is found in the bytes written, searching back from where the next piece
    starts (the last from the end): a frame carries its seq and time, so a piece of a
    frame's length or more is found in one place only. A piece not found is taken to end
    where the next one starts. So a host that reads while the port is emptied neither
    loses frames the log misses nor has frames it decoded logged lost: a frame it read
    whole between two pieces has no byte in either, and one cut by a piece is logged."""
    stream = b"".join(data for _, data in recent)
    stream = stream[:len(stream) - unsent]
    ends = np.cumsum([len(data) for _, data in recent])  # frame k ends before byte ends[k]
    lost = {len(recent) - 1} if unsent and recent else set()
    end = len(stream)
    for piece in reversed(pieces):
        at = stream.rfind(piece, 0, end)
        if at < 0:
            at = max(0, end - len(piece))
        first, last = np.searchsorted(ends, [at, at + len(piece) - 1], side="right")
        lost.update(range(int(first), min(int(last), len(recent) - 1) + 1))
        end = at
    return [recent[k][0] for k in sorted(lost)]


def _on_sequence_grid(seq: np.ndarray, values: np.ndarray,
                      limit: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A recording's sensor rows spread over every sequence number from its first to its last
    (or over its first ``limit`` sequence numbers, when fewer): ((P, S) values, (P,) present).
    Rows the recording lacks are interpolated (so value effects such as filters see a smooth
    signal) and marked absent; they are never sent."""
    offsets = np.asarray(seq, dtype=np.int64) - int(seq[0])
    size = int(offsets[-1]) + 1
    if limit is not None and limit < size:
        # the rows up to the first at or past the limit interpolate every row before it
        end = int(np.searchsorted(offsets, limit)) + 1
        offsets, values, size = offsets[:end], values[:end], limit
    grid = np.arange(size)
    present = np.zeros(size, dtype=bool)
    present[offsets[offsets < size]] = True
    filled = np.column_stack([np.interp(grid, offsets, values[:, i])
                              for i in range(values.shape[1])])
    return filled, present
