"""Fault injection for the Arduino emulator: what can go wrong between the sensors and the host.

Two levels (docs/emulator.md):

* value level: any effect of :mod:`exohil.emulators.effects` (``noise``, ``creep``, ``drift``,
  ``dropout``, ...) applied to the whole value series (mm) before replay;
* frame and byte level, decided per frame while sending: ``drop`` (frames never sent, in
  bursts), ``corrupt`` (one byte of the encoded frame changed), ``truncate`` (the frame is
  cut short and the delimiter follows), ``stall`` (sending pauses, then the held frames go out
  in one burst: a USB hiccup, nothing lost) and ``disconnect`` (the port vanishes for a while).

Every injected fault is logged as a :class:`FaultRecord` keyed by the frame's unwrapped
sequence number, so a test can reconcile exactly which frames the host should have seen.
Each fault draws from its own generator derived from ``(seed, kind, occurrence)``, so adding
one fault never reseeds another.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from exohil.emulators.seeding import keyed_rng
from exohil.formats.wire import DELIMITER, WireError, decode_packet

# Fault kinds whose frames never reach the host intact (the reconciliation set).
LOSING_KINDS = frozenset({"drop", "corrupt", "truncate", "disconnect", "not_read"})


@dataclass(frozen=True)
class FaultRecord:
    """One injected fault.

    Attributes:
        seq: the affected frame's unwrapped sequence number (``seq0 + frame index``).
        kind: ``drop``, ``corrupt``, ``truncate``, ``stall``, ``disconnect``, ``not_read``
            (the emulator could not hand the frame over: no host, host attaching, buffer
            full) or ``effect`` (a value-level effect, logged once at the first frame).
        details: kind-specific parameters (byte offset, burst length, reason, ...).
    """

    seq: int
    kind: str
    details: dict[str, Any] = field(default_factory=dict)


def _check(condition: bool, message: str) -> None:
    if not condition:
        raise ValueError(message)


@dataclass
class Drop:
    """Frames never sent: each frame starts a burst of ``burst`` dropped frames with
    probability ``rate`` (per frame, 0..1)."""

    kind = "drop"
    rate: float = 0.01
    burst: int = 1

    def __post_init__(self) -> None:
        _check(0.0 <= self.rate <= 1.0, "drop: rate must be in [0, 1]")
        _check(int(self.burst) == self.burst and self.burst >= 1, "drop: burst must be >= 1")


@dataclass
class Corrupt:
    """One byte of the encoded frame (delimiter excluded) XORed with a random non-zero mask,
    with probability ``rate`` per frame. Only corruptions the protocol detects are injected
    (one that would still decode, p ~ 2**-16, is redrawn), so the log is exact."""

    kind = "corrupt"
    rate: float = 0.001

    def __post_init__(self) -> None:
        _check(0.0 <= self.rate <= 1.0, "corrupt: rate must be in [0, 1]")


@dataclass
class Truncate:
    """With probability ``rate`` per frame, only the first 1..len-1 encoded bytes are sent,
    then the delimiter (a frame aborted mid-way)."""

    kind = "truncate"
    rate: float = 0.001

    def __post_init__(self) -> None:
        _check(0.0 <= self.rate <= 1.0, "truncate: rate must be in [0, 1]")


@dataclass
class Stall:
    """Sending pauses for ``duration_ms`` every ``every_s`` seconds of device time (first at
    ``every_s``); frames sampled meanwhile are held and sent in one burst afterwards."""

    kind = "stall"
    every_s: float = 5.0
    duration_ms: float = 40.0

    def __post_init__(self) -> None:
        _check(self.every_s > 0, "stall: every_s must be > 0")
        _check(0 < self.duration_ms < self.every_s * 1000.0,
               "stall: duration_ms must be > 0 and shorter than every_s")


@dataclass
class Disconnect:
    """The port vanishes at ``at_s`` seconds of device time for ``for_s`` seconds (USB cable
    pulled and re-plugged): the host sees EIO, the device path disappears, frames sampled
    meanwhile are lost, then a fresh port appears at the same path."""

    kind = "disconnect"
    at_s: float = 10.0
    for_s: float = 0.5

    def __post_init__(self) -> None:
        _check(self.at_s >= 0, "disconnect: at_s must be >= 0")
        _check(self.for_s > 0, "disconnect: for_s must be > 0")


FRAME_FAULT_TYPES: dict[str, type] = {
    cls.kind: cls for cls in (Drop, Corrupt, Truncate, Stall, Disconnect)
}
FrameFault = Drop | Corrupt | Truncate | Stall | Disconnect


def _is_detectable(sent: bytes) -> bool:
    """True when no packet in ``sent`` (bytes ending in the delimiter) decodes as a frame."""
    for packet in sent[:-1].split(bytes([DELIMITER])):
        if not packet:
            continue
        try:
            decode_packet(packet)
        except WireError:
            continue
        return False
    return True


class FrameFaultInjector:
    """Per-frame decisions of the frame/byte-level faults of a plan, in frame order.

    Every fault draws its per-frame decision for every frame (so the decisions of one fault
    do not depend on the others); details (byte offsets, masks) come from a second generator.
    Frame ``k`` is sampled at device time ``k / rate_hz`` seconds.
    """

    def __init__(self, faults: list[FrameFault], seed: int, rate_hz: float) -> None:
        self._rate_hz = rate_hz
        occurrences: dict[str, int] = {}
        self._faults: list[tuple[FrameFault, np.random.Generator, np.random.Generator]] = []
        for fault in faults:
            n = occurrences.get(fault.kind, 0)
            occurrences[fault.kind] = n + 1
            decide = keyed_rng(seed, fault.kind, 2 * n)
            detail = keyed_rng(seed, fault.kind, 2 * n + 1)
            self._faults.append((fault, decide, detail))
        self._burst_left = [0] * len(self._faults)

    def _first_frame_at(self, t_s: float) -> int:
        """Index of the first frame sampled at or after ``t_s`` (robust to float rounding)."""
        return math.ceil(t_s * self._rate_hz - 1e-6)

    def in_outage(self, k: int) -> Disconnect | None:
        """The disconnect whose outage covers frame ``k``, if any."""
        for fault, _, _ in self._faults:
            if (isinstance(fault, Disconnect)
                    and self._first_frame_at(fault.at_s) <= k
                    < self._first_frame_at(fault.at_s + fault.for_s)):
                return fault
        return None

    def stall_window(self, k: int) -> tuple[int, Stall] | None:
        """(window index, stall) when frame ``k`` is held by a stall."""
        for fault, _, _ in self._faults:
            if not isinstance(fault, Stall):
                continue
            latest = int((k + 0.5) // (fault.every_s * self._rate_hz))
            for index in (latest, latest - 1):
                start_s = index * fault.every_s
                if (index >= 1 and self._first_frame_at(start_s) <= k
                        < self._first_frame_at(start_s + fault.duration_ms / 1000.0)):
                    return index, fault
        return None

    def drop(self, k: int) -> dict[str, Any] | None:
        """Draw this frame's drop decisions; details of the drop that hits it, if any."""
        hit: dict[str, Any] | None = None
        for i, (fault, decide, _) in enumerate(self._faults):
            if not isinstance(fault, Drop):
                continue
            starts = bool(decide.random() < fault.rate)
            if self._burst_left[i] > 0:
                self._burst_left[i] -= 1
                hit = hit or {"burst": fault.burst}
            elif starts:
                self._burst_left[i] = fault.burst - 1
                hit = hit or {"burst": fault.burst, "burst_start": True}
        return hit

    def mangle(self, sent: bytes) -> tuple[bytes, list[tuple[str, dict[str, Any]]]]:
        """Apply this frame's corrupt/truncate decisions to ``sent`` (an encoded frame with
        its delimiter); returns the bytes to send and (kind, details) of each fault applied."""
        applied: list[tuple[str, dict[str, Any]]] = []
        for fault, decide, detail in self._faults:
            if isinstance(fault, Corrupt) and decide.random() < fault.rate:
                sent, info = _corrupt(sent, detail)
                applied.append(("corrupt", info))
            elif isinstance(fault, Truncate) and decide.random() < fault.rate:
                sent, info = _truncate(sent, detail)
                applied.append(("truncate", info))
        return sent, applied


_MAX_REDRAWS = 64


def _corrupt(sent: bytes, rng: np.random.Generator) -> tuple[bytes, dict[str, Any]]:
    for _ in range(_MAX_REDRAWS):
        offset = int(rng.integers(0, len(sent) - 1))
        mask = int(rng.integers(1, 256))
        mangled = bytearray(sent)
        mangled[offset] ^= mask
        if _is_detectable(bytes(mangled)):
            return bytes(mangled), {"offset": offset, "xor": mask}
    raise RuntimeError("could not draw a detectable corruption")  # p < 2**-1000


def _truncate(sent: bytes, rng: np.random.Generator) -> tuple[bytes, dict[str, Any]]:
    encoded = len(sent) - 1
    for _ in range(_MAX_REDRAWS):
        keep = int(rng.integers(1, encoded)) if encoded > 1 else 0
        cut = sent[:keep] + bytes([DELIMITER])
        if _is_detectable(cut):
            return cut, {"kept_bytes": keep, "of_bytes": encoded}
    raise RuntimeError("could not draw a detectable truncation")
