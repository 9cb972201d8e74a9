"""Byte stream → frames: delimiter splitting, validation, resynchronisation, unwrapping.

Pure and single-threaded (the acquisition thread owns one); counts into a :class:`LinkStats`.
Unwrapping: each valid frame advances the sequence number by ``(seq - prev) mod 65536``
(a gap of ``d - 1`` frames when ``d > 1``; ``d == 0`` is a duplicate and is discarded), and
the device time by ``(t_us - prev) mod 2**32`` µs. A gap of 65536 frames or more (262 s at
250 Hz) aliases, as does a device that restarts its counters; both are documented limits.
"""

from __future__ import annotations

import time

from exohil.formats.wire import (
    MAX_PACKET_SIZE,
    SEQ_MODULUS,
    TIME_MODULUS_US,
    CrcError,
    WireError,
    decode_packet,
)
from exohil.harness.frame_source import Frame, LinkStats


class StreamDecoder:
    """Feed raw bytes, get validated frames; garbage is skipped up to the next 0x00."""

    def __init__(self, stats: LinkStats, expected_sensors: int | None = None) -> None:
        self._stats = stats
        self._expected = expected_sensors
        self._partial = bytearray()
        self._discarding = False
        self._seq: int | None = None
        self._wire_seq = 0
        self._time_us = 0
        self._wire_time_us = 0

    def feed(self, data: bytes, host_ns: int) -> list[Frame]:
        """Decode the complete packets in ``data`` (read at ``host_ns``); keep the tail."""
        self._stats.bytes_read += len(data)
        self._partial += data
        *packets, tail = self._partial.split(b"\x00")
        self._partial = bytearray(tail)
        frames = [f for f in (self._decode(bytes(p), host_ns) for p in packets) if f is not None]
        if len(self._partial) > MAX_PACKET_SIZE:  # no delimiter in sight: drop and re-lock
            self._reject_bytes(len(self._partial))
            self._partial.clear()
            self._discarding = True
        return frames

    def reset(self) -> None:
        """Forget a partial packet (after a reconnect the byte stream starts afresh)."""
        if self._partial:
            self._reject_bytes(len(self._partial))
        self._partial.clear()
        self._discarding = False

    def _reject_bytes(self, n: int) -> None:
        self._stats.garbage_bytes += n
        self._stats.resyncs += 1

    def _decode(self, packet: bytes, host_ns: int) -> Frame | None:
        if self._discarding:  # the end of an over-long run already counted as a resync
            self._stats.garbage_bytes += len(packet)
            self._discarding = False
            return None
        if not packet:
            return None
        try:
            wire = decode_packet(packet, self._expected)
        except CrcError:
            self._stats.crc_errors += 1
            self._reject_bytes(len(packet) + 1)
            return None
        except WireError:
            self._stats.decode_errors += 1
            self._reject_bytes(len(packet) + 1)
            return None
        if self._seq is None:
            self._seq, self._time_us = wire.seq, wire.t_us
        else:
            step = (wire.seq - self._wire_seq) % SEQ_MODULUS
            if step == 0:
                self._stats.duplicates += 1
                return None
            self._stats.dropped += step - 1
            self._seq += step
            self._time_us += (wire.t_us - self._wire_time_us) % TIME_MODULUS_US
        self._wire_seq, self._wire_time_us = wire.seq, wire.t_us
        self._stats.frames += 1
        return Frame(seq=self._seq, device_time_s=self._time_us / 1e6,
                     values_mm=wire.values_mm, host_ns=host_ns,
                     decoded_ns=time.perf_counter_ns())
