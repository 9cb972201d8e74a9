"""How busy the host was: the load meter the latency check reports beside its figures."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest

from exohil.harness import machine
from exohil.harness.machine import HostLoad, HostLoadMeter


def test_more_busy_processes_than_cores_show_as_cpu_pressure():
    if machine._pressure_stall_us() is None:
        pytest.skip("this kernel reports no pressure stall information")
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"])
            for _ in range(2 * len(os.sched_getaffinity(0)) + 1)]
    try:
        time.sleep(0.3)  # every one of them running
        meter = HostLoadMeter()
        time.sleep(1.0)
        load = meter.stop()
    finally:
        for proc in busy:
            proc.kill()
            proc.wait()
    assert load.cpu_pressure is not None and load.cpu_pressure > 0.5
    assert load.cpu_steal is None or 0.0 <= load.cpu_steal <= 1.0


def test_a_kernel_that_reports_nothing_gives_an_unknown_load(monkeypatch):
    monkeypatch.setattr(machine, "_pressure_stall_us", lambda: None)
    monkeypatch.setattr(machine, "_cpu_jiffies", lambda: None)
    load = HostLoadMeter().stop()
    assert load == HostLoad(None, None)
    assert load.describe() == "CPU pressure unknown, steal unknown"
    assert HostLoad(0.25, 0.0).describe() == "CPU pressure 25 %, steal 0 %"
