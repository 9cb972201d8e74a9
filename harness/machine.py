"""The machine a benchmark, a demo or a conformance run ran on, for its report, and the
memory a long job may still take on it."""

from __future__ import annotations

import os
import platform


def cpu_model() -> str:
    """CPU model name from /proc/cpuinfo (Linux), else what platform reports."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def machine() -> str:
    """Platform, CPU model, core count and Python version on one line."""
    return (f"{platform.platform()}; {cpu_model()}; {os.cpu_count()} cores; "
            f"python {platform.python_version()}")


def available_memory_bytes() -> int | None:
    """Memory the kernel estimates a new job can take without swapping (``MemAvailable`` of
    /proc/meminfo, Linux), bytes; None where it does not say."""
    try:
        with open("/proc/meminfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024  # kB
    except (OSError, ValueError, IndexError):
        pass
    return None
