"""Independent jobs of the discrepancy workflow run at once, one BLAS thread per process.

Two ways, for two sizes of job:

* :func:`parallel_map` runs whole recordings (the benchmarks' and tests' cases) in spawned
  processes: each job reads its own recording, so nothing but its name travels.
* :func:`forked_map` runs the candidate effects of one workflow step in forked processes:
  they share the step's calibrated trial and model (hundreds of MB of designs and their
  caches), which a fork hands over without copying; only each candidate's fit comes back.

On Ctrl-C (the terminal signals the whole process group) the forked workers abandon their
jobs, and the process that owns the pool raises ``KeyboardInterrupt`` once the pool is down
(:func:`forked_map`).

Either way each process runs one BLAS thread: two OpenBLAS pools of two threads each on two
cores took longer than one process alone (184 s against 130 s for the CI suite's 48 cases;
73 s with one thread each). A process that is itself a worker runs its jobs in turn
(:func:`workers_for`), so the two never nest.

While a workflow runs, the memory its arrays free is kept for the next ones
(:func:`memory_reused`), and a fork inherits that.
"""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from types import FrameType
from typing import Any, TypeVar

from threadpoolctl import threadpool_limits

T = TypeVar("T")
R = TypeVar("R")

#: prctl option: the signal a process gets when its parent ends (linux/prctl.h).
PR_SET_PDEATHSIG = 1

#: The job of the forked pool now running (:func:`forked_map`): a fork inherits it, so it
#: may be any callable (a closure over the step's state), never pickled.
_FORKED_JOB: Callable | None = None
#: What SIGINT does while a forked worker runs a job (set by :func:`_start_worker`).
_JOB_SIGINT: Callable | signal.Handlers = signal.SIG_IGN


