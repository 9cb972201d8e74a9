"""Absolute-deadline pacing: sleep until a ``time.perf_counter()`` deadline (seconds).

A pty has no baud rate, so the emulator paces itself: frame k is due at t0 + k / rate.
Coarse ``time.sleep`` gets within ``SPIN_S`` of the deadline, then a short spin on
``perf_counter`` (yielding the GIL with ``sleep(0)``) lands on it. Absolute deadlines mean a
late frame does not shift the ones after it, so the mean rate does not drift.
"""

from __future__ import annotations

import threading
import time

SPIN_S = 0.0003


def sleep_until(deadline_s: float, spin_s: float = SPIN_S,
                cancel: threading.Event | None = None) -> None:
    """Return at (or just after) ``deadline_s`` on the ``time.perf_counter()`` clock, spinning
    for the last ``spin_s`` seconds (a longer spin absorbs later wake-ups, at a CPU cost).
    The coarse wait ends early when ``cancel`` is set (the caller checks it afterwards)."""
    remaining = deadline_s - time.perf_counter()
    if remaining > spin_s:
        if cancel is None:
            time.sleep(remaining - spin_s)
        elif cancel.wait(remaining - spin_s):
            return
    while time.perf_counter() < deadline_s:
        time.sleep(0)
