"""Byte stream → frames: delimiter splitting, validation, resynchronisation, unwrapping.

Pure and single-threaded (the acquisition thread owns one); counts into a :class:`LinkStats`.

Unwrapping and plausibility (docs/reliability.md). The device's sequence number and device
time advance together (one period per sampled frame), so a frame's step from the last accepted
frame is judged by both: with ``d = (seq - prev) mod 65536`` frames and
``dt = (t_us - prev) mod 2**32`` µs,

* ``dt`` must be forward in serial arithmetic (``0 < dt < 2**31`` µs, i.e. under 35.8 min):
  a stale frame (an older one replayed, or reordered) goes back in time and is rejected;
* once the period ``P`` is known (the mean µs per frame over the accepted frames of the
  current numbering), the frame count is ``d + 65536·m`` with the ``m ≥ 0`` that best fits
  ``dt / P``, and it must fit within ``TOL_PERIODS·P·(1 + count/span)`` µs (endpoint jitter,
  plus the uncertainty of ``P`` measured over ``span`` frames); so a long disconnect is
  accepted whatever its length, even past the 65536-frame sequence wrap, while a header whose
  sequence number disagrees with its time is not. An aliased gap (``m ≥ 1``, 262 s or more at
  250 Hz) is also checked against the host clock: at least half of it must have passed there;
* before ``P`` is known (the second frame of a numbering) the sequence step must be forward
  (``0 < d < 32768``).

A frame that passes is delivered (``d - 1`` frames counted ``dropped``). An exact repeat of one
of the last 1024 accepted frames, or one whose sequence number did not advance, is a
``duplicate``. A frame up to ``LATE_FRAMES`` behind the last accepted one, in sequence and time
alike, arrived late and is ``implausible``. Any other valid-CRC frame is held as a candidate for
a new numbering (a device reset restarts both counters): once ``RESYNC_FRAMES`` consecutive
candidates step consistently with each other, the new numbering is taken (``sequence_resets``)
and they are delivered, continuing the host's numbering (sequence +1, device time + the host
time elapsed; the frames that host time holds at the old period, less one, are counted
``dropped_in_resets``); candidates that never make such a run are ``implausible`` and discarded.
Delivered sequence numbers and device times therefore always increase strictly.
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass

from exohil.formats.wire import (
    MAX_PACKET_SIZE,
    SEQ_MODULUS,
    TIME_MODULUS_US,
    CrcError,
    WireError,
    WireFrame,
    decode_packet,
)
from exohil.harness.frame_source import Frame, LinkStats

#: Allowed disagreement between a step's device time and its frame count, in periods (the
#: timestamp jitter of the two frames compared; the firmware stamps ``micros()`` at sampling).
TOL_PERIODS = 4.0
#: Consecutive mutually consistent frames on a new numbering that make it accepted.
RESYNC_FRAMES = 3
#: Largest sequence step between two candidates of a new numbering, frames.
MAX_CANDIDATE_STEP = 64
#: Accepted frames remembered to recognise exact repeats.
RECENT_FRAMES = 1024
#: A frame this many frames or fewer behind the last accepted one, in sequence and time alike,
#: is a late frame of the current numbering (discarded), never the start of a new one.
LATE_FRAMES = 256

_HALF_SEQ = SEQ_MODULUS // 2
_HALF_TIME_US = TIME_MODULUS_US // 2


@dataclass(frozen=True)
class _Accepted:
    """The last accepted frame: wire fields, unwrapped counters, host receive time (ns)."""

    wire_seq: int
    wire_t_us: int
    seq: int
    time_us: int
    host_ns: int


class StreamDecoder:
    """Feed raw bytes, get validated, plausible frames; garbage is skipped up to the next 0x00.

    See the module doc for the plausibility rule.
    """

    def __init__(self, stats: LinkStats, expected_sensors: int | None = None) -> None:
        self._stats = stats
        self._expected = expected_sensors
        self._partial = bytearray()
        self._discarding = False
        self._last: _Accepted | None = None
        self._origin: tuple[int, int] = (0, 0)  # (seq, time_us) where this numbering began
        self._recent: deque[tuple[int, int]] = deque(maxlen=RECENT_FRAMES)
        self._recent_set: set[tuple[int, int]] = set()
        self._candidates: list[tuple[WireFrame, int]] = []
        self._after_disconnect = False

    @property
    def pending(self) -> int:
        """Valid frames held as candidates for a new numbering (neither delivered nor
        counted yet)."""
        return len(self._candidates)

    def feed(self, data: bytes, host_ns: int) -> list[Frame]:
        """Decode the complete packets in ``data`` (read at ``host_ns``); keep the tail."""
        self._stats.bytes_read += len(data)
        self._partial += data
        *packets, tail = self._partial.split(b"\x00")
        self._partial = bytearray(tail)
        frames: list[Frame] = []
        for packet in packets:
            frames += self._decode(bytes(packet), host_ns)
        if len(self._partial) > MAX_PACKET_SIZE:  # no delimiter in sight: drop and re-lock
            self._discard(len(self._partial))
            self._partial.clear()
        return frames

    def reset(self) -> None:
        """Forget a partial packet (after a reconnect the byte stream starts afresh); the
        next gap in the numbering is also counted in ``dropped_in_disconnects``."""
        if self._partial:
            self._discard(len(self._partial))
        self._partial.clear()
        self._discarding = False
        self._after_disconnect = self._last is not None

    def _discard(self, n: int) -> None:
        """Drop ``n`` bytes of a run with no delimiter yet: one resync per run, however the
        run arrives in chunks; its bytes all count as garbage (the closing delimiter too, in
        :meth:`_decode`, as on the reject path)."""
        if self._discarding:
            self._stats.garbage_bytes += n
        else:
            self._reject_bytes(n)
        self._discarding = True

    def _reject_bytes(self, n: int) -> None:
        self._stats.garbage_bytes += n
        self._stats.resyncs += 1

    def _decode(self, packet: bytes, host_ns: int) -> list[Frame]:
        if self._discarding:  # the end of an over-long run already counted as a resync
            self._stats.garbage_bytes += len(packet) + 1  # its closing delimiter included
            self._discarding = False
            return []
        if not packet:
            return []
        try:
            wire = decode_packet(packet, self._expected)
        except CrcError:
            self._stats.crc_errors += 1
            self._reject_bytes(len(packet) + 1)
            return []
        except WireError:
            self._stats.decode_errors += 1
            self._reject_bytes(len(packet) + 1)
            return []
        return self._sequence(wire, host_ns)

    # ---- plausibility and unwrapping ---------------------------------------------------
    def _sequence(self, wire: WireFrame, host_ns: int) -> list[Frame]:
        last = self._last
        if last is None:
            self._origin = (wire.seq, wire.t_us)
            return [self._accept(wire, host_ns, wire.seq, wire.t_us)]
        if (wire.seq, wire.t_us) in self._recent_set:
            self._stats.duplicates += 1
            return []
        step = self._plausible_step(last, wire, host_ns)
        if step is not None:
            self._stats.implausible += len(self._candidates)
            self._candidates.clear()
            frames, dt_us = step
            self._stats.dropped += frames - 1
            if self._after_disconnect:
                self._stats.dropped_in_disconnects += frames - 1
            return [self._accept(wire, host_ns, last.seq + frames, last.time_us + dt_us)]
        if (wire.seq - last.wire_seq) % SEQ_MODULUS == 0:
            self._stats.duplicates += 1
            return []
        if self._late(last, wire):
            self._stats.implausible += 1
            return []
        return self._candidate(wire, host_ns)

    def _period_us(self) -> tuple[float, int] | None:
        """(mean µs per frame, frames spanned) over the current numbering; None before its
        second frame."""
        assert self._last is not None
        span = self._last.seq - self._origin[0]
        if span <= 0:
            return None
        return (self._last.time_us - self._origin[1]) / span, span

    def _plausible_step(self, last: _Accepted, wire: WireFrame,
                        host_ns: int) -> tuple[int, int] | None:
        """(frames, µs) advanced from ``last`` to ``wire``, or None when implausible."""
        d = (wire.seq - last.wire_seq) % SEQ_MODULUS
        dt = (wire.t_us - last.wire_t_us) % TIME_MODULUS_US
        if not 0 < dt < _HALF_TIME_US:
            return None
        period = self._period_us()
        if period is None:
            return (d, dt) if 0 < d < _HALF_SEQ else None
        p_us, span = period
        m = max(0, round((dt / p_us - d) / SEQ_MODULUS))
        frames = d + m * SEQ_MODULUS
        if frames == 0:
            return None
        if abs(dt - frames * p_us) > TOL_PERIODS * p_us * (1.0 + frames / span):
            return None
        if m > 0 and host_ns - last.host_ns < dt * 500:  # ns; at least half of dt (µs)
            return None
        return frames, dt

    def _late(self, last: _Accepted, wire: WireFrame) -> bool:
        """Whether ``wire`` is a frame of the current numbering at most LATE_FRAMES behind
        ``last``, in sequence and time alike (it arrived late, e.g. overtaken)."""
        d = (last.wire_seq - wire.seq) % SEQ_MODULUS
        dt = (last.wire_t_us - wire.t_us) % TIME_MODULUS_US
        if not (0 < d <= LATE_FRAMES and 0 < dt < _HALF_TIME_US):
            return False
        period = self._period_us()
        if period is None:
            return True
        p_us, span = period
        return abs(dt - d * p_us) <= TOL_PERIODS * p_us * (1.0 + d / span)

    def _candidate(self, wire: WireFrame, host_ns: int) -> list[Frame]:
        """Hold ``wire`` as a candidate for a new numbering; take the numbering once
        RESYNC_FRAMES consecutive candidates agree."""
        if self._candidates and not _consistent(self._candidates, wire):
            self._stats.implausible += len(self._candidates)
            self._candidates.clear()
        self._candidates.append((wire, host_ns))
        if len(self._candidates) < RESYNC_FRAMES:
            return []
        assert self._last is not None
        last = self._last
        first, first_ns = self._candidates[0]
        period = self._period_us()
        gap_us = max(1, round((first_ns - last.host_ns) / 1000),
                     round(period[0]) if period else 1)
        self._stats.sequence_resets += 1
        if period:  # the frames the device's period fits in the gap, less the one sent
            self._stats.dropped_in_resets += max(0, round(gap_us / period[0]) - 1)
        self._origin = (last.seq + 1, last.time_us + gap_us)
        frames = [self._accept(first, first_ns, *self._origin)]
        for wire_k, ns_k in self._candidates[1:]:
            prev = self._last
            d = (wire_k.seq - prev.wire_seq) % SEQ_MODULUS
            dt = (wire_k.t_us - prev.wire_t_us) % TIME_MODULUS_US
            self._stats.dropped += d - 1
            frames.append(self._accept(wire_k, ns_k, prev.seq + d, prev.time_us + dt))
        self._candidates.clear()
        return frames

    def _accept(self, wire: WireFrame, host_ns: int, seq: int, time_us: int) -> Frame:
        self._last = _Accepted(wire.seq, wire.t_us, seq, time_us, host_ns)
        self._after_disconnect = False
        key = (wire.seq, wire.t_us)
        if len(self._recent) == RECENT_FRAMES:
            self._recent_set.discard(self._recent[0])
        self._recent.append(key)
        self._recent_set.add(key)
        self._stats.frames += 1
        return Frame(seq=seq, device_time_s=time_us / 1e6, values_mm=wire.values_mm,
                     host_ns=host_ns, decoded_ns=time.perf_counter_ns())


def _consistent(candidates: list[tuple[WireFrame, int]], wire: WireFrame) -> bool:
    """Whether ``wire`` continues the run of candidates: forward in sequence (by at most
    MAX_CANDIDATE_STEP) and in time, at the run's own period within TOL_PERIODS."""
    prev = candidates[-1][0]
    d = (wire.seq - prev.seq) % SEQ_MODULUS
    dt = (wire.t_us - prev.t_us) % TIME_MODULUS_US
    if not (0 < d <= MAX_CANDIDATE_STEP and 0 < dt < _HALF_TIME_US):
        return False
    if len(candidates) < 2:
        return True
    first = candidates[0][0]
    span = (prev.seq - first.seq) % SEQ_MODULUS
    p_us = ((prev.t_us - first.t_us) % TIME_MODULUS_US) / span
    return abs(dt - d * p_us) <= TOL_PERIODS * p_us * (1.0 + d / span)
