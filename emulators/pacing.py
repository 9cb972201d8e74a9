"""Absolute-deadline pacing: sleep until a ``time.perf_counter()`` deadline (seconds).

A pty has no baud rate, so the emulator paces itself: frame k is due at t0 + k / rate.
Coarse ``time.sleep`` gets within ``SPIN_S`` of the deadline, then a short spin on
``perf_counter`` (yielding the GIL with ``sleep(0)``) lands on it. Absolute deadlines mean a
late frame does not shift the ones after it, so the mean rate does not drift.
"""

from __future__ import annotations

import time

SPIN_S = 0.0003


def sleep_until(deadline_s: float) -> None:
    """Return at (or just after) ``deadline_s`` on the ``time.perf_counter()`` clock."""
    remaining = deadline_s - time.perf_counter()
    if remaining > SPIN_S:
        time.sleep(remaining - SPIN_S)
    while time.perf_counter() < deadline_s:
        time.sleep(0)
