"""``exohil record info``: what is inside a recording (format v1 MCAP) file;
``exohil record recover``: a clean, indexed copy of a recording that was never closed;
``exohil record cut``: a time span of a recording as a recording of its own."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import click

from exohil.harness.cli_types import (
    MAX_DURATION_S,
    Finite,
    InputFile,
    OutputFile,
    refuse_overwriting_inputs,
)


@click.group("record")
def record_group() -> None:
    """Inspect, cut and recover recordings (recording format v1, MCAP; see
    docs/recording-format.md)."""


@record_group.command("info")
@click.argument("file", type=InputFile())
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object instead of text.")
def info_command(file: Path, as_json: bool) -> None:
    """Summarise FILE: duration, channels (topic, schema, messages, mean rate), sequence gaps,
    sensors, mocap joints, metadata, segments and reader notes (e.g. ignored channels)."""
    from exohil.formats.errors import RecordingError
    from exohil.formats.recording_reader import scan_recording

    try:
        scan = scan_recording(file)
    except RecordingError as exc:
        raise click.ClickException(str(exc)) from exc
    summary = recording_summary(file, scan)
    if as_json:
        click.echo(json.dumps(summary, indent=2, allow_nan=False))
    else:
        click.echo(_as_text(summary))


def recording_summary(file: Path, scan: Any) -> dict[str, Any]:
    """A JSON-ready summary of a :class:`~exohil.formats.recording_reader.RecordingScan`.

    Times are seconds, rates Hz; NaN (undefined) becomes None.
    """
    from exohil.formats.sequence import sequence_gaps

    rec = scan.recording
    times = [rec.sensors.t] + [stream.t for stream in rec.mocap.values()]
    times = [t for t in times if len(t)]
    start = min(float(t.min()) for t in times) if times else math.nan
    end = max(float(t.max()) for t in times) if times else math.nan
    gaps = sequence_gaps(rec.sensors.seq)
    return {
        "file": str(file),
        "size_bytes": file.stat().st_size,
        "duration_s": _finite(end - start),
        "start_s": _finite(start),
        "end_s": _finite(end),
        "channels": [
            {
                "topic": c.topic,
                "schema": c.schema_name,
                "messages": c.message_count,
                "mean_rate_hz": _finite(c.mean_rate_hz),
                "used": c.used,
            }
            for c in scan.channels
        ],
        "sensors": {
            "names": list(rec.sensor_names),
            "units": rec.sensor_units,
            "frames": len(rec.sensors),
            "nominal_rate_hz": rec.sensor_rate_hz,
        },
        "sequence_gaps": {
            "gaps": gaps.gaps,
            "frames_missing": gaps.missing,
            "largest_gap": gaps.largest,
        },
        "mocap": {
            joint: {"angles": list(stream.names), "samples": len(stream)}
            for joint, stream in rec.mocap.items()
        },
        "mocap_nominal_rate_hz": rec.mocap_rate_hz,
        "segments": [{"name": s.name, "t0": s.t0, "t1": s.t1} for s in rec.segments],
        "metadata": dict(sorted(rec.metadata.items())),
        "notes": list(scan.notes),
    }


def _finite(value: float) -> float | None:
    return round(value, 6) if math.isfinite(value) else None


def _as_text(summary: dict[str, Any]) -> str:
    lines = [f"file      {summary['file']} ({summary['size_bytes']:,} bytes)"]
    duration = summary["duration_s"]
    span = (
        f"{duration:.3f} s ({summary['start_s']:.3f} → {summary['end_s']:.3f} s)"
        if duration is not None
        else "empty"
    )
    lines.append(f"duration  {span}")
    lines.append("channels")
    width = max([len(c["topic"]) for c in summary["channels"]] + [5])
    for c in summary["channels"]:
        rate = f"{c['mean_rate_hz']:9.3f} Hz" if c["mean_rate_hz"] is not None else "        - Hz"
        ignored = "" if c["used"] else "  (ignored)"
        lines.append(
            f"  {c['topic']:<{width}}  {c['messages']:>8} msgs  {rate}  {c['schema']}{ignored}"
        )
    sensors = summary["sensors"]
    if sensors["names"]:
        lines.append(
            f"sensors   {','.join(sensors['names'])} [{sensors['units']}], "
            f"{sensors['frames']} frames, nominal {sensors['nominal_rate_hz']:g} Hz"
        )
    else:
        lines.append("sensors   none (a mocap-only recording)")
    gaps = summary["sequence_gaps"]
    lines.append(
        f"seq gaps  {gaps['gaps']} gaps, {gaps['frames_missing']} frames missing, "
        f"largest gap {gaps['largest_gap']} frame{'' if gaps['largest_gap'] == 1 else 's'}"
    )
    for joint, stream in summary["mocap"].items():
        lines.append(
            f"mocap     {joint}: {', '.join(stream['angles'])} [deg], {stream['samples']} samples,"
            f" nominal {summary['mocap_nominal_rate_hz']:g} Hz"
        )
    lines.append("metadata")
    for key, value in summary["metadata"].items():
        shown = value.replace("\r", "\\r").replace("\n", "\\n")  # one line per key
        shown = shown if len(shown) <= 100 else shown[:97] + "..."
        lines.append(f"  {key} = {shown}")
    if summary["segments"]:
        lines.append(f"segments  {len(summary['segments'])}")
        name_width = max(len(s["name"]) for s in summary["segments"])
        for s in summary["segments"]:
            lines.append(f"  {s['name']:<{name_width}} {s['t0']:10.3f} → {s['t1']:10.3f} s")
    for note in summary["notes"]:
        lines.append(f"note      {note}")
    return "\n".join(lines)


@record_group.command("recover")
@click.argument("file", type=InputFile())
@click.option("--out", "out", type=OutputFile(), required=True,
              help="The clean copy (must not be FILE).")
def recover_command(file: Path, out: Path) -> None:
    """Rewrite FILE, e.g. a recording left as NAME.mcap.partial by a killed run, as a clean,
    indexed recording OUT, and say what was lost (what its writer had not written out: at
    most the last second of a durable recording; and the metadata written at close, such as
    segments and the measured rate)."""
    from exohil.formats.errors import RecordingError
    from exohil.formats.recording_reader import scan_recording

    refuse_overwriting_inputs([("--out", out)], [file])
    try:
        scan = scan_recording(file)
    except RecordingError as exc:
        raise click.ClickException(str(exc)) from exc
    rec = scan.recording
    mocap = sum(len(stream) for stream in rec.mocap.values())
    if scan.lost_bytes is not None and not len(rec.sensors) and not mocap:
        raise click.ClickException(
            f"nothing to recover from {file}: no complete record of a frame or a sample "
            f"before the {scan.lost_bytes} bytes where it ends (a recording written whole "
            "keeps its records in chunks of up to 1 MiB, and one cut inside its first chunk "
            "loses them all; the durable NAME.partial of run/demo --record closes a chunk "
            "every second)")
    _write_as_read(out, rec)
    span = (f", {rec.sensors.t[0]:.3f} → {rec.sensors.t[-1]:.3f} s" if len(rec.sensors)
            else "")
    click.echo(f"recovered {len(rec.sensors)} sensor frames{span} and {mocap} mocap samples "
               f"into {out}")
    if scan.lost_bytes is None and scan.magic_missing:
        click.echo(f"lost: nothing (every record was there, up to the footer; only the last "
                   f"{scan.magic_missing} bytes of the closing MCAP magic were missing)")
    elif scan.lost_bytes is None:
        click.echo("lost: nothing (the file was complete)")
    else:  # a durable file killed between its syncs ends after a complete record: 0 bytes
        cut = (f"the {scan.lost_bytes} bytes after the last complete record" if scan.lost_bytes
               else "no partial record (the file ends after a complete one)")
        click.echo(f"lost: {cut}; the file was never closed, so what its writer had not yet "
                   "written out (the durable recording of run/demo --record: at most its last "
                   "second; a file written whole: the rest of its chunk) and the metadata it "
                   "writes at close (segments, the measured rate) are not in it")


@record_group.command("cut")
@click.argument("file", type=InputFile())
@click.option("--start", "start_s", type=Finite(0.0, MAX_DURATION_S), default=0.0,
              show_default=True, help="Start of the part, seconds after the first sensor "
              "frame (the first mocap sample without sensors).")
@click.option("--stop", "stop_s", type=Finite(0.0, MAX_DURATION_S),
              help="End of the part (excluded), seconds after the first sensor frame; "
              "default: the end of the recording.")
@click.option("--out", "out", type=OutputFile(), required=True,
              help="The part, a recording of its own (must not be FILE).")
def cut_command(file: Path, start_s: float, stop_s: float | None, out: Path) -> None:
    """Write the part of FILE from --start to --stop as recording OUT: its sensor frames, the
    motion capture of the same span and the segments clipped to it, with times and sequence
    numbers as they were (a recording without sensors, such as an imported .mot, is cut by
    its motion capture, times after its first sample). OUT's metadata names FILE, its
    sha256 (and those of the recordings FILE was cut from, if it was) and the span. Example,
    the first 12 s of a session for calibration and the rest to test on:

    \b
        exohil record cut session.mcap --stop 12 --out calib.mcap
        exohil record cut session.mcap --start 12 --out test.mcap
    """
    import numpy as np

    from exohil.formats.digest import sha256_file
    from exohil.formats.errors import RecordingError
    from exohil.formats.recording import cut_recording
    from exohil.formats.recording_metadata import cut_lineage
    from exohil.formats.recording_reader import read_recording

    refuse_overwriting_inputs([("--out", out)], [file])
    try:
        rec = read_recording(file)
        part = cut_recording(rec, start_s, math.inf if stop_s is None else stop_s)
    except (RecordingError, ValueError) as exc:
        raise click.ClickException(f"{file}: {exc}" if isinstance(exc, ValueError)
                                   else str(exc)) from None
    earlier = cut_lineage(rec.metadata)
    if earlier:  # a part of a part: every recording it came from, for the heldout check
        part.metadata["cut.origins_sha256"] = ",".join(earlier)
    part.metadata.update({"cut.source": file.name, "cut.source_sha256": sha256_file(file),
                          "cut.start_s": f"{start_s:g}",
                          "cut.stop_s": "end" if stop_s is None else f"{stop_s:g}"})
    _write_as_read(out, part)
    if len(rec.sensors):
        kept, whole, what = part.sensors.t, rec.sensors.t, "sensor frames"
    else:  # a mocap-only recording: times after its first sample
        kept = np.concatenate([stream.t for stream in part.mocap.values()])
        whole = np.concatenate([stream.t for stream in rec.mocap.values()])
        what = "mocap samples"
    click.echo(f"wrote {out}: {len(kept)} of {len(whole)} {what}, {kept.min() - whole.min():.3f}"
               f" → {kept.max() - whole.min():.3f} s after the first {what[:-1]}")


def _write_as_read(out: Path, rec: Any) -> None:
    """Write ``rec`` with the decimal places its values were read with, so that rewriting a
    recording (cut, recover) rounds nothing away: one imported with 6 places keeps them."""
    from exohil.formats.recording_messages import stored_decimals
    from exohil.formats.recording_writer import write_recording

    arrays = [rec.sensors.values, *(stream.angles for stream in rec.mocap.values())]
    write_recording(out, rec, decimals=stored_decimals(arrays))


COMMANDS: list[click.Command] = [record_group]
