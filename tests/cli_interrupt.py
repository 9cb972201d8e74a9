"""Ctrl-C (SIGINT) in tests: an ``exohil`` command in a child process stopped with it once
it streams, as a user at a terminal would; a child started, or a block of this process run,
with SIGINT set as the test needs, whatever this process inherited (a command a script
starts in the background ignores SIGINT, and Python then leaves it ignored)."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path


def interrupt_once_streaming(args: list[str], after_s: float = 0.0,
                             timeout_s: float = 120.0) -> tuple[int, str, str]:
    """Start ``exohil ARGS``, wait for its first status line with frames and ``after_s`` more
    seconds, send SIGINT; (return code, stdout, stderr after that line)."""
    proc = subprocess.Popen(started_with_sigint(signal.SIG_DFL,
                                                [str(Path(sys.executable).parent / "exohil"),
                                                 *args]),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stderr is not None
        for line in proc.stderr:  # the first status line: frames are streaming
            if " frames " in line:
                break
        time.sleep(after_s)
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=timeout_s)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return proc.returncode, stdout, stderr


#: Sets SIGINT's action (named by its first argument), then becomes the command in the rest.
_SET_SIGINT_THEN_EXEC = ("import os, signal, sys; "
                         "signal.signal(signal.SIGINT, getattr(signal, sys.argv[1])); "
                         "os.execv(sys.argv[2], sys.argv[2:])")


def started_with_sigint(action: signal.Handlers, argv: list[str]) -> list[str]:
    """``argv`` started with SIGINT at ``action``: ``SIG_DFL`` as a terminal's shell starts
    a command (Python then installs its handler), ``SIG_IGN`` as a script's ``cmd &`` does
    (kept across exec, so also by what the command spawns)."""
    return [sys.executable, "-c", _SET_SIGINT_THEN_EXEC, action.name, *argv]


@contextmanager
def sigint_handled_by(handler: Callable | signal.Handlers) -> Iterator[None]:
    """SIGINT's handler in this process inside the block, restored after."""
    previous = signal.signal(signal.SIGINT, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
