"""``exohil fixtures build [--check]``: regenerate or verify the simulated fixture recordings."""

from __future__ import annotations

import tempfile
from pathlib import Path

import click

from exohil.formats.atomic import write_bytes, write_text
from exohil.harness.cli_types import InputDir, OutputDir
from exohil.harness.paths import FIXTURES_DIR, MODELS_DIR, SHOULDER_IK_DIR


@click.group("fixtures")
def fixtures_group() -> None:
    """Bundled recordings and reference models: where they are, how they are rebuilt
    (fixtures/README.md)."""


@fixtures_group.command("build")
@click.option("--check", is_flag=True,
              help="Rebuild into a temporary folder and compare sha256 against "
                   "fixtures/SHA256SUMS (and the committed files); exit 1 on any mismatch.")
@click.option("--dir", "fixtures_dir", type=OutputDir(),
              default=FIXTURES_DIR, show_default=True, help="Fixtures folder.")
@click.option("--shoulder-ik", "shoulder_ik_dir", type=InputDir(),
              default=SHOULDER_IK_DIR, show_default=True,
              help="Folder of the shoulder-ik .mot trials (real motion, CC BY 4.0); by default "
                   "in $EXOHIL_SHARED, else in ../shared beside a checkout.")
def build_command(check: bool, fixtures_dir: Path, shoulder_ik_dir: Path) -> None:
    """Regenerate every fixture (bit-identical on rebuild) and fixtures/SHA256SUMS.

    With --check nothing under fixtures/ changes: the fixtures are rebuilt in a temporary
    folder and their hashes compared with the recorded ones.
    """
    from exohil.formats.digest import sha256_file
    from exohil.formats.opensim_mot import MotError
    from exohil.harness.fixture_specs import (
        FIXTURES,
        SHOULDER_IK_NOTICES,
        SUMS_FILE,
        build_fixture,
        format_sums,
        parse_sums,
    )

    if check and not (fixtures_dir / SUMS_FILE).is_file():
        raise click.BadParameter(f"{fixtures_dir} has no {SUMS_FILE} to check against",
                                 param_hint="--dir")
    with tempfile.TemporaryDirectory(prefix="exohil-fixtures-") as tmp:
        # every fixture is built here first: a build that fails half-way (the real motion
        # missing) leaves the fixtures folder and its sums as they were
        out_dir = Path(tmp)
        hashes = {}
        for spec in FIXTURES:
            click.echo(f"building {spec.filename}: {spec.description}", err=True)
            try:
                built = build_fixture(spec, out_dir, shoulder_ik_dir)
            except MotError as exc:
                raise click.ClickException(f"{spec.filename}: {exc} (see --shoulder-ik)") from None
            except OSError as exc:  # its licence notice, stored in the recording
                raise click.ClickException(f"{spec.filename}: cannot read the shoulder-ik "
                                           f"licence notice: {exc} (see --shoulder-ik)") from None
            hashes[spec.filename] = sha256_file(built)
        if not check:
            try:
                notices = {target: (shoulder_ik_dir / source).read_bytes()
                           for source, target in SHOULDER_IK_NOTICES.items()}
            except OSError as exc:
                raise click.ClickException(f"cannot read the shoulder-ik licence notice: {exc} "
                                           "(see --shoulder-ik)") from None
            fixtures_dir.mkdir(parents=True, exist_ok=True)
            for name in hashes:
                write_bytes(fixtures_dir / name, (out_dir / name).read_bytes())
            for target, notice in notices.items():
                write_bytes(fixtures_dir / target, notice)
            write_text(fixtures_dir / SUMS_FILE, format_sums(hashes))
            click.echo(f"wrote {len(hashes)} fixtures and {SUMS_FILE} to {fixtures_dir}", err=True)
            return
    sums_path = fixtures_dir / SUMS_FILE
    try:
        recorded = parse_sums(sums_path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise click.ClickException(f"cannot read {sums_path}: {exc}") from exc
    problems = []
    for name, digest in hashes.items():
        committed = fixtures_dir / name
        if recorded.get(name) != digest:
            problems.append(f"{name}: rebuilt sha256 {digest[:12]}… != {SUMS_FILE} "
                            f"{(recorded.get(name) or 'missing')[:12]}")
        elif not committed.is_file():
            problems.append(f"{name}: missing from {fixtures_dir}")
        elif sha256_file(committed) != digest:
            problems.append(f"{name}: committed file differs from its rebuild")
    for line in problems:
        click.echo(f"MISMATCH {line}", err=True)
    if problems:
        raise click.ClickException(f"{len(problems)} fixture(s) do not match; "
                                   f"run `exohil fixtures build` and commit the result")
    click.echo(f"all {len(hashes)} fixtures match {SUMS_FILE}", err=True)


@fixtures_group.command("list")
def list_command() -> None:
    """Print the bundled recordings and reference models, one absolute path per line with
    what it is, for the commands that take a file (an installed exohil keeps them inside the
    package; $EXOHIL_FIXTURES names another folder). Example:

    \b
        exohil evaluate "$(exohil fixtures list | grep ennet.npz | cut -f1)" my_trial.mcap
    """
    from exohil.harness.fixture_specs import FIXTURES

    described = {spec.filename: spec.description for spec in FIXTURES}
    recordings = sorted(FIXTURES_DIR.glob("*.mcap"))
    models = sorted(MODELS_DIR.glob("*.npz"))
    if not recordings and not models:
        raise click.ClickException(f"no recording or model in {FIXTURES_DIR} "
                                   "(check $EXOHIL_FIXTURES)")
    for path in recordings:
        click.echo(f"{path.absolute()}\trecording: {described.get(path.name, 'not built here')}")
    for path in models:
        click.echo(f"{path.absolute()}\treference model {path.stem} "
                   f"(provenance: {MODELS_DIR.absolute() / 'README.md'})")


COMMANDS: list[click.Command] = [fixtures_group]
