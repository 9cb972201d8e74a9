"""``exohil emulate``: a software Arduino streaming a recording over a virtual serial port."""

from __future__ import annotations

import json
import signal
import sys
import time
from collections import Counter
from pathlib import Path

import click

from exohil.formats.atomic import write_text
from exohil.harness.cli_types import (
    MAX_DURATION_S,
    MAX_RATE_HZ,
    FaultSpec,
    Finite,
    InputFile,
    OutputFile,
    Seed,
    refuse_overwriting_inputs,
)


def _load_recording(path: Path):
    from exohil.formats.errors import RecordingError
    from exohil.formats.recording_reader import read_recording
    from exohil.formats.wire import off_the_wire

    try:
        recording = read_recording(path)
    except RecordingError as exc:
        raise click.ClickException(str(exc)) from exc
    why = off_the_wire(recording.sensor_units)
    if why is not None:
        raise click.ClickException(f"{path}: {why}")
    if len(recording.sensors) == 0:
        raise click.ClickException(f"{path}: the recording has no sensor frames")
    return recording


def _warn_of_another_rate(path: Path, recording) -> None:
    """One warning line when the frames' timestamps give another rate than the metadata's
    sensor_rate_hz, at which the frames are streamed (another tool's recording)."""
    from exohil.formats.recording_metadata import rate_the_times_give

    measured = rate_the_times_give(recording)
    if measured is not None:
        click.echo(f"warning: {path}: metadata sensor_rate_hz={recording.sensor_rate_hz:g} but "
                   f"its timestamps give {measured:.4g} Hz; streaming at "
                   f"{recording.sensor_rate_hz:g} Hz (--rate to choose)", err=True)


def _write_fault_log(path: Path, emulator) -> None:
    write_text(path, "".join(json.dumps({"seq": r.seq, "kind": r.kind, "details": r.details},
                                        default=str) + "\n" for r in emulator.fault_log))


def _raise_interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt


@click.command("emulate")
@click.argument("recording", type=InputFile())
@click.option("--rate", type=Finite(0.0, MAX_RATE_HZ, min_open=True), default=None,
              help="Frame rate, Hz [default: the recording's sensor rate, so that device "
                   "time is the recording's time and `run --reference` aligns with it].")
@click.option("--loop", is_flag=True, help="Replay the recording cyclically.")
@click.option("--faults", type=FaultSpec(), default=None, metavar="SPEC|FILE.toml",
              help="Faults to inject, e.g. 'noise:sigma_mm=0.5;drop:rate=0.01,burst=3;"
                   "corrupt:rate=0.001;truncate:rate=0.001;stall:every_s=5,duration_ms=40;"
                   "disconnect:at_s=10,for_s=0.5' or a TOML file of [[fault]] tables "
                   "(see docs/emulator.md).")
@click.option("--seed", type=Seed(), default=0, show_default=True,
              help="Seed for every random fault.")
@click.option("--duration", type=Finite(0.0, MAX_DURATION_S, min_open=True), default=None,
              help="Stop after this many seconds of device time (default: end of the "
                   "recording, or never with --loop).")
@click.option("--spin-ms", "spin_ms", type=Finite(0.0, 100.0), default=0.3,
              show_default=True,
              help="Spin on the clock for this long before each deadline (absorbs late "
                   "wake-ups on a loaded machine, costs CPU).")
@click.option("--realtime", is_flag=True,
              help="Pace under SCHED_FIFO (Linux, needs CAP_SYS_NICE): tighter timing on a "
                   "loaded machine; falls back with a warning when refused.")
@click.option("--fault-log", "fault_log", type=OutputFile(),
              default=None, help="Write every injected fault as JSON lines here on exit.")
