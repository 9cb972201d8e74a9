"""Shared click parameter types for the ``exohil`` commands."""

from __future__ import annotations

from pathlib import Path

import click


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
