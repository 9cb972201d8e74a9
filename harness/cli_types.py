"""Shared click parameter types for the ``exohil`` commands."""

from __future__ import annotations

import tempfile
from collections.abc import Iterable
from pathlib import Path

import click

from exohil.formats.atomic import same_file


class OutputFile(click.Path):
    """A file the command will write: its folder must exist and take new files, checked when
    the command line is parsed, so a long run (training, streaming) cannot fail only at the
    end."""

    def __init__(self) -> None:
        super().__init__(dir_okay=False, path_type=Path)

    def convert(self, value, param, ctx):
        path = super().convert(value, param, ctx)
        folder = Path(path).resolve().parent
        if not folder.is_dir():
            self.fail(f"folder {folder} does not exist (create it first)", param, ctx)
        problem = _cannot_write_in(folder)
        if problem:
            self.fail(f"cannot write in folder {folder}: {problem}", param, ctx)
        return path


class OutputFolder(click.Path):
    """A folder the command will write files into (created when missing): it, or the nearest
    folder above it that exists, must take new files; checked when the command line is
    parsed."""

    def __init__(self) -> None:
        super().__init__(file_okay=False, path_type=Path)

    def convert(self, value, param, ctx):
        path = super().convert(value, param, ctx)
        existing = Path(path).resolve()
        while not existing.exists():
            existing = existing.parent
        if not existing.is_dir():
            self.fail(f"{existing} is not a folder", param, ctx)
        problem = _cannot_write_in(existing)
        if problem:
            self.fail(f"cannot write in folder {existing}: {problem}", param, ctx)
        return path


def _cannot_write_in(folder: Path) -> str | None:
    """Why a new file cannot be created in ``folder`` (tried with a temporary file, which is
    removed at once), or None."""
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as err:
        return err.strerror or str(err)
    return None


def refuse_overwriting_inputs(outputs: Iterable[tuple[str, Path | None]],
                              inputs: Iterable[Path | None]) -> None:
    """Refuse (a usage error naming both) when an output file is one of the input files, by
    any path to it: a command never replaces what it reads. ``outputs`` holds (option that
    names it, path) of each output; None paths are ignored."""
    sources = [path for path in inputs if path is not None]
    for option, path in outputs:
        if path is None:
            continue
        clash = same_file(path, sources)
        if clash is not None:
            raise click.UsageError(f"{option} {path} is the input {clash}; refusing to overwrite "
                                   "it (choose another output)")
