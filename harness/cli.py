"""The ``exohil`` command line: one group, one module per command family.

Heavy imports (torch, matplotlib, scipy.signal: each half a second or more) happen inside
the commands, so ``exohil --help`` stays fast (0.2 s).
"""

from __future__ import annotations

import os
import sys
from importlib.metadata import entry_points
from typing import IO, Any

import click

from exohil import __version__
from exohil.formats.errors import InputError


class OneLineError(click.ClickException):
    """An error shown as one line on stderr, ``Error: MESSAGE``, with exit code ``code``
    (click's usage errors keep their 2)."""

    def __init__(self, message: str, code: int = 1) -> None:
        super().__init__(" ".join(line.strip() for line in message.splitlines() if line.strip())
                         or "failed")
        self.exit_code = code  # type: ignore[misc]  # a ClassVar in click's annotations

    def show(self, file: IO[Any] | None = None) -> None:
        click.echo(f"Error: {self.format_message()}", file=file, err=True)


#: Set to see the traceback of an unexpected error instead of its one-line summary.
TRACEBACK_ENV = "EXOHIL_TRACEBACK"


#: click >= 8.2 raises this for a group called without a command: its "message" is the help.
_HELP_ERRORS = (OneLineError, *(
    (click.exceptions.NoArgsIsHelpError,) if hasattr(click.exceptions, "NoArgsIsHelpError")
    else ()))


def _one_line(err: click.ClickException) -> click.ClickException:
    if isinstance(err, _HELP_ERRORS):  # help text, or already one line
        return err
    return OneLineError(err.format_message(), err.exit_code)


class _Group(click.Group):
    """Every error a command ends with is one line on stderr, never a traceback:

    * a bad command line (click's usage error: unknown option, bad value) is
      ``Error: Invalid value for '--seed': ...`` with exit code 2, without click's usage block;
    * bad input found anywhere in a command (:class:`InputError`: a recording, a checkpoint, a
      profile that does not fit the job) is ``Error: message`` with exit code 1;
    * an operating-system error anywhere in a command (a file that vanished, a full disk, a
      permission) is ``Error: FILE: reason`` with exit code 1, and so is a command started
      with its standard output closed (Python then drops every line printed);
    * any other unexpected exception is ``Error: <type>: message`` with exit code 1
      (``EXOHIL_TRACEBACK=1`` shows the traceback instead).
    """

    def make_context(self, info_name, args, parent=None, **extra):
        try:
            return super().make_context(info_name, args, parent, **extra)
        except click.ClickException as err:
            raise _one_line(err) from None

    def invoke(self, ctx: click.Context):
        if sys.stdout is None:  # started with fd 1 closed: click would drop every line
            raise OneLineError("standard output is closed (started with >&-?): nothing this "
                               "command prints would be seen; send it to a file or /dev/null")
        try:
            return super().invoke(ctx)
        except click.ClickException as err:
            raise _one_line(err) from None
        except (click.exceptions.Exit, click.Abort):
            raise
        except InputError as err:
            raise OneLineError(str(err)) from None
        except OSError as err:
            where = f"{err.filename}: " if err.filename else ""
            raise OneLineError(f"{where}{err.strerror or err}") from None
        except Exception as err:
            if os.environ.get(TRACEBACK_ENV):
                raise
            raise OneLineError(f"unexpected {type(err).__name__}: {err} (set "
                               f"{TRACEBACK_ENV}=1 for the traceback)") from None


@click.group(cls=_Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="exohil")
def main() -> None:
    """exohil: hardware-in-the-loop harness and conformance suite for a soft shoulder
    sensing exosuit (four tendon sensors → shoulder angles → NAO teleoperation)."""


def _register() -> None:
    from exohil.harness import (
        cmd_calibrate,
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
        cmd_plot, cmd_train, cmd_calibrate, cmd_run, cmd_discrepancy,
    ):
        for command in module.COMMANDS:
            main.add_command(command)
    # Commands of the layers above the harness (`exohil conform`) come in through the
    # `exohil.commands` entry point, so the harness never imports them.
    for entry in entry_points(group="exohil.commands"):
        main.add_command(entry.load())

_register()

if __name__ == "__main__":  # python -m exohil.harness.cli: it printed nothing and exited 0
    main(prog_name="exohil")
