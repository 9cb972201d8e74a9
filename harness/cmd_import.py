"""``exohil import csv|mot``: bring other tools' data into recording format v1.

Every imported recording carries provenance metadata: ``source`` (file name),
``source_sha256``, ``license`` (when known), ``generator``, ``command`` and, for each license
or source note beside the input (``LICENSE*``, ``SOURCE*``, ...), ``notice.<name>``: its text.
"""

from __future__ import annotations

import hashlib
import shlex
from dataclasses import dataclass
from pathlib import Path

import click

from exohil.harness.cli_types import (
    MAX_RATE_HZ,
    Count,
    Finite,
    InputFile,
    Name,
    NameList,
    OutputFile,
    refuse_overwriting_inputs,
)

#: The most lines ``--skip-rows`` drops.
MAX_SKIP_ROWS = 10_000_000


@dataclass(frozen=True)
class CsvPreset:
    """Column mapping of a known CSV layout."""

    rate_hz: float
    sensor_cols: str
    angle_cols: str
    sensor_names: tuple[str, ...]
    angle_names: tuple[str, ...]
    joint: str
    sensor_units: str
    license: str


PRESETS = {
    # ../shared/realdata/graphene-knee (see its SOURCE.md): no header, BOM, 100 Hz;
    # col 0 knee flexion (deg, optical mocap), cols 1-5 textile sensors (normalised ΔR/R0).
    "graphene-knee": CsvPreset(
        rate_hz=100.0,
        sensor_cols="1-5",
        angle_cols="0",
        sensor_names=("s1", "s2", "s3", "s4", "s5"),
        angle_names=("knee_flexion",),
        joint="knee",
        sensor_units="dR/R0",
        license="MIT, e-Body-Lab/graphene-based-knitted-sensing-sleeve",
    ),
}


@click.group("import")
def import_group() -> None:
    """Convert other tools' files into recordings (format v1 MCAP)."""


class Delimiter(click.ParamType):
    """One field-separator character: printable or a tab, not a quote or a line break."""

    name = "char"

    def convert(self, value, param, ctx):
        text = str(value)
        if len(text) != 1 or text in "\r\n\"" or (not text.isprintable() and text != "\t"):
            self.fail(f"must be exactly one character (printable or a tab, not a quote), "
                      f"got {text!r}", param, ctx)
        return text


class Columns(click.ParamType):
    """0-based column indices, ``'1-5'``, ``'1,3,6-8'``; the text is returned unchanged."""

    name = "columns"

    def convert(self, value, param, ctx):
        from exohil.formats.column_table import TableError, parse_columns

        try:
            parse_columns(str(value))
        except TableError as exc:
            self.fail(str(exc), param, ctx)
        return str(value)


def _names(text: str | None) -> tuple[str, ...] | None:
    return tuple(name.strip() for name in text.split(",")) if text else None


#: Files beside an input whose text an imported recording carries (``notice.<name>``): the
#: data's license and source note, which its terms ask to keep with anything derived from it.
#: A name counts when what precedes its first dot (any case) starts with one of
#: ``LICENSE_PREFIXES`` (``LICENSE_data``) or is one of ``NOTICE_STEMS`` (``SOURCE.md``), and
#: what follows it is a text suffix (not a recording written beside its input as SOURCE.mcap).
LICENSE_PREFIXES = ("LICENSE", "LICENCE", "COPYING")
NOTICE_STEMS = ("NOTICE", "SOURCE")
NOTICE_SUFFIXES = ("", "md", "txt", "rst")


def _provenance(path: Path, license_note: str | None) -> dict[str, str]:
    metadata = {
        "source": path.name,
        "source_sha256": hashlib.sha256(path.read_bytes()).hexdigest(),
        "command": _command_line(),
    }
    if license_note:
        metadata["license"] = license_note
    metadata.update(notices_beside(path))
    if not license_note and not any(key.startswith("notice.") for key in metadata):
        click.echo(f"warning: no license known for {path.name} (no --license, no LICENSE file "
                   "beside it): the recording names none", err=True)
    return metadata


def notices_beside(path: Path) -> dict[str, str]:
    """``notice.<name>`` → text of each license or source note beside the data file ``path``
    (``LICENSE_PREFIXES``, ``NOTICE_STEMS``): what a recording derived from it carries."""
    notices = {}
    for notice in sorted(path.parent.iterdir()):
        stem, _, suffix = notice.name.partition(".")
        if (stem.upper().startswith(LICENSE_PREFIXES) or stem.upper() in NOTICE_STEMS) \
                and suffix.lower() in NOTICE_SUFFIXES and notice.is_file() \
                and notice.resolve() != path.resolve():
            notices[f"notice.{notice.name}"] = notice.read_text(encoding="utf-8",
                                                                errors="replace")
    return notices


