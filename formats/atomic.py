"""Whole-file outputs: written under a temporary name, renamed into place only when complete.

A file output is either the complete new file or the old file untouched: an exception, a
Ctrl-C or a kill while writing leaves the target as it was (a killed process may leave the
hidden temporary file beside it, never a shorter file under the target's name). The rename
is ``os.replace`` within one folder, atomic on POSIX; the data is flushed to disk first.

:func:`same_file` tells whether an output names one of the inputs, so commands can refuse
to overwrite what they read.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path


def temporary_name(path: Path) -> Path:
    """The hidden temporary name beside ``path`` (unique per process, keeps the suffix so
    writers that look at it, such as ``savefig``, still work)."""
    return path.with_name(f".{path.stem}.partial-{os.getpid()}{path.suffix}")


@contextmanager
def replacing(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path to write instead of ``path``; rename it to ``path`` when the
    block ends normally; remove it when the block raises (anything, KeyboardInterrupt
    included), leaving ``path`` as it was."""
    target = Path(path)
    tmp = temporary_name(target)
    try:
        yield tmp
        _fsync(tmp)
        os.replace(tmp, target)
    finally:
        tmp.unlink(missing_ok=True)


def write_with(path: str | Path, write: Callable[[Path], object]) -> Path:
    """Call ``write(temporary path)`` and rename the result to ``path``; returns ``path``."""
    with replacing(path) as tmp:
        write(tmp)
    return Path(path)


def write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` as a whole (see module doc)."""
    with replacing(path) as tmp:
        tmp.write_bytes(data)


def write_text(path: str | Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` as a whole (see module doc)."""
    write_bytes(path, text.encode("utf-8"))


def same_file(output: str | Path, inputs: Iterable[str | Path]) -> Path | None:
    """The first of ``inputs`` that ``output`` names (the same file through any path, link or
    hard link), or None. An output that does not exist yet names no input."""
    out = Path(output)
    if not out.exists():
        return None
    for candidate in inputs:
        path = Path(candidate)
        try:
            if path.exists() and os.path.samefile(out, path):
                return path
        except OSError:
            continue
    return None


def _fsync(path: Path) -> None:
    if not path.exists():
        raise FileNotFoundError(2, "the writer produced no file", str(path))
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
