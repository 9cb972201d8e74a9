"""Candidates and cases in processes: in order, one BLAS thread each, never nested."""

from __future__ import annotations

import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from cli_interrupt import sigint_handled_by, started_with_sigint
from threadpoolctl import threadpool_info

from exohil.emulators.discrepancy.workers import (
    default_workers,
    forked_map,
    glibc,
    memory_reused,
    one_blas_thread,
    workers_for,
)


def _blas_threads() -> list[int]:
    return [pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"]


def _page_faults_to_fill(megabytes: int) -> int:
    """Minor page faults this process takes to make and fill an array of ``megabytes``."""
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    np.empty(megabytes * 2**20 // 8).fill(1.0)  # freed at once
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before


def _resident_mb() -> float:
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


@pytest.mark.skipif(glibc() is None, reason="the C library is not glibc")
def test_memory_freed_inside_the_block_is_reused_and_given_back_after_it():
    _page_faults_to_fill(64)
    assert _page_faults_to_fill(64) > 0  # by default every large array is mapped afresh
    with memory_reused():
        with memory_reused():  # nested: the outer block's settings hold
            pass
        _page_faults_to_fill(64)
        assert _page_faults_to_fill(64) == 0  # the freed array's memory, written before
        held = _resident_mb()
        _page_faults_to_fill(256)
        assert _resident_mb() > held + 150  # freed (64 MB of it held before), yet kept
    assert _resident_mb() < held + 50  # given back on leaving
    assert _page_faults_to_fill(64) > 0  # and mapped afresh again
    first, second = memory_reused(), memory_reused()  # overlapping, as two threads' are
    first.__enter__()
    second.__enter__()
    first.__exit__(None, None, None)
    _page_faults_to_fill(64)
    assert _page_faults_to_fill(64) == 0  # the second block still holds
    second.__exit__(None, None, None)
    assert _page_faults_to_fill(64) > 0


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


CTRL_C_WHILE_THE_WORKERS_RUN = """
import os, sys, time
import exohil.emulators.discrepancy as discrepancy
from exohil.emulators.discrepancy.workers import forked_map
from exohil.harness.cli import main

def job(k):
    os.write(1, b"idle\\n" if k == 0 else b"busy\\n")  # the idle worker waits for its next job
    time.sleep(30 * k)
    return k

def analysis(*args, **kwargs):
    forked_map(job, [1, 0], workers=2)

discrepancy.run = analysis
main(["discrepancy", sys.argv[1], "--out", sys.argv[2]])
"""


@pytest.mark.skipif(sys.platform != "linux", reason="only Linux forks the workers")
def test_ctrl_c_while_the_workers_run_stops_at_once_with_one_line(tmp_path):
    """Ctrl-C at a terminal signals the whole process group, forked workers included: the
    busy worker abandons its job and the idle one waits on silently (until 2026-12-07 a
    worker waiting for its next job printed its KeyboardInterrupt's traceback), and
    ``exohil discrepancy`` stops at once with its one line."""
    from exohil.emulators.discrepancy.hidden import Case, make_recording
    from exohil.formats.recording_writer import write_recording

    path, out = tmp_path / "trial.mcap", tmp_path / "out"
    write_recording(path, make_recording(Case("clean", "lib", 1, seed=3, duration_s=12.0)))
    script = tmp_path / "ctrl_c.py"
    script.write_text(CTRL_C_WHILE_THE_WORKERS_RUN)
    proc = subprocess.Popen(started_with_sigint(signal.SIG_DFL,  # as at a terminal
                                                [sys.executable, str(script), str(path),
                                                 str(out)]),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    try:
        assert proc.stdout is not None
        assert {proc.stdout.readline(), proc.stdout.readline()} == {"busy\n", "idle\n"}
        time.sleep(0.5)  # the idle worker is back waiting on the pool's queue
        started = time.monotonic()
        os.killpg(proc.pid, signal.SIGINT)  # what the terminal sends on Ctrl-C
        _, err = proc.communicate(timeout=20)  # far less than the busy worker's 30 s
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 130, err
    assert err == f"interrupted: {out} left as it was (no output of this run written)\n", err
    assert time.monotonic() - started < 10 and not out.exists()


@pytest.mark.skipif(sys.platform != "linux", reason="only Linux forks the workers")
def test_a_sigint_to_this_process_alone_is_raised_once_the_pool_is_down(tmp_path):
    """The KeyboardInterrupt is raised when the map ends, by the handler that was there, and
    never inside the process pool's own code (raised there it was lost in a fork's hooks,
    or left the pool waiting forever): sent to this process alone, the workers finish
    every job, those not yet started included (until 2026-12-07 they were cancelled)."""
    def job(k: int) -> int:
        if k == 0:
            os.kill(os.getppid(), signal.SIGINT)
        time.sleep(0.2)
        (tmp_path / str(k)).touch()
        return k

    with sigint_handled_by(signal.default_int_handler):
        with pytest.raises(KeyboardInterrupt):
            forked_map(job, [0, 1, 2, 3, 4, 5], workers=2)
        assert sorted(p.name for p in tmp_path.iterdir()) == ["0", "1", "2", "3", "4", "5"]
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
        assert forked_map(job, [1, 2], workers=2) == [1, 2]  # no SIGINT: no KeyboardInterrupt


@pytest.mark.skipif(sys.platform != "linux", reason="only Linux forks the workers")
def test_where_this_process_ignores_sigint_its_workers_ignore_it_too(tmp_path):
    """A SIGINT to this process and to the worker running a job changes nothing where this
    process ignores SIGINT: every job ends and nothing is raised (until 2026-12-07 the
    worker's job was abandoned and the map raised ``KeyboardInterrupt``)."""
    def job(k: int) -> int:
        if k == 0:
            os.kill(os.getppid(), signal.SIGINT)
            os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.2)
        (tmp_path / str(k)).touch()
        return k

    with sigint_handled_by(signal.SIG_IGN):
        try:
            done = forked_map(job, [0, 1, 2, 3], workers=2)
        except KeyboardInterrupt:  # fail this test, rather than end pytest's whole run
            pytest.fail("the map raised KeyboardInterrupt")
        assert done == [0, 1, 2, 3]
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    assert sorted(p.name for p in tmp_path.iterdir()) == ["0", "1", "2", "3"]
