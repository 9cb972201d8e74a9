"""``exohil simulate``: write a simulated suit recording (MCAP, recording format v1)."""

from __future__ import annotations

from pathlib import Path

import click

from exohil.harness.cli_types import OutputFile, refuse_overwriting_inputs


def _mot_files(protocol: str) -> list[Path]:
    return [Path(p) for p in protocol[4:].split(",")] if protocol.startswith("mot:") else []


def _trajectory(protocol: str, seed: int):
    from exohil.emulators.protocols import mot_trajectory, paper_protocol

    if protocol == "paper":
        return paper_protocol(seed)
    if protocol.startswith("mot:") and protocol[4:]:
        paths = _mot_files(protocol)
        missing = [str(p) for p in paths if not p.is_file()]
        if missing:
            raise click.BadParameter(f"no such .mot file: {', '.join(missing)}",
                                     param_hint="--protocol")
        try:
            return mot_trajectory(paths)
        except ValueError as exc:
            raise click.ClickException(str(exc)) from exc
    raise click.BadParameter(f"{protocol!r}: use 'paper' or 'mot:FILE[,FILE...]'",
                             param_hint="--protocol")


@click.command("simulate")
@click.option("--protocol", default="paper", show_default=True, metavar="paper|mot:FILE[,FILE]",
              help="Movement: the paper's Table III protocol (seeded), or real motion from "
                   "OpenSim .mot files (comma-separated, concatenated in order).")
@click.option("--profile", "profile_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="Suit profile TOML (default: the packaged default profile).")
@click.option("--seed", type=int, default=0, show_default=True,
              help="Seed for the protocol and every random effect.")
@click.option("--without", "without", multiple=True, metavar="KIND",
              help="Drop effects of this kind (hysteresis, creep, saturation, lag, drift, noise, "
                   "quantization, dropout) from the profile's chain (repeatable).")
@click.option("--out", "out_path", required=True,
              type=OutputFile(), help="Output recording (.mcap).")
def simulate_command(protocol: str, profile_path: Path | None, seed: int,
                     without: tuple[str, ...], out_path: Path) -> None:
    """Simulate the suit following a movement and write a recording.

    Sensors (tendon path lengths, mm) at 250 Hz after the profile's effect chain, ground-truth
    shoulder angles at 120 Hz on /mocap/shoulder, movement segments and provenance metadata.

    \b
    Examples:
      exohil simulate --protocol paper --seed 7 --out paper.mcap
      exohil simulate --protocol mot:ABD01.mot,FLX01.mot --without noise --out real.mcap
    """
    from exohil.emulators.effects import EFFECT_TYPES
    from exohil.emulators.simulate import simulate
    from exohil.emulators.suit_profile import ProfileError, load_default_profile, load_profile
    from exohil.formats.errors import RecordingError
    from exohil.formats.recording_writer import write_recording

    refuse_overwriting_inputs([("--out", out_path)], [profile_path, *_mot_files(protocol)])

    unknown = sorted(set(without) - set(EFFECT_TYPES))
    if unknown:
        raise click.BadParameter(f"unknown effect kind(s) {', '.join(unknown)}; "
                                 f"known: {', '.join(EFFECT_TYPES)}", param_hint="--without")
    try:
        profile = load_default_profile() if profile_path is None else load_profile(profile_path)
    except ProfileError as exc:
        raise click.ClickException(str(exc)) from exc
    trajectory = _trajectory(protocol, seed)
    click.echo(f"simulating {trajectory.duration_s:.1f} s of {trajectory.source} on suit "
               f"profile '{profile.name}'", err=True)
    recording = simulate(trajectory, profile, seed, effects=profile.effects.without(*without))
    try:
        write_recording(out_path, recording)
    except (OSError, RecordingError) as exc:
        raise click.ClickException(f"cannot write {out_path}: {exc}") from exc
    click.echo(f"wrote {out_path} ({len(recording.sensors)} sensor frames)", err=True)


COMMANDS: list[click.Command] = [simulate_command]
