"""The machine a benchmark, a demo or a conformance run ran on, for its report, the memory a
long job may still take on it, and how busy its CPUs were while a timed run ran."""

from __future__ import annotations

import os
import platform
import time
from dataclasses import dataclass


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


@dataclass(frozen=True)
class HostLoad:
    """How contended the host's CPUs were over an interval (Linux), as shares of it:

    * ``cpu_pressure``: of the wall time, the share in which at least one runnable task waited
      for a CPU (``some`` of /proc/pressure/cpu, pressure stall information), this process's
      own threads included;
    * ``cpu_steal``: of all CPU time, the share the hypervisor gave to other machines (the
      ``steal`` column of /proc/stat).

    Either is None where the kernel does not report it."""

    cpu_pressure: float | None
    cpu_steal: float | None

    def describe(self) -> str:
        def pct(x: float | None) -> str:
            return "unknown" if x is None else f"{100 * x:.0f} %"
        return f"CPU pressure {pct(self.cpu_pressure)}, steal {pct(self.cpu_steal)}"


def _pressure_stall_us() -> int | None:
    """Total µs in which some task waited for a CPU since boot (/proc/pressure/cpu)."""
    try:
        with open("/proc/pressure/cpu", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("some "):
                    return int(line.rsplit("total=", 1)[1])
    except (OSError, ValueError, IndexError):
        pass
    return None


def _cpu_jiffies() -> tuple[int, int] | None:
    """(steal, total) CPU time since boot, in clock ticks, over every CPU (/proc/stat)."""
    try:
        with open("/proc/stat", encoding="ascii") as fh:
            fields = fh.readline().split()
        if fields[0] != "cpu" or len(fields) < 9:
            return None
        ticks = [int(x) for x in fields[1:9]]  # user nice system idle iowait irq softirq steal
    except (OSError, ValueError, IndexError):
        return None
    return ticks[7], sum(ticks)


class HostLoadMeter:
    """Measures :class:`HostLoad` from construction to :meth:`stop`."""

    def __init__(self) -> None:
        self._wall = time.monotonic()
        self._stall_us = _pressure_stall_us()
        self._jiffies = _cpu_jiffies()

    def stop(self) -> HostLoad:
        wall_s = time.monotonic() - self._wall
        stall_us, jiffies = _pressure_stall_us(), _cpu_jiffies()
        pressure = steal = None
        if self._stall_us is not None and stall_us is not None and wall_s > 0:
            pressure = min(1.0, max(0.0, (stall_us - self._stall_us) / 1e6 / wall_s))
        if self._jiffies is not None and jiffies is not None and jiffies[1] > self._jiffies[1]:
            steal = (jiffies[0] - self._jiffies[0]) / (jiffies[1] - self._jiffies[1])
        return HostLoad(pressure, steal)
