"""Run an ``exohil`` command in a child process and stop it with Ctrl-C (SIGINT) once it
streams, as a user at a terminal would."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path


def interrupt_once_streaming(args: list[str], after_s: float = 0.0,
                             timeout_s: float = 120.0) -> tuple[int, str, str]:
    """Start ``exohil ARGS``, wait for its first status line with frames and ``after_s`` more
    seconds, send SIGINT; (return code, stdout, stderr after that line)."""
    proc = subprocess.Popen(as_at_a_terminal([str(Path(sys.executable).parent / "exohil"),
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


#: Sets SIGINT's default action, then becomes the command in its arguments.
_DEFAULT_SIGINT_THEN_EXEC = ("import os, signal, sys; "
                             "signal.signal(signal.SIGINT, signal.SIG_DFL); "
                             "os.execv(sys.argv[1], sys.argv[1:])")


def as_at_a_terminal(argv: list[str]) -> list[str]:
    """``argv`` started with SIGINT at its default action, as a terminal's shell starts a
    command, whatever this process inherited (a command a script starts in the background
    ignores SIGINT, and so does what it starts: an ignored SIGINT is kept across exec)."""
    return [sys.executable, "-c", _DEFAULT_SIGINT_THEN_EXEC, *argv]
