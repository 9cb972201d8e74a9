"""``exohil discrepancy``: where simulation and measurement disagree, and which effect is
missing (docs/discrepancy.md)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING

import click
import numpy as np

from exohil.harness.cli_types import Count, InputFile, OutputDir, refuse_overwriting_inputs

if TYPE_CHECKING:
    from exohil.formats.recording import Recording

#: Most processes ``--workers`` takes: a bound that refuses nonsense (a step has five
#: candidates at most, so more than five would idle).
MAX_WORKERS = 64
#: Memory a run has taken per sensor frame, at most as measured: 12.5 GB in use on the
#: machine, forked candidates included, for the 450,000 frames of a 30-minute recording
#: with seven tendons at 250 Hz (docs/discrepancy-results.md, Speed); 17–23 kB in the largest
#: process for four to seven sensors.
BYTES_PER_FRAME = 28_000
#: Exit status of a run stopped with Ctrl-C (128 + SIGINT, as a shell reports it).
INTERRUPTED = 130


def memory_warning(frames: int, available: int | None) -> str | None:
    """A progress line for a recording of ``frames`` sensor frames that may need more
    memory than the ``available`` bytes (None: unknown, no warning)."""
    need = frames * BYTES_PER_FRAME
    if available is None or need <= available:
        return None
    return (f"    warning: {frames:,} sensor frames may need up to {need / 1e9:.1f} GB "
            f"(about {BYTES_PER_FRAME // 1000} kB per frame as measured) and "
            f"{available / 1e9:.1f} GB are available: the run may be stopped by the system "
            f"before it ends; analyse the recording in parts (exohil record cut IN "
            f"--start S --stop S --out PART)")


def _in_model(profile_path: Path | None) -> tuple[str, tuple[str, ...], str | None]:
    """The profile's name, the vocabulary effects its model already has, and (for a
    calibrated profile) the sensors and unit it was calibrated on, in words."""
    from exohil.emulators.discrepancy import VOCABULARY
    from exohil.emulators.discrepancy.profile import CalibratedSuit, load_any_profile
    from exohil.emulators.suit_profile import ProfileError

    if profile_path is None:
        return "calibrated", (), None
    try:
        profile = load_any_profile(profile_path)
    except ProfileError as exc:
        raise click.ClickException(str(exc)) from exc
    if isinstance(profile, CalibratedSuit):
        return (profile.name, tuple(e for e in profile.effects if e in VOCABULARY),
                _sensors_words(profile.sensors, profile.units))
    kinds = {e.name for e in profile.effects.effects}
    return profile.name, tuple(k for k in VOCABULARY if k in kinds), None


def _usable(rec: Recording) -> tuple[str, ...]:
    """The recording's sensors the analysis will use: a dead channel it leaves out (method
    step 1) is not in a profile it wrote either."""
    from exohil.emulators.discrepancy.data import unusable_sensors

    if not len(rec.sensors):
        return tuple(rec.sensor_names)
    dead = {sensor for sensor, _ in unusable_sensors(np.asarray(rec.sensors.values),
                                                      rec.sensor_names, rec.sensor_units)}
    return tuple(s for s in rec.sensor_names if s not in dead)


def _sensors_words(sensors: tuple[str, ...], units: str) -> str:
    return (f"{len(sensors)} sensor{'' if len(sensors) == 1 else 's'} ({', '.join(sensors)}) "
            f"in {units}")


@click.command("discrepancy")
@click.argument("measured", type=InputFile())
@click.option("--profile", "profile_path", type=InputFile(),
              help="Current suit profile (geometric or calibrated TOML): the effects it already "
                   "has are fitted from the start and not proposed again. Its geometry is not "
                   "assumed; the static map is calibrated to the measurement.")
@click.option("--out", "out_dir", type=OutputDir(), default=Path("discrepancy"), show_default=True,
              help="Output folder: discrepancy.json, report.md, plots, suit_profile.toml.")
@click.option("--workers", type=Count(1, MAX_WORKERS), default=None,
              help="Processes that try each step's candidate effects at once (one per "
                   "candidate at most) and draw the two plots  [default: one per CPU]. The "
                   "result is the same for any number.")
def discrepancy(measured: Path, profile_path: Path | None, out_dir: Path,
                workers: int | None) -> None:
    """Find what the simulated suit gets wrong on MEASURED (sensors + motion capture), name
    the missing effect, add it, and show the held-out gap shrink, step by step.

    MEASURED needs sensor frames and a /mocap/<joint> stream of the joint's angles over at
    least 8 x 2.5 s of them. One progress line per step goes to stderr, then how long the
    run took (reading, analysis, writing the outputs); the last line, to stdout, names the
    effects added and the held-out gap (cross-validated RMS of simulation minus
    measurement, in the recording's units) before and after. Where it says "what
    remains ... none of the five effects explains", the written profile is the best fit
    found, not a faithful model of the suit. Exit status: 0 done (whatever was named), 1
    unusable recording or profile, 2 wrong command line, 130 stopped with Ctrl-C (the output
    folder left as it was). Every output: docs/discrepancy.md, "Outputs".

    Time and memory grow with the recording: a four-minute trial with seven tendons takes
    30-65 s on two cores (the machine's hour moves it), a thirty-minute one ten minutes and
    10 GB. Analyse a longer
    session in parts (exohil record cut), each of which holds out its own blocks; a
    recording that may need more memory than is available gets a warning line first.

    \b
    Example:
      exohil discrepancy trial.mcap --out disc/
      exohil record cut session.mcap --stop 900 --out part1.mcap
    """
    started = time.perf_counter()  # the imports of the analysis, about 2 s, are in its time
    from exohil.emulators.discrepancy.report import OUTPUT_NAMES

    refuse_overwriting_inputs([("--out", out_dir / name) for name in OUTPUT_NAMES],
                              [measured, profile_path])
    for name in OUTPUT_NAMES:  # found now, not after the analysis
        if (out_dir / name).is_dir():
            raise click.BadParameter(f"{out_dir / name} is a folder, so {name} cannot be "
                                     "written there (choose another output folder)",
                                     param_hint="'--out'")
    name, in_model, calibrated_on = _in_model(profile_path)
    try:
        summary, written = _analyse_and_write(measured, profile_path, out_dir, workers, name,
                                              in_model, calibrated_on, started)
    except KeyboardInterrupt:
        click.echo(f"interrupted: {out_dir} left as it was (no output of this run written)",
                   err=True)
        raise SystemExit(INTERRUPTED) from None
    click.echo(f"{summary['conclusion']}: held-out gap {summary['gap_before']:.4g} -> "
               f"{summary['gap_after']:.4g} {summary['units']}; wrote "
               f"{', '.join(str(p) for p in written)}")


def _analyse_and_write(measured: Path, profile_path: Path | None, out_dir: Path,
                       workers: int | None, name: str, in_model: tuple[str, ...],
                       calibrated_on: str | None, started: float
                       ) -> tuple[dict, list[Path]]:
    """Analyse ``measured`` and write the outputs into ``out_dir``: the run's summary and the
    files written. The last progress line says how long since ``started`` (the command's
    start, ``time.perf_counter``) and its parts (:func:`time_words`)."""
    from exohil.emulators.discrepancy import DiscrepancyError, run
    from exohil.emulators.discrepancy.report import write_outputs
    from exohil.emulators.discrepancy.workers import workers_for
    from exohil.formats.errors import RecordingError
    from exohil.formats.recording_reader import read_recording
    from exohil.harness.machine import available_memory_bytes

    reading_started = time.perf_counter()
    try:
        rec = read_recording(measured)
        read_s = time.perf_counter() - reading_started
        measured_on = _sensors_words(_usable(rec), rec.sensor_units)
        if calibrated_on is not None and calibrated_on != measured_on:
            click.echo(f"warning: {profile_path} was calibrated on {calibrated_on}, "
                       f"{measured.name} has {measured_on}: only its effects' names are "
                       "taken, and every term is fitted to this recording", err=True)
        warning = memory_warning(len(rec.sensors), available_memory_bytes())
        if warning is not None:
            click.echo(warning, err=True)
        analysis_started = time.perf_counter()
        outcome = run(rec, measured.name, in_model=in_model,
                      progress=lambda line: click.echo(line, err=True), workers=workers)
    except (RecordingError, DiscrepancyError) as exc:
        raise click.ClickException(str(exc)) from exc
    writing_started = time.perf_counter()
    written = write_outputs(outcome, out_dir, profile_name(name, measured.stem), workers)
    done = time.perf_counter()
    click.echo(time_words(done - started, read_s, writing_started - analysis_started,
                          done - writing_started, workers_for(workers)), err=True)
    return outcome.summary, written


def time_words(total_s: float, read_s: float, analysed_s: float, wrote_s: float,
               processes: int) -> str:
    """The command's wall-clock time (from its start, the analysis's imports included; the
    interpreter's start is not) and its parts, s, as the last progress line says it."""
    return (f"took {total_s:.1f} s: read {read_s:.1f} s, analysed {analysed_s:.1f} s, wrote "
            f"the outputs {wrote_s:.1f} s ({processes} process{'' if processes == 1 else 'es'})")


def profile_name(base: str, stem: str) -> str:
    """The written profile's name: the name of the profile the run started from (or
    "calibrated") and ``+`` the recording's stem, unless that recording is among those its
    name already holds: a run on top of a calibrated profile named itself
    ``calibrated+hyst+hyst``, one ``+hyst`` more with each run. The profile's
    ``description`` names the recording of the last run."""
    return base if f"+{stem}+" in f"{base}+" else f"{base}+{stem}"


COMMANDS: list[click.Command] = [discrepancy]
