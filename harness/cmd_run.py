"""``exohil run``: the pipeline against a real device (or any pyserial URL), with the demo's
live status line and report. Ctrl-C (or SIGTERM) ends it cleanly: the report is printed and
the recording finalised."""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import click
import numpy as np

from exohil.formats import strict_json
from exohil.formats.atomic import write_text
from exohil.harness.bench import BenchConfig
from exohil.harness.cli_types import (
    MAX_DURATION_S,
    MAX_RATE_HZ,
    DeviceUrl,
    Finite,
    InputFile,
    OutputDir,
    OutputFile,
    Robot,
    refuse_overwriting_inputs,
)
from exohil.harness.pipeline import Status

#: The exit status of a run whose device was lost before its end (the report is written).
EXIT_DEVICE_LOST = 3


def status_line(status: Status) -> None:
    """The live status line (stderr), about once a second: frames, drops, CRC errors, the
    end-to-end latency p99 and the running error (arm direction, against the reference) of
    the last second, and the latest estimate."""
    link = status.link
    latency = status.recent_latency_ms
    p99 = f"  p99 {np.percentile(latency, 99):5.1f} ms" if latency.size else ""
    error = "" if status.error_deg is None else f"  arm error {status.error_deg:5.1f}°"
    angles = ("" if status.last is None else
              "  estimate " + " ".join(f"{v:6.1f}°" for v in status.last))
    click.echo(f"  {status.frames:6d} frames  dropped {link.dropped}  crc errors "
               f"{link.crc_errors}{p99}{error}{angles}", err=True)


@contextmanager
def stop_on_signals() -> Iterator[threading.Event]:
    """An event set by SIGINT or SIGTERM while the block runs (previous handlers restored);
    one this process ignores (SIGINT, in a command a script starts in the background) stays
    ignored."""
    stop = threading.Event()

    def handler(signum, frame) -> None:
        if stop.is_set():  # a second Ctrl-C: give up on a clean end
            raise KeyboardInterrupt
        click.echo("\nstopping (again to abort) ...", err=True)
        stop.set()

    previous = {sig: signal.signal(sig, handler) for sig in (signal.SIGINT, signal.SIGTERM)
                if signal.getsignal(sig) is not signal.SIG_IGN}
    try:
        yield stop
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


def _inputs(config: BenchConfig) -> list[Path | None]:
    device = config.device
    return [config.model, getattr(device, "recording", None), getattr(device, "reference", None)]


def _refuse_calibration_frames(config: BenchConfig) -> None:
    """Refuse (a usage error) to score a calibrated model against ground truth that holds
    its calibration frames (evaluate's rule): they are its training data. A model or
    recording that cannot be read is left to the session to report."""
    from exohil.estimator.checkpoint import CheckpointError, load_checkpoint
    from exohil.formats.errors import RecordingError
    from exohil.formats.recording_metadata import source_entry
    from exohil.formats.recording_reader import read_recording
    from exohil.harness.cmd_train import refuse_calibration_frames

    device = config.device
    scored = getattr(device, "recording", None) or getattr(device, "reference", None)
    if config.model is None or scored is None:
        return
    try:
        info = load_checkpoint(config.model).info
        if not any(s.get("role") == "calibration" for s in info.get("sources", [])):
            return
        rec = read_recording(scored)
    except (CheckpointError, RecordingError, OSError):
        return
    label = "--reference" if getattr(device, "reference", None) else "--recording"
    # every frame of it, whatever part of it the run reaches
    refuse_calibration_frames(info, [(source_entry(scored, rec), rec.sensors.t)], label)


def _outputs(config: BenchConfig, json_out: Path | None,
             out_dir: Path | None) -> list[tuple[str, Path | None]]:
    """Every file the run writes, with the option that names it."""
    from exohil.harness.demo_report import REPORT_FILES, report_files_in

    outputs = [("--record", config.record), ("--json", json_out)]
    if out_dir is not None:
        outputs += [("--out", out_dir / name) for name in REPORT_FILES]
        # the report replaces or removes every numbered arm still (arm_NNNNN.png) in the folder
        outputs += [("--out", path) for path in report_files_in(out_dir)
                    if path.name not in REPORT_FILES]
    return outputs


def _span(config: BenchConfig, seconds: float | None) -> str:
    """How long the run lasts, for its header line."""
    from exohil.harness.bench import EmulatorDevice, SerialDevice

    device = config.device
    if seconds is not None:
        return f"{seconds:g} s"
    if isinstance(device, SerialDevice) and device.reference is not None:
        return "until the device's clock passes the reference's end (or Ctrl-C)"
    if isinstance(device, EmulatorDevice) and not device.loop:
        return "to the end of the recording (or Ctrl-C)"
    return "until Ctrl-C"


