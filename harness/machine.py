"""The machine a benchmark, a demo or a conformance run ran on, for its report."""

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
