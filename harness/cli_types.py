"""Shared click parameter types for the ``exohil`` commands."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import click

from exohil.formats.atomic import same_file


class OutputFile(click.Path):
    """A file the command will write: its folder must exist, checked when the command line is
    parsed, so a long run (training, streaming) cannot fail only at the end."""

    def __init__(self) -> None:
        super().__init__(dir_okay=False, path_type=Path)

    def convert(self, value, param, ctx):
        path = super().convert(value, param, ctx)
        folder = Path(path).resolve().parent
        if not folder.is_dir():
            self.fail(f"folder {folder} does not exist (create it first)", param, ctx)
        return path


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