def _command_line() -> str:
    """The invoking command as text, rebuilt from click's parsed parameters: deterministic,
    file paths reduced to their names, arguments first, unset options left out."""
    context = click.get_current_context()
    words = ["exohil", *context.command_path.split()[1:]]
    options: list[str] = []
    for param in context.command.params:
        value = context.params.get(param.name or "")
        if value is None or value is False:
            continue
        shown = shlex.quote(value.name if isinstance(value, Path) else str(value))
        if isinstance(param, click.Argument):
            words.append(shown)
        elif value is True:
            options.append(param.opts[0])
        else:
            options.extend([param.opts[0], shown])
    return " ".join(words + options)


@import_group.command("csv")
@click.argument("input_file", type=InputFile())
@click.option("--out", "out", required=True, type=OutputFile(),
              help="Output recording (.mcap).")
@click.option("--preset", type=click.Choice(sorted(PRESETS)),
              help="Fill the mapping for a known layout (graphene-knee: ../shared/realdata).")
@click.option("--rate", type=Finite(0.0, MAX_RATE_HZ, min_open=True),
              help="Row rate, Hz (rows are equally spaced).")
@click.option("--sensor-cols", type=Columns(), help="0-based sensor columns: '1-5', '1,3,6-8'.")
@click.option("--angle-cols", type=Columns(), help="0-based angle columns (degrees), e.g. '0'.")
@click.option("--sensor-names", type=NameList(),
              help="Comma-separated sensor names (default: header or cN).")
@click.option("--angle-names", type=NameList(),
              help="Comma-separated angle names (default: header or angleN).")
@click.option("--joint", type=Name(), help="Mocap joint (topic /mocap/<joint>); default 'joint'.")
@click.option("--sensor-units", type=Name(), help="Unit of the sensor values; default 'mm'.")
@click.option("--skip-rows", type=Count(0, MAX_SKIP_ROWS), default=0, show_default=True,
              help="Lines to drop before the header/data.")
@click.option("--delimiter", type=Delimiter(), default=",", show_default=True,
              help="Field separator (one character).")
@click.option("--decimals", type=Count(0, 9), default=6, show_default=True,
              help="Decimal places kept for sensor values and angles; a sensor whose "
              "range needs more to keep 10⁻⁵ of it keeps more.")
@click.option("--license", "license_note", type=Name(),
              help="License note stored in the metadata (the text of LICENSE*, SOURCE* "
              "files beside the input is stored as well).")