def default_workers() -> int:
    """One worker per CPU this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (
        os.cpu_count() or 1)


def workers_for(requested: int | None) -> int:
    """The processes to use: ``requested``, or by default one per CPU, but one in a process
    that is itself a worker (its siblings already use the other CPUs)."""
    if requested is not None:
        if requested < 1:
            raise ValueError(f"workers must be at least 1, got {requested}")
        return requested
    return 1 if multiprocessing.parent_process() is not None else default_workers()


@contextmanager
def one_blas_thread() -> Iterator[None]:
    """Inside the block this process's BLAS libraries (NumPy's and SciPy's OpenBLAS) run one
    thread each, and so do processes forked inside it; restored after. With one thread a
    result does not depend on how many processes computed it."""
    with threadpool_limits(limits=1, user_api="blas"):
        yield


#: glibc's ``mallopt`` parameters (malloc.h) and the defaults :func:`memory_reused` restores.
M_TRIM_THRESHOLD, M_MMAP_MAX = -1, -4
DEFAULT_TRIM_THRESHOLD, DEFAULT_MMAP_MAX = 128 * 1024, 65536
#: Free memory at the top of the heap that glibc keeps rather than give back, inside
#: :func:`memory_reused`: more than any analysis holds (the largest int ``mallopt`` takes).
KEPT_TRIM_THRESHOLD = 2**31 - 1
#: Blocks of :func:`memory_reused` open in this process, in any thread (the first to open
#: changes the allocator, the last to close restores it), and the lock that guards the count.
_memory_reused_blocks = 0
_MEMORY_REUSED_LOCK = threading.Lock()


@contextmanager
def memory_reused() -> Iterator[None]:
    """Inside the block, arrays freed in this process leave their memory in its heap for the
    next ones (glibc's allocator; elsewhere the block changes nothing); when the last block
    open in the process (in any thread) is left, the allocator's defaults return and the
    heap's free memory goes back to the system.

    By default glibc maps every allocation over a threshold (at most 32 MB) afresh and unmaps
    it when freed, and the kernel clears each page of a fresh mapping when it is first
    written. A four-minute recording's designs are about 120 MB each, made for every lag a
    step tries: the fixture stamped 1.5 s early spent 10–13 s of system time (its processes
    together) on that. Taken from the heap (``M_MMAP_MAX`` 0) and never trimmed
    (``M_TRIM_THRESHOLD``), 7.4–8.8 s; through the command, 3 s less time in the mean of
    three runs each (2026-12-07, the 2-core AMD EPYC VM). The peak memory is the same
    (1.14–1.17 GB either way). Setting either parameter ends glibc's own adjustment of its
    mapping threshold for the rest of the process.
    """
    global _memory_reused_blocks
    libc = glibc()
    with _MEMORY_REUSED_LOCK:
        _memory_reused_blocks += 1
        if libc is not None and _memory_reused_blocks == 1:
            libc.mallopt(M_MMAP_MAX, 0)
            libc.mallopt(M_TRIM_THRESHOLD, KEPT_TRIM_THRESHOLD)
    try:
        yield
    finally:
        with _MEMORY_REUSED_LOCK:
            _memory_reused_blocks -= 1
            if libc is not None and _memory_reused_blocks == 0:
                libc.mallopt(M_MMAP_MAX, DEFAULT_MMAP_MAX)
                libc.mallopt(M_TRIM_THRESHOLD, DEFAULT_TRIM_THRESHOLD)
                libc.malloc_trim(0)


def glibc() -> ctypes.CDLL | None:
    """This process's C library where it is glibc (Linux), else None (musl's ``mallopt``
    takes the calls and does nothing; other systems have none)."""
    if not sys.platform.startswith("linux"):
        return None
    libc = ctypes.CDLL(None)
    return libc if hasattr(libc, "gnu_get_libc_version") else None


def forked_map(job: Callable[[T], R], items: Sequence[T], workers: int) -> list[R]:
    """``[job(item) for item in items]``, in order, in up to ``workers`` forked processes
    (in this process with one worker or one item, or where processes cannot be forked:
    only Linux forks safely with the BLAS loaded).

    The items travel to the workers pickled and the results come back pickled; ``job`` and
    whatever it refers to are inherited by the fork. Call it inside :func:`one_blas_thread`
    so that the workers run one BLAS thread each. Items go out in order: put the longest
    first.

    Ctrl-C stops the map and raises ``KeyboardInterrupt`` here, without a worker's
    traceback: each worker abandons the job it runs as soon as that job is back in Python
    code from a long NumPy or LAPACK call (under 2 s, docs/discrepancy.md), and this process's
    ``KeyboardInterrupt`` waits until the pool is down (:func:`_ctrl_c_after`). A SIGINT
    sent to this process alone, not to its workers, takes effect when the map ends. Where this
    process does not handle SIGINT (ignored, as in a command a script starts in the
    background, or the default action), the workers ignore it too.
    """
    global _FORKED_JOB
    if workers <= 1 or len(items) <= 1 or sys.platform != "linux":
        return [job(item) for item in items]
    if _FORKED_JOB is not None:
        raise RuntimeError("forked_map is not re-entrant")
    _FORKED_JOB = job
    interruptible = callable(signal.getsignal(signal.SIGINT))
    try:
        context = multiprocessing.get_context("fork")
        with _ctrl_c_after(), \
                ProcessPoolExecutor(min(workers, len(items)), mp_context=context,
                                    initializer=_start_worker,
                                    initargs=(os.getpid(), interruptible)) as pool:
            return list(pool.map(_run_forked_job, items))
    finally:
        _FORKED_JOB = None


@contextmanager
def _ctrl_c_after() -> Iterator[None]:
    """SIGINT inside the block is noted, and handled as before (``KeyboardInterrupt``) when
    the block ends, however it ends.

    Raised at once, a ``KeyboardInterrupt`` lands anywhere in the process pool's own code.
    Ctrl-C at 2–25 s into a four-minute analysis (2026-12-07) left a run that went on to its
    end and wrote its outputs (the exception lost in ``os.fork``'s after-fork hooks, where
    Python ignores exceptions), and one that never ended (waiting on the pool while a worker
    waited to send its result). Only the main thread can set a handler; elsewhere, or where
    SIGINT is ignored or has its default action, the block changes nothing."""
    previous = signal.getsignal(signal.SIGINT)
    if threading.current_thread() is not threading.main_thread() or not callable(previous):
        yield
        return
    seen: list[FrameType | None] = []
    signal.signal(signal.SIGINT, lambda _signum, frame: seen.append(frame))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        if seen:
            previous(signal.SIGINT, seen[0])


def _start_worker(parent: int, interruptible: bool) -> None:
    """Make a forked worker end with ``parent``, however it ends, and ignore Ctrl-C between
    jobs, and in them too unless ``interruptible`` (``parent`` handles SIGINT;
    :func:`_run_forked_job`).

    A fork inherits both ends of the pool's pipes, so a worker whose parent was killed
    (SIGTERM, SIGKILL, out of memory) never reads the end of its queue and would wait
    forever; the parent-death signal ends it instead (Linux, ``PR_SET_PDEATHSIG``). Where a
    sandbox refuses the call the worker still works: it only loses this safety net.

    Ctrl-C reaches the workers too (the terminal signals the whole process group). A worker
    waiting for its next job printed its ``KeyboardInterrupt``'s traceback; one ended while
    it sent its result would leave the pool waiting for the rest of it forever. Between
    jobs the worker ignores it; the pool ends it when it shuts down."""
    global _JOB_SIGINT
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _JOB_SIGINT = signal.default_int_handler if interruptible else signal.SIG_IGN
    libc = ctypes.CDLL(None, use_errno=True)
    libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    if os.getppid() != parent:  # the parent ended before the signal was set
        os._exit(1)


def _run_forked_job(item: Any) -> Any:
    """The inherited job on one item (runs in a forked worker); Ctrl-C abandons it with
    ``KeyboardInterrupt``, which the pool sends back as the job's result, where the worker's
    parent handles SIGINT (:func:`_start_worker`)."""
    assert _FORKED_JOB is not None, "a forked worker inherits the job"
    signal.signal(signal.SIGINT, _JOB_SIGINT)
    try:
        return _FORKED_JOB(item)
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)


def parallel_map(job: Callable[[T], dict], items: Iterable[T], workers: int | None = None
                 ) -> Iterator[tuple[T, dict]]:
    """``(item, job(item))`` for every item, in order, as each completes.

    Items are independent, so they run in ``workers`` spawned processes (default: one per
    CPU; 1 runs them here); ``job`` must be a module-level function and the items small.
    """
    items = list(items)
    workers = default_workers() if workers is None else workers
    if workers <= 1 or len(items) <= 1:
        for item in items:
            yield item, job(item)
        return
    context = multiprocessing.get_context("spawn")
    with _one_blas_thread_in_children(), \
            ProcessPoolExecutor(min(workers, len(items)), mp_context=context) as pool:
        yield from zip(items, pool.map(job, items), strict=True)


@contextmanager
def _one_blas_thread_in_children() -> Iterator[None]:
    """Processes spawned inside the block read one BLAS/OpenMP thread from their environment
    (a spawned child's BLAS reads it when numpy loads); this process's environment is
    restored after."""
    names = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
    saved = {name: os.environ.get(name) for name in names}
    os.environ.update(dict.fromkeys(names, "1"))
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value
