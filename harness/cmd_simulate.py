"""``exohil simulate``: write a simulated suit recording (MCAP, recording format v1)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click

from exohil.emulators.effects import EFFECT_TYPES
from exohil.harness.cli_types import InputFile, OutputFile, Seed, refuse_overwriting_inputs

if TYPE_CHECKING:  # imported when a command runs: `exohil --help` stays quick
    from exohil.emulators.discrepancy.profile import CalibratedSuit
    from exohil.formats.recording import Recording


def _mot_files(protocol: str) -> list[Path]:
    return [Path(p) for p in protocol[4:].split(",")] if protocol.startswith("mot:") else []


def _replayed_file(protocol: str) -> Path | None:
    return Path(protocol[len("replay:"):]) if protocol.startswith("replay:") else None


def _replayed_name(protocol: str) -> str:
    """The file name of the recording ``replay:FILE`` replays, as messages and metadata give
    it."""
    replayed = _replayed_file(protocol)
    assert replayed is not None, "called for a replay only"
    return replayed.name


def _input_files(protocol: str) -> list[Path]:
    """The files the movement is read from."""
    replayed = _replayed_file(protocol)
    return _mot_files(protocol) + ([replayed] if replayed else [])


def _trajectory(protocol: str, seed: int, replayed: Recording | None):
    """The shoulder movement ``protocol`` names (``replayed``: the recording it replays)."""
    from exohil.emulators.protocols import (
        calibration_protocol,
        mot_trajectory,
        paper_protocol,
        replay_trajectory,
    )

    if protocol == "paper":
        return paper_protocol(seed)
    if protocol == "calibration":
        return calibration_protocol(seed)
    try:
        if replayed is not None:
            return replay_trajectory(replayed, _replayed_name(protocol))
        return mot_trajectory([Path(p) for p in protocol[4:].split(",")])
    except ValueError as exc:
        raise click.ClickException(str(exc)) from exc


def _names_a_file(name: str) -> bool:
    """``name`` is the path of a file that exists (not blank, no NUL byte)."""
    return bool(name.strip()) and "\x00" not in name and Path(name).is_file()


class Protocol(click.ParamType):
    """``paper``, ``calibration``, ``mot:FILE[,FILE...]`` with every .mot file present, or
    ``replay:FILE`` with the recording present."""

    name = "protocol"

    def convert(self, value, param, ctx):
        text = str(value)
        if text in ("paper", "calibration"):
            return text
        if text.startswith("replay:"):
            name = text[len("replay:"):]
            if not _names_a_file(name):
                self.fail(f"no such recording: {name!r}", param, ctx)
            return text
        if not text.startswith("mot:") or not text[4:]:
            self.fail(f"{text!r}: use 'paper', 'calibration', 'mot:FILE[,FILE...]' or "
                      "'replay:FILE'", param, ctx)
        for name in text[4:].split(","):
            if not _names_a_file(name):
                self.fail(f"no such .mot file: {name!r}", param, ctx)
        return text


class EffectKind(click.Choice):
    """One of the effect kinds of :data:`~exohil.emulators.effects.EFFECT_TYPES`."""

    def __init__(self) -> None:
        super().__init__(list(EFFECT_TYPES))

    def get_invalid_choice_message(self, value, ctx) -> str:
        return f"unknown effect kind {value!r}; known: {', '.join(EFFECT_TYPES)}"


@click.command("simulate")
@click.option("--protocol", type=Protocol(), default="paper", show_default=True,
              metavar="paper|calibration|mot:FILE[,FILE]|replay:FILE",
              help="Movement: the paper's Table III protocol (246 s, seeded); 'calibration', "
                   "the 60 s calibration recording a new wearer makes (stand, flexion-"
                   "extension, abduction, plane sweeps, slow and fast reaching, stand; "
                   "seeded; docs/suit-model.md); real motion from OpenSim .mot files "
                   "(comma-separated, concatenated in order); or 'replay:FILE', the motion "
                   "capture of a recording: the shoulder's, from 0 s at its first sample; "
                   "with a calibrated profile, the joint it was calibrated on (a knee, an "
                   "elbow, ...), on the recording's own clock.")
@click.option("--profile", "profile_path", type=InputFile(), default=None,
              help="Suit profile TOML (default: the packaged default profile), or a "
                   "calibrated suit profile written by `exohil discrepancy` "
                   "(DIR/suit_profile.toml).")
@click.option("--seed", type=Seed(), default=0, show_default=True,
              help="Seed for the protocol and every random effect.")
@click.option("--without", "without", multiple=True, metavar="KIND",
              type=EffectKind(),
              help="Drop effects of this kind (hysteresis, creep, saturation, lag, drift, noise, "
                   "quantization, dropout, gain) from the profile's chain (repeatable). A "
                   "calibrated profile takes only 'noise': its effects were fitted together "
                   "with its static map.")
@click.option("--out", "out_path", required=True, type=OutputFile(),
              help="Output recording (.mcap).")
def simulate_command(protocol: str, profile_path: Path | None, seed: int,
                     without: tuple[str, ...], out_path: Path) -> None:
    """Simulate the suit following a movement and write a recording.

    Sensors (tendon path lengths, mm) at 250 Hz after the profile's effect chain, ground-truth
    shoulder angles at 120 Hz on /mocap/shoulder, movement segments and provenance metadata.
    With a calibrated profile (from `exohil discrepancy`) the sensors are those it was
    calibrated on, in its units and at its rate, with its white noise; a movement that
    leaves the angles it was calibrated on gets a warning line (the map extrapolates there).
    A calibrated profile's replay writes the angles as recorded, on their joint's stream;
    every replay carries the replayed recording's license and source notes.

    \b
    Examples:
      exohil simulate --protocol paper --seed 7 --out paper.mcap
      exohil simulate --protocol calibration --seed 3 \\
          --profile emulators/profiles/donning-b.toml --out calibration.mcap
      exohil simulate --protocol mot:ABD01.mot,FLX01.mot --without noise --out real.mcap
      exohil simulate --profile disc/suit_profile.toml --out calibrated.mcap
      exohil simulate --profile disc/suit_profile.toml --protocol replay:knee.mcap \\
          --out knee-sim.mcap
    """
    from exohil.emulators.discrepancy.profile import CalibratedSuit, load_any_profile
    from exohil.emulators.suit_profile import ProfileError, load_default_profile

    refuse_overwriting_inputs([("--out", out_path)], [profile_path, *_input_files(protocol)])
    try:
        profile = load_default_profile() if profile_path is None else load_any_profile(
            profile_path)
    except ProfileError as exc:
        raise click.ClickException(str(exc)) from exc
    replayed = _read_replayed(protocol)
    if isinstance(profile, CalibratedSuit):
        recording = _calibrated(profile, protocol, seed, without, replayed)
    else:
        from exohil.emulators.simulate import simulate

        trajectory = _trajectory(protocol, seed, replayed)
        click.echo(f"simulating {trajectory.duration_s:.1f} s of {trajectory.source} on suit "
                   f"profile '{profile.name}'", err=True)
        recording = simulate(trajectory, profile, seed, effects=profile.effects.without(*without))
    _carry_notices(recording, _mot_files(protocol))
    if replayed is not None:
        _carry_terms(recording, replayed)
    if recording.sensor_units == "mm":
        _warn_beyond_the_wire(recording)
    _write(out_path, recording)


def _carry_notices(recording: Recording, mot_files: list[Path]) -> None:
    """Store the license and source notes beside the real motion's .mot files in the
    recording's metadata (their terms go with what derives from them, as on import), with a
    warning line where none is found."""
    from exohil.harness.cmd_import import notices_beside

    for mot in mot_files:
        notices = notices_beside(mot)
        if not notices:
            click.echo(f"warning: no LICENSE or SOURCE file beside {mot.name}: the recording "
                       "names no license for its real motion", err=True)
        for key, text in notices.items():
            if recording.metadata.setdefault(key, text) != text:  # same name, other folder
                recording.metadata[f"{key}@{mot.parent.name}"] = text


def _read_replayed(protocol: str) -> Recording | None:
    """The recording ``replay:FILE`` names (None for another protocol); one error line where
    it cannot be read."""
    path = _replayed_file(protocol)
    if path is None:
        return None
    from exohil.formats.errors import RecordingError
    from exohil.formats.recording_reader import read_recording

    try:
        return read_recording(path)
    except (OSError, RecordingError) as exc:
        raise click.ClickException(f"cannot read {path}: {exc}") from exc


#: Metadata keys of a replayed recording that go with what is simulated from its motion: its
#: license and where it came from (``notice.<file>``: the text of each note beside the data it
#: was imported from).
CARRIED_KEYS = ("license", "source", "source_sha256")


def _carry_terms(recording: Recording, replayed: Recording) -> None:
    """Store the license and source notes of the recording whose motion was replayed in
    ``recording``'s metadata, under ``replayed.<key>`` (the terms of real motion go with
    what derives from it)."""
    for key, text in replayed.metadata.items():
        if key in CARRIED_KEYS or key.startswith("notice."):
            recording.metadata[f"replayed.{key}"] = text


def _warn_beyond_the_wire(recording: Recording) -> None:
    """A warning line naming each sensor with readings outside the wire's 0..655.35 mm: the
    emulator (and so demo, run and conform) clips them; evaluate, train and calibrate do not.
    Another when the recording has more sensors than a wire frame carries."""
    from exohil.formats.wire import MAX_SENSORS, MAX_VALUE_MM

    if len(recording.sensor_names) > MAX_SENSORS:
        click.echo(f"warning: {len(recording.sensor_names)} sensors; a wire protocol v1 frame "
                   f"carries at most {MAX_SENSORS}, so the emulator (demo, run, conform) "
                   "refuses this recording; evaluate, train and calibrate read it", err=True)
    values = recording.sensors.values
    if not len(values):
        return
    outside = ((values < 0) | (values > MAX_VALUE_MM)).mean(axis=0)
    shares = [f"{name} {100 * share:.1f} %" for name, share in
              zip(recording.sensor_names, outside, strict=True) if share > 0]
    if shares:
        click.echo(f"warning: readings outside the wire's 0..{MAX_VALUE_MM:g} mm on "
                   f"{', '.join(shares)} of the frames: the emulator (demo, run, conform) "
                   "clips them there, as a pot at the end of its travel would; evaluate, "
                   "train and calibrate read them unclipped", err=True)


def _calibrated(suit: CalibratedSuit, protocol: str, seed: int, without: tuple[str, ...],
                replayed: Recording | None) -> Recording:
    """The recording of the calibrated ``suit`` following ``protocol`` (``replayed``: the
    recording it replays, of the joint ``suit`` was calibrated on; noise-free with
    ``--without noise``; any other ``--without`` is refused), with a warning line where the
    movement leaves the angles the suit was calibrated on."""
    from exohil.emulators.discrepancy.profile import (
        outside_calibration,
        outside_range,
        replay_calibrated_recording,
        simulate_calibrated_recording,
    )
    from exohil.emulators.suit_profile import ProfileError

    others = sorted(set(without) - {"noise"})
    if others:
        raise click.ClickException(
            f"--without {', '.join(others)}: a calibrated profile's effects "
            f"({', '.join(suit.effects) or 'none'}) were fitted together with its static map, "
            "so they cannot be dropped one by one; only --without noise applies")
    described = (f"on calibrated suit profile '{suit.name}' ({len(suit.sensors)} sensors, "
                 f"{suit.units}, {suit.rate_hz:.4g} Hz; effects: "
                 f"{', '.join(suit.effects) or 'none'})")
    if replayed is not None:
        name = _replayed_name(protocol)
        try:
            recording = replay_calibrated_recording(replayed, suit, seed, name,
                                                    noise="noise" not in without)
        except ValueError as exc:
            raise click.ClickException(str(exc)) from exc
        t = recording.sensors.t
        click.echo(f"simulating {t[-1] - t[0]:.1f} s of {recording.metadata['trajectory']} "
                   f"(its clock, from {t[0]:.6g} s) {described}", err=True)
        _warn_outside(suit, outside_range(suit, recording.mocap[suit.joint].angles),
                      "motion-capture samples")
        return recording
    trajectory = _trajectory(protocol, seed, None)
    try:
        outside = outside_calibration(suit, trajectory)
    except ProfileError as exc:
        raise click.ClickException(str(exc)) from exc
    click.echo(f"simulating {trajectory.duration_s:.1f} s of {trajectory.source} {described}",
               err=True)
    _warn_outside(suit, outside, "frames")
    return simulate_calibrated_recording(trajectory, suit, seed, noise="noise" not in without)


def _warn_outside(suit: CalibratedSuit, outside: dict[str, float], counted: str) -> None:
    """A warning line where the movement leaves the angles ``suit`` was calibrated on
    (``outside``: the share of its ``counted`` beyond each angle's range)."""
    if not outside:
        return
    lo, hi = suit.inputs.angle_lo, suit.inputs.angle_hi
    click.echo("warning: the movement leaves the angles the profile was calibrated on ("
               + "; ".join(f"{a} {lo[k]:.0f}…{hi[k]:.0f}° on {100 * outside[a]:.1f} % of "
                           f"the {counted}" for k, a in enumerate(suit.angles) if a in outside)
               + "): the calibrated map extrapolates there", err=True)


def _write(out_path: Path, recording: Recording) -> None:
    """Write ``recording`` to ``out_path``; one error line where it cannot be written."""
    from exohil.formats.errors import RecordingError
    from exohil.formats.recording_writer import write_recording

    try:
        write_recording(out_path, recording)
    except (OSError, RecordingError) as exc:
        raise click.ClickException(f"cannot write {out_path}: {exc}") from exc
    click.echo(f"wrote {out_path} ({len(recording.sensors)} sensor frames)", err=True)


COMMANDS: list[click.Command] = [simulate_command]
