"""``python -m exohil …``: the same command line as the ``exohil`` console script."""

from exohil.harness.cli import main

main(prog_name="exohil")
