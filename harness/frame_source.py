"""What the pipeline consumes: frames from a device, behind a small protocol.

Following labgrid's Resource → Driver → Protocol split in spirit, the pipeline and the tests
depend only on :class:`FrameSource`; :class:`~exohil.harness.acquisition.SerialFrameSource`
(any pyserial URL: the emulator's pty, ``/dev/ttyACM0``, ``loop://``, ``socket://``) is one
implementation, and a fake device drops straight in.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np


@dataclass(frozen=True)
class Frame:
    """One sensor frame as delivered to the host.

    Attributes:
        seq: sequence number, unwrapped (continues past 65535) from the first frame received.
        device_time_s: device timestamp, seconds, unwrapped past the u32 µs wrap.
        values_mm: (S,) float64 tendon lengths, mm.
        host_ns: host receive time, ``time.perf_counter_ns()`` when its bytes were read.
        decoded_ns: when the frame was decoded and validated (same clock); 0 if not stamped.
    """

    seq: int
    device_time_s: float
    values_mm: np.ndarray
    host_ns: int
    decoded_ns: int = 0


@dataclass
class LinkStats:
    """Counters of one link since ``start()``.

    Attributes:
        frames: frames decoded with a valid CRC and delivered to the buffer.
        dropped: frames missing by sequence number (gaps between delivered frames).
        dropped_in_disconnects: the part of ``dropped`` missing across a disconnect (the
            gap between the last frame before the link was lost and the first after).
        duplicates: frames whose sequence number did not advance, or exact repeats of a
            recent frame (discarded).
        implausible: frames with a valid CRC whose sequence number and device time did not
            fit the stream (stale, far ahead, or disagreeing with each other; discarded, see
            harness/link_decoder.py).
        sequence_resets: times the device's numbering restarted (e.g. a device reset) and
            the host took the new numbering after consecutive consistent frames; the host's
            numbering continues across it.
        dropped_in_resets: frames the device's period says it would have sent between the
            last frame before a sequence reset and the first frame of the new numbering, by
            host time (a reboot, a re-enumeration gap); not in ``dropped``, which counts by
            sequence number and cannot see across a restarted numbering.
        crc_errors: packets whose CRC did not match.
        decode_errors: packets that were not valid COBS or had a wrong length/type.
        garbage_bytes: bytes discarded (rejected packets, partial packets at reconnect,
            over-long runs without a delimiter; a discarded packet's closing delimiter too).
        resyncs: times the decoder discarded data and re-locked on the next delimiter (one
            per rejected packet or per run without a delimiter, however it was chunked).
        disconnects: times the link was lost (read error, the device vanished).
        reconnects: successful re-opens after a disconnect, of the same device.
        wrong_device: re-open attempts refused because the path led to another device
            (e.g. a stale link to a pty that now belongs to someone else).
        overflow: frames discarded because the buffer was full (oldest first).
        bytes_read: bytes read from the link.
    """

    frames: int = 0
    dropped: int = 0
    dropped_in_disconnects: int = 0
    duplicates: int = 0
    implausible: int = 0
    sequence_resets: int = 0
    dropped_in_resets: int = 0
    crc_errors: int = 0
    decode_errors: int = 0
    garbage_bytes: int = 0
    resyncs: int = 0
    disconnects: int = 0
    reconnects: int = 0
    wrong_device: int = 0
    overflow: int = 0
    bytes_read: int = 0


@runtime_checkable
class FrameSource(Protocol):
    """A stream of :class:`Frame` objects fed by a background reader."""

    def start(self) -> None:
        """Begin acquiring (returns promptly; connecting happens in the background)."""

    def stop(self) -> None:
        """Stop acquiring; returns within a bounded time."""

    def get(self, timeout: float | None = None) -> Frame | None:
        """The oldest buffered frame, waiting up to ``timeout`` s; None when none arrived."""

    def stats(self) -> LinkStats:
        """A snapshot of the link counters."""