def emulate_command(recording: Path, rate: float | None, loop: bool, faults: str | None, seed: int,
                    duration: float | None, spin_ms: float, realtime: bool,
                    fault_log: Path | None) -> None:
    """Stream RECORDING's sensor frames (wire protocol v1) from a software Arduino on a pty.

    The first line of stdout is the device path to open (a stable link that survives
    emulated disconnects); open it with any serial client (pyserial, the harness).
    Frames are paced on absolute deadlines; progress and a fault summary go to stderr.
    Stop with Ctrl-C.

    \b
    Examples:
      exohil emulate fixtures/paper_protocol.mcap --loop
      exohil emulate rec.mcap --faults 'drop:rate=0.01,burst=3;stall:every_s=5,duration_ms=40'
    """
    # SIGTERM stops it as Ctrl-C does, from the start: reading a long recording takes seconds
    # (a SIGTERM then ended it with status 143 and no word); the previous handler comes back
    # when the command returns
    previous = signal.signal(signal.SIGTERM, _raise_interrupt)
    try:
        _emulate(recording, rate, loop, faults, seed, duration, spin_ms, realtime, fault_log)
    finally:
        signal.signal(signal.SIGTERM, previous)


def _done(generated: int, written: int, read: int, faults: str) -> None:
    click.echo(f"done: {generated} frames generated, {written} handed to the host, {read} "
               f"read by it; faults: {faults}", err=True)


def _emulate(recording: Path, rate: float | None, loop: bool, faults: str | None, seed: int,
             duration: float | None, spin_ms: float, realtime: bool,
             fault_log: Path | None) -> None:
    checked = False  # whether --fault-log may be written: it replaces no input
    try:
        from exohil.emulators.arduino import ArduinoEmulator
        from exohil.emulators.fault_spec import check_sensor_count, fault_plan

        # a --faults FILE.toml is an input too: the fault log must not replace it
        refuse_overwriting_inputs([("--fault-log", fault_log)],
                                  [recording, *([Path(faults)] if faults else [])])
        checked = True
        source = _load_recording(recording)
        if rate is None:
            _warn_of_another_rate(recording, source)
        try:
            plan = fault_plan(faults)
            check_sensor_count(plan, len(source.sensor_names))
        except (ValueError, OSError) as exc:
            raise click.BadParameter(str(exc), param_hint="--faults") from exc
        try:
            # from the recording: its own sequence numbers and clock, as the in-process
            # emulator
            emulator = ArduinoEmulator(source, rate_hz=rate or source.sensor_rate_hz,
                                       loop=loop, duration_s=duration, faults=plan, seed=seed,
                                       spin_s=spin_ms / 1000.0, realtime=realtime)
        except ValueError as exc:
            raise click.ClickException(str(exc)) from exc
    except KeyboardInterrupt:  # stopped before streaming: the end a later stop has, at 0
        if fault_log is not None and checked:
            write_text(fault_log, "")
        _done(0, 0, 0, "none")
        return
    try:
        try:
            emulator.start()
        except RuntimeError as exc:
            raise click.ClickException(str(exc)) from exc
        click.echo(emulator.port)
        sys.stdout.flush()
        if emulator.realtime_error:
            click.echo(f"warning: {emulator.realtime_error}; pacing without it", err=True)
        if emulator.clipped_values:
            click.echo(f"warning: {emulator.clipped_values} values outside 0..655.35 mm "
                       "were clipped", err=True)
        next_report = time.monotonic() + 5.0
        while not emulator.wait_finished(0.2):
            if time.monotonic() >= next_report:
                next_report += 5.0
                click.echo(f"{emulator.frames_generated} frames, "
                           f"{emulator.frames_written} handed to the host", err=True)
    except KeyboardInterrupt:
        pass
    finally:
        emulator.stop()
        if fault_log is not None:
            _write_fault_log(fault_log, emulator)
    if emulator.error is not None:
        raise click.ClickException(f"emulator failed: {emulator.error}")
    counts = Counter(record.kind for record in emulator.fault_log)
    _done(emulator.frames_generated, emulator.frames_written, emulator.frames_read,
          ", ".join(f"{kind} {n}" for kind, n in sorted(counts.items())) or "none")


COMMANDS = [emulate_command]
