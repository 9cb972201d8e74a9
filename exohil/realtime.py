"""Real-time scheduling for exohil's time-critical threads (the device emulator's sender and
the acquisition reader). Shared by every layer: it is an operating-system policy, not part of
any one of them."""

from __future__ import annotations

import os

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
