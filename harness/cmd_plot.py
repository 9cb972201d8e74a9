"""``exohil plot``: hysteresis loops and time series of a recording, as PNG."""

from __future__ import annotations

from pathlib import Path

import click

from exohil.harness.cli_types import (
    MAX_TIME_S,
    Finite,
    InputFile,
    Name,
    OutputFile,
    refuse_overwriting_inputs,
)


@click.command("plot")
@click.argument("file", type=InputFile())
@click.option("--kind", type=click.Choice(["hysteresis", "timeseries"]), required=True,
              help="hysteresis: one sensor against a mocap angle, coloured by direction of "
              "motion; timeseries: sensors and angles against time.")
@click.option("--sensor", "sensors", type=Name(), multiple=True,
              help="Sensor name (hysteresis: default SF or the first; timeseries: repeat to "
              "choose, default all).")
@click.option("--joint", type=Name(), default=None,
              help="Mocap joint (hysteresis; default: shoulder, or the recording's only joint).")
@click.option("--angle", type=Name(), default=None,
              help="Mocap angle on the x axis (hysteresis; default: shoulder_elv, or the "
                   "joint's only angle).")
@click.option("--segment", type=Name(), help="Keep only the spans of this labelled segment.")
@click.option("--t0", type=Finite(-MAX_TIME_S, MAX_TIME_S),
              help="Start of the time window, s on the recording's clock (the times `record "
              "info` shows; a part from `record cut` keeps its times).")
@click.option("--t1", type=Finite(-MAX_TIME_S, MAX_TIME_S),
              help="End of the time window, s on the recording's clock.")
@click.option("--out", required=True, type=OutputFile(),
              help="Output image: .png, or .svg or .pdf for a vector copy.")
def plot_command(
    file: Path,
    kind: str,
    sensors: tuple[str, ...],
    joint: str | None,
    angle: str | None,
    segment: str | None,
    t0: float | None,
    t1: float | None,
    out: Path,
) -> None:
    """Plot a recording FILE to an image (PNG, SVG or PDF, from --out's suffix). Examples:

        exohil plot rec.mcap --kind hysteresis --sensor SF --out sf.png

        exohil plot rec.mcap --kind timeseries --t0 10 --t1 30 --out ts.png
    """
    refuse_overwriting_inputs([("--out", out)], [file])
    image_format = out.suffix.lower().lstrip(".")
    if image_format not in IMAGE_FORMATS:
        raise click.BadParameter(f"{out.name}: end it in {', '.join(IMAGE_FORMATS)} (the "
                                 "image's format)", param_hint="--out")
    from exohil.formats.atomic import write_with
    from exohil.formats.errors import RecordingError
    from exohil.formats.recording_reader import read_recording
    from exohil.harness.recording_plots import plot_hysteresis, plot_timeseries, time_window

    if t0 is not None and t1 is not None and t1 <= t0:
        raise click.BadParameter("--t1 must be after --t0", param_hint="--t1")
    try:
        rec = read_recording(file)
        window = time_window(rec, segment, t0, t1)
        if kind == "hysteresis":
            if len(sensors) > 1:
                raise click.BadParameter("hysteresis takes one --sensor", param_hint="--sensor")
            sensor = sensors[0] if sensors else _default_sensor(rec.sensor_names)
            joint = joint or _only_or(tuple(rec.mocap), "shoulder")
            stream = rec.mocap.get(joint)
            angle = angle or _only_or(stream.names if stream else (), "shoulder_elv")
            figure = plot_hysteresis(
                rec, sensor, joint=joint, angle=angle, window=window,
                title=f"{file.name}: {sensor} vs {angle}" + (f" ({segment})" if segment else ""),
            )
        else:
            figure = plot_timeseries(rec, sensors, window=window, title=file.name)
    except RecordingError as exc:
        raise click.ClickException(str(exc)) from exc
    try:
        write_with(out, lambda tmp: figure.savefig(tmp, format=image_format))
    except OSError as exc:
        raise click.ClickException(f"{out}: cannot write: {exc.strerror or exc}") from exc
    click.echo(f"wrote {out}", err=True)


#: What ``--out`` may end in: the image formats written (matplotlib's names).
IMAGE_FORMATS = ("png", "svg", "pdf")


def _only_or(names: tuple[str, ...], preferred: str) -> str:
    """``preferred`` when present or when there is no single alternative, else the only name."""
    return names[0] if len(names) == 1 and preferred not in names else preferred


def _default_sensor(names: tuple[str, ...]) -> str:
    if not names:
        raise click.ClickException("recording has no sensors (mocap-only); nothing to plot")
    return "SF" if "SF" in names else names[0]


COMMANDS: list[click.Command] = [plot_command]