def import_csv(
    input_file: Path,
    out: Path,
    preset: str | None,
    rate: float | None,
    sensor_cols: str | None,
    angle_cols: str | None,
    sensor_names: str | None,
    angle_names: str | None,
    joint: str | None,
    sensor_units: str | None,
    skip_rows: int,
    delimiter: str,
    decimals: int,
    license_note: str | None,
) -> None:
    """Import a numeric CSV (one row per sample at --rate Hz) as a recording: --sensor-cols
    become /suit/sensors (seq = row, t = row/rate), --angle-cols become /mocap/<joint> angles
    in degrees. A UTF-8 BOM and a header row are detected. Example:

        exohil import csv S1_2_HC45.csv --preset graphene-knee --out hc45.mcap
    """
    from exohil.formats.column_table import (
        TableError,
        parse_columns,
        read_table,
        recording_from_table,
    )
    from exohil.formats.errors import RecordingError
    from exohil.formats.recording_metadata import plain_field
    from exohil.formats.recording_writer import check_names, write_recording

    refuse_overwriting_inputs([("--out", out)], [input_file])

    chosen = PRESETS[preset] if preset else None
    rate = rate if rate is not None else (chosen.rate_hz if chosen else None)
    sensor_cols = sensor_cols or (chosen.sensor_cols if chosen else None)
    angle_cols = angle_cols if angle_cols is not None else (chosen.angle_cols if chosen else "")
    if rate is None or not rate > 0:
        raise click.BadParameter("give a positive --rate (Hz) or a --preset", param_hint="--rate")
    if not sensor_cols:
        raise click.BadParameter("give --sensor-cols or a --preset", param_hint="--sensor-cols")
    if sensor_units is not None and not plain_field(sensor_units):
        raise click.BadParameter(f"{sensor_units!r}: a unit without commas or outer spaces "
                                 "(the format's `units` is '<sensor unit>,deg')",
                                 param_hint="--sensor-units")
    try:
        sensor_idx = parse_columns(sensor_cols)
        angle_idx = parse_columns(angle_cols) if angle_cols else []
    except TableError as exc:
        raise click.BadParameter(str(exc)) from exc
    if set(sensor_idx) & set(angle_idx):
        raise click.BadParameter("a column is both a sensor and an angle column")
    try:
        table = read_table(
            input_file, sensor_idx + angle_idx, delimiter=delimiter, skip_rows=skip_rows
        )
    except TableError as exc:
        raise click.ClickException(str(exc)) from exc
    header = table.header or []
    # a preset's names go with its columns: columns of the user's own take the header's
    preset_s = chosen is not None and sensor_cols == chosen.sensor_cols
    preset_a = chosen is not None and angle_cols == chosen.angle_cols
    names_s = _names(sensor_names) or (chosen.sensor_names if preset_s and chosen else None)
    names_s = names_s or tuple(header[: len(sensor_idx)]) or tuple(f"c{c}" for c in sensor_idx)
    names_a = _names(angle_names) or (chosen.angle_names if preset_a and chosen else None)
    names_a = names_a or tuple(header[len(sensor_idx) :]) or tuple(f"angle{c}" for c in angle_idx)
    if len(names_s) != len(sensor_idx) or len(names_a) != len(angle_idx):
        raise click.BadParameter(
            f"{len(names_s)} sensor / {len(names_a)} angle names for "
            f"{len(sensor_idx)} / {len(angle_idx)} columns"
        )
    joint = joint or (chosen.joint if chosen else "joint")
    try:  # names from the header are the input's fault: say so before writing
        check_names(f"{input_file}: column names", names_s, {joint: names_a})
    except RecordingError as exc:
        raise click.ClickException(str(exc)) from exc
    metadata = _provenance(input_file, license_note or (chosen.license if chosen else None))
    metadata["generator"] = "exohil import csv"
    rec = recording_from_table(
        table.data,
        rate_hz=rate,
        sensor_names=names_s,
        angle_names=names_a,
        joint=joint,
        sensor_units=sensor_units or (chosen.sensor_units if chosen else "mm"),
        metadata=metadata,
    )
    try:
        write_recording(out, rec, decimals=decimals)
    except RecordingError as exc:
        raise click.ClickException(str(exc)) from exc
    click.echo(
        f"wrote {out}: {len(rec.sensors)} rows, sensors {','.join(names_s)}, "
        f"{'angles ' + ','.join(names_a) if names_a else 'no angles'} at {rate:g} Hz",
        err=True,
    )


@import_group.command("mot")
@click.argument("input_file", type=InputFile())
@click.option("--out", "out", required=True, type=OutputFile(),
              help="Output recording (.mcap).")
@click.option("--license", "license_note", type=Name(),
              help="License note stored in the metadata (the text of LICENSE*, SOURCE* "
              "files beside the input is stored as well).")
def import_mot(input_file: Path, out: Path, license_note: str | None) -> None:
    """Import an OpenSim .mot (e.g. inverse kinematics) as a mocap-only recording:
    /mocap/shoulder with plane_elv → elv_angle, shoulder_elv → shoulder_elv,
    axial_rot → shoulder_rot (degrees), and no sensors. Example:

    \b
        exohil import mot ABD01.mot --out abd01.mcap --license "CC BY 4.0, rmr-solver"
    """
    from exohil.formats.errors import RecordingError
    from exohil.formats.mot_import import shoulder_recording_from_mot
    from exohil.formats.opensim_mot import MotError, read_mot
    from exohil.formats.recording_writer import write_recording

    refuse_overwriting_inputs([("--out", out)], [input_file])

    try:
        mot = read_mot(input_file)
    except MotError as exc:
        raise click.ClickException(str(exc)) from exc
    metadata = _provenance(input_file, license_note)
    metadata["generator"] = "exohil import mot"
    try:
        rec = shoulder_recording_from_mot(mot, metadata)
    except RecordingError as exc:
        raise click.ClickException(f"{input_file}: {exc}") from exc
    try:
        write_recording(out, rec)
    except RecordingError as exc:
        raise click.ClickException(str(exc)) from exc
    click.echo(
        f"wrote {out}: {len(rec.mocap['shoulder'])} shoulder samples at {rec.mocap_rate_hz:g} Hz",
        err=True,
    )


COMMANDS: list[click.Command] = [import_group]
