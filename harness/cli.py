"""The ``exohil`` command line: one group, one module per command family.

Heavy imports (torch, matplotlib, mcap) happen inside the commands, so ``exohil --help``
stays fast.
"""

from __future__ import annotations

from importlib.metadata import entry_points

import click

from exohil import __version__
from exohil.formats.errors import InputError


class _Group(click.Group):
    """Turns bad input found anywhere in a command (:class:`InputError`: a recording, a
    checkpoint, a profile that does not fit the job) and an operating-system error (a file that
    vanished, a full disk, a permission) into one error line and exit code 1 instead of a
    traceback."""

    def invoke(self, ctx: click.Context):
        try:
            return super().invoke(ctx)
        except InputError as err:
            raise click.ClickException(str(err)) from None
        except OSError as err:
            where = f"{err.filename}: " if err.filename else ""
            raise click.ClickException(f"{where}{err.strerror or err}") from None


@click.group(cls=_Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="exohil")
def main() -> None:
    """exohil: hardware-in-the-loop harness and conformance suite for a soft shoulder
    sensing exosuit (four tendon sensors → shoulder angles → NAO teleoperation)."""


def _register() -> None:
    from exohil.harness import (
        cmd_convert,
        cmd_demo,
        cmd_discrepancy,
        cmd_emulate,
        cmd_fixtures,
        cmd_import,
        cmd_plot,
        cmd_record,
        cmd_run,
        cmd_simulate,
        cmd_train,
    )

    for module in (
        cmd_demo, cmd_convert, cmd_fixtures, cmd_simulate, cmd_emulate, cmd_record, cmd_import,
        cmd_plot, cmd_train, cmd_run, cmd_discrepancy,
    ):
        for command in module.COMMANDS:
            main.add_command(command)
    # Commands of the layers above the harness (`exohil conform`) come in through the
    # `exohil.commands` entry point, so the harness never imports them.
    for entry in entry_points(group="exohil.commands"):
        main.add_command(entry.load())

_register()
