"""Real-time helpers for exohil's time-critical threads (the device emulator's sender, the
acquisition reader, the robot's physics): absolute-deadline pacing and SCHED_FIFO. Shared by
every layer: they are operating-system matters, not part of any one of them.

Pacing: a pty has no baud rate, so the emulator paces itself: frame k is due at t0 + k / rate.
Coarse ``time.sleep`` gets within ``SPIN_S`` of the deadline, then a short spin on
``perf_counter`` (yielding the GIL with ``sleep(0)``) lands on it. Absolute deadlines mean a
late frame does not shift the ones after it, so the mean rate does not drift.
"""

from __future__ import annotations

import os
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


REALTIME_PRIORITY = 10


def request_realtime(priority: int = REALTIME_PRIORITY) -> str | None:
    """Put the calling thread under SCHED_FIFO at ``priority`` (Linux; needs CAP_SYS_NICE).

    Returns None on success, else why not (the thread keeps its normal policy). Opt-in only:
    a SCHED_FIFO thread outranks every normal task on a shared machine.
    """
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (AttributeError, OSError) as exc:
        return f"SCHED_FIFO unavailable: {exc}"
    return None