def run_and_report(config: BenchConfig, seconds: float | None, json_out: Path | None,
                   title: str, out_dir: Path | None = None) -> dict:
    """Run one session on ``config``, print the report, write the JSON and, with ``out_dir``,
    the report folder (``demo_report``); returns the summary. A device lost before the end
    exits with :data:`EXIT_DEVICE_LOST` once everything is written."""
    from exohil.harness.session import SessionError, run_session
    from exohil.harness.session_report import session_measurements, summary, summary_lines

    refuse_overwriting_inputs(_outputs(config, json_out, out_dir), _inputs(config))
    _refuse_calibration_frames(config)
    # the folders made for the report, outermost first, removed again if the run fails
    made = [] if out_dir is None else [p for p in (*reversed(out_dir.parents), out_dir)
                                       if not p.exists()]
    if out_dir is not None:  # refused before any work, like the output files
        try:
            out_dir.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise click.ClickException(f"cannot create the report folder {out_dir}: "
                                       f"{err.strerror or err}") from None
    span = _span(config, seconds)
    model = config.model.name if config.model else "?"
    device = config.device.describe() if config.device else "?"
    click.echo(f"{title}: {device} → acquisition → {model} → NAO, {span}", err=True)
    with stop_on_signals() as stop:
        try:
            result = run_session(config, seconds, progress=status_line, stop=stop)
        except SessionError as err:
            for folder in reversed(made):  # only while empty: nothing written is removed
                try:
                    folder.rmdir()
                except OSError:
                    break
            raise click.ClickException(str(err)) from None
    measurements = session_measurements(result)
    s = summary(result, measurements)
    if json_out is not None:
        write_text(json_out, strict_json.dumps(s, indent=2) + "\n")
    lines = summary_lines(s)
    if config.record is not None:
        lines.append(f"recorded    {config.record}")
    if json_out is not None:
        lines.append(f"summary     {json_out}")
    if out_dir is not None:
        from exohil.harness.demo_report import write_report

        try:
            files, notes = write_report(result, s, out_dir)
        except OSError as err:
            raise click.ClickException(f"cannot write the report to {out_dir}: {err}") from None
        lines += [f"note        {n}" for n in notes]
        lines.append(f"report      {out_dir}/")
        lines += [f"            {path}  ({label})" for label, path in files]
    click.echo("\n".join(lines))
    if s.get("device_lost"):  # a script must not take a run cut short for a whole one
        click.echo(f"{title}: the device was lost before the end (exit status "
                   f"{EXIT_DEVICE_LOST})", err=True)
        raise SystemExit(EXIT_DEVICE_LOST)
    return s


@click.command("run")
@click.argument("url", type=DeviceUrl(), required=False)
@click.option("--model", type=InputFile(), default=None,
              help="Estimator checkpoint [default: the bench's, else the reference ENNet].")
@click.option("--bench", "bench_file", type=InputFile(), default=None,
              help="Bench configuration (TOML); URL and options override it.")
@click.option("--sink", "sinks", type=Robot(), multiple=True,
              help="Robot the commands go to (repeatable): simulated (bookkeeping only, the "
                   "default), mujoco (NAO's arms simulated in MuJoCo), udp:HOST:PORT (one JSON "
                   "datagram per command, docs/robot.md), or none.")
@click.option("--reference", type=InputFile(), default=None,
              help="Ground truth recording of this session (aligned by device time); without "
                   "it accuracy is not measured.")
@click.option("--record", "record_path", type=OutputFile(), default=None,
              help="Write the frames the host received to this recording (MCAP).")
@click.option("--duration", type=Finite(0.1, MAX_DURATION_S), default=None,
              help="Seconds to run [default: until Ctrl-C].")
@click.option("--rate", type=Finite(0.0, MAX_RATE_HZ, min_open=True), default=None,
              help="The device's frame rate, Hz, written into what the run records "
                   "[default: the bench's, else the reference's, else 250]. The run warns "
                   "when the device's own timestamps show a rate more than 1% away, and "
                   "records that measured rate beside it.")
@click.option("--backend", type=click.Choice(["auto", "numpy", "torch", "torchscript",
                                              "onnxruntime"]), default=None,
              help="Streaming inference backend [auto].")
@click.option("--json", "json_out", type=OutputFile(), default=None,
              help="Write the summary JSON here.")
@click.option("--out", "out_dir", type=OutputDir(), default=None,
              help="Also write a report folder here (summary, plots, arm pictures with --sink "
                   "mujoco, run.mcap).")
def run(url: str | None, model: Path | None, bench_file: Path | None, sinks: tuple[str, ...],
        reference: Path | None, record_path: Path | None, duration: float | None,
        rate: float | None, backend: str | None, json_out: Path | None,
        out_dir: Path | None) -> None:
    """Run the pipeline on the device at URL (a serial port such as /dev/ttyACM0, a pty
    printed by `exohil emulate`, or any pyserial URL such as socket://host:port) [default:
    the bench's; a URL alone keeps the bench's reference].

    Exit status 0 when the run ended as asked (its duration, the reference's end or Ctrl-C);
    3 when the device was lost before that: no frame for 10 s, or, with a reference, its last
    frame short of the reference's end (the report is still written); 1 for
    an error (no frame at all, a bad file), 2 for a bad command line."""
    from exohil.harness.bench import BenchError, SerialDevice, load_bench
    from exohil.harness.paths import MODELS_DIR

    try:
        config = load_bench(bench_file) if bench_file else BenchConfig()
    except BenchError as err:
        raise click.ClickException(str(err)) from None
    robots = None
    if sinks:
        robots = tuple(s for s in sinks if s != "none")
    bench_device = config.device if isinstance(config.device, SerialDevice) else None
    if url is None:
        if bench_device is None:
            raise click.UsageError("give the device's URL, or a --bench file whose [device] "
                                   "names a serial device (url)")
        url = bench_device.url
    if reference is None and bench_device is not None:
        reference = bench_device.reference
    config = config.with_overrides(
        device=SerialDevice(url, reference), model=model or config.model or
        MODELS_DIR / "ennet.npz", backend=backend, record=record_path, robots=robots,
        rate_hz=rate)
    run_and_report(config, duration, json_out, title="exohil run", out_dir=out_dir)


COMMANDS = [run]
