"""Candidates and cases in processes: in order, one BLAS thread each, never nested."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from threadpoolctl import threadpool_info

from exohil.emulators.discrepancy.workers import (
    default_workers,
    forked_map,
    one_blas_thread,
    workers_for,
)


def _blas_threads() -> list[int]:
    return [pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"]


def test_forked_jobs_run_in_other_processes_and_come_back_in_order():
    here = os.getpid()
    scale = np.arange(3.0)  # inherited by the fork, never pickled

    def job(k: int) -> tuple[int, float, int]:
        return k, float(scale.sum() * k), os.getpid()

    out = forked_map(job, [3, 1, 2, 0], workers=2)
    assert [k for k, _, _ in out] == [3, 1, 2, 0]
    assert [v for _, v, _ in out] == [9.0, 3.0, 6.0, 0.0]
    if sys.platform == "linux":
        assert all(pid != here for _, _, pid in out)
    assert forked_map(job, [5], workers=2)[0][2] == here  # one item: no process to start
    assert [pid for _, _, pid in forked_map(job, [1, 2], workers=1)] == [here, here]


def test_a_failing_job_raises_its_error_here():
    def job(k: int) -> int:
        if k == 2:
            raise ValueError("no such candidate")
        return k

    with pytest.raises(ValueError, match="no such candidate"):
        forked_map(job, [1, 2, 3], workers=2)
    assert forked_map(job, [1, 3], workers=2) == [1, 3]  # and the next map starts afresh


def test_a_worker_runs_its_own_jobs_in_turn_with_one_blas_thread():
    assert workers_for(3) == 3
    assert workers_for(None) == default_workers()  # this process is no worker
    with pytest.raises(ValueError, match="at least 1"):
        workers_for(0)
    before = _blas_threads()
    with one_blas_thread():
        assert set(_blas_threads()) == {1}
        inside = forked_map(lambda _: (workers_for(None), _blas_threads()), [0, 1], workers=2)
    assert _blas_threads() == before  # restored
    if sys.platform == "linux":
        assert inside == [(1, [1] * len(before))] * 2


@pytest.mark.skipif(sys.platform != "linux", reason="only Linux forks the workers")
def test_forked_workers_end_with_a_killed_parent(tmp_path):
    script = f"""
import os, sys, time
from exohil.emulators.discrepancy.workers import forked_map
def job(k):
    (__import__("pathlib").Path({str(tmp_path)!r}) / f"{{k}}.pid").write_text(str(os.getpid()))
    time.sleep(60)
forked_map(job, [0, 1], workers=2)
"""
    parent = subprocess.Popen([sys.executable, "-c", script])
    try:
        pid_files = [tmp_path / "0.pid", tmp_path / "1.pid"]
        deadline = time.monotonic() + 30
        while not all(f.exists() and f.read_text() for f in pid_files):
            assert time.monotonic() < deadline, "the workers did not start"
            time.sleep(0.05)
        workers = [int(f.read_text()) for f in pid_files]
    finally:
        parent.kill()  # SIGKILL: nothing of the parent's runs after it
        parent.wait()
    deadline = time.monotonic() + 10
    while any(_running(pid) for pid in workers):
        assert time.monotonic() < deadline, "a worker outlived its parent"
        time.sleep(0.05)


def _running(pid: int) -> bool:
    """Whether ``pid`` is a process that is neither gone nor a zombie awaiting its reaper."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except FileNotFoundError:
        return False
    return "State:\tZ" not in status
