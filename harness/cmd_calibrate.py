"""``exohil calibrate``: adapt a trained estimator to a new wearer or donning (logic in
:mod:`exohil.estimator.calibration`; see docs/calibration.md)."""

from __future__ import annotations

import click
import numpy as np

from exohil.estimator.defaults import CALIBRATION_JITTERS
from exohil.estimator.rates import RATE_REMEDY, rate_mismatch
from exohil.harness.cli_types import (
    Count,
    Finite,
    InputFile,
    OutputFile,
    Seed,
    refuse_overwriting_inputs,
    refuse_repeated_inputs,
)
from exohil.harness.cmd_train import (
    _accuracy_line,
    _command_line,
    _model_and_recordings,
)

#: Most fine-tuning steps accepted (far beyond any useful value; a typo cannot run for days).
MAX_STEPS = 1_000_000
#: Largest --jitter accepted (a σ of 10 training standard deviations drowns any signal).
MAX_JITTER = 10.0


@click.command("calibrate")
@click.argument("checkpoint", type=InputFile())
@click.argument("recordings", nargs=-1, required=True, type=InputFile())
@click.option("--out", required=True, type=OutputFile(),
              help="Calibrated checkpoint to write (.npz); must not be an input.")
@click.option("--steps", type=Count(1, MAX_STEPS), default=600, show_default=True,
              help="Fine-tuning steps (minibatches of 500 windows).")
@click.option("--jitter", type=Finite(0.0, MAX_JITTER), help="σ of the random per-sensor "
              "input offset, in the sensor's training standard deviations (the gain's is a "
              "third of it); default: the best of "
              f"{', '.join(map(str, CALIBRATION_JITTERS))} on the last quarter of the calibration "
              "data (docs/calibration.md).")
@click.option("--seed", type=Seed(), default=0, show_default=True,
              help="Seed of the minibatches and the input jitter.")
def calibrate_command(checkpoint, recordings, out, steps, jitter, seed):
    """Adapt CHECKPOINT to a new wearer or donning with calibration RECORDING files (sensors
    plus ground truth; 30–60 s of the calibration protocol in docs/calibration.md) and write
    the adapted model to --out.

    Every weight of the network is fine-tuned on the calibration frames, each window given a
    random per-sensor offset and gain (--jitter, chosen on held-out calibration frames
    unless given); 60 s of data take about 25 s on one CPU core. The new checkpoint
    records the base checkpoint's and the recordings' sha256, the method and the seconds used;
    the recordings count as training data, so score the calibrated model on other recordings
    of the same wearer. Example:

    \b
        exohil calibrate ennet.npz calib.mcap --out ennet-wearer2.npz
        exohil evaluate ennet-wearer2.npz wearer2-session.mcap
    """
    from exohil.estimator.calibration import (
        ADVISED_CALIBRATION_SECONDS,
        MIN_CALIBRATION_RANGE_DEG,
        MIN_CALIBRATION_SECONDS,
        CalibrationConfig,
        CalibrationError,
        calibrate,
    )
    from exohil.estimator.checkpoint import save_checkpoint
    from exohil.estimator.training import progress_printer
    from exohil.formats.digest import sha256_file
    from exohil.formats.recording_metadata import shared_frames

    refuse_overwriting_inputs([("--out", out)], [checkpoint, *recordings])
    refuse_repeated_inputs(("RECORDING", r) for r in recordings)
    base, data = _model_and_recordings(checkpoint, recordings)
    _refuse_copies(data.sources)
    other_rate = rate_mismatch(data.rate_hz, base.sensor_rate_hz)
    if other_rate:
        raise click.ClickException(f"{other_rate}; {RATE_REMEDY}")
    blocks = [b for b in data.blocks(base.offset_frames) if len(b)]
    seconds = sum(len(b) for b in blocks) / base.sensor_rate_hz
    if MIN_CALIBRATION_SECONDS <= seconds < ADVISED_CALIBRATION_SECONDS:
        click.echo(f"warning: {seconds:.1f} s of calibration frames with ground truth; the "
                   f"calibration protocol takes 60 s and {ADVISED_CALIBRATION_SECONDS:g} s or "
                   "more is advised (docs/calibration.md)", err=True)
    if seconds >= MIN_CALIBRATION_SECONDS:  # less is refused by calibrate(), one line alone
        spans = np.ptp(np.concatenate([b.y for b in blocks]), axis=0)
        if spans.max() < MIN_CALIBRATION_RANGE_DEG:
            click.echo(f"warning: the calibration frames' angles span {spans.max():.1f}° at "
                       f"most: one pose, which is all the model will be fitted to; calibrate "
                       "on the movements of the protocol (docs/calibration.md)", err=True)
        for source in data.sources:
            trained = [why for overlap, why in (shared_frames(source, s)
                                                for s in base.info.get("sources", [])) if overlap]
            if trained:
                click.echo(f"warning: {trained[0]}: it holds frames the model has fitted, so "
                           "the accuracy before is on training data and the jitter is chosen on "
                           "frames already seen; calibrate on a new recording of the wearer",
                           err=True)
    try:
        est = calibrate(base, blocks, CalibrationConfig(steps=steps, jitter=jitter, seed=seed),
                        base_source={"file": checkpoint.name, "sha256": sha256_file(checkpoint)},
                        sources=data.sources, progress=progress_printer())
    except CalibrationError as exc:
        raise click.ClickException(str(exc)) from None
    est.info["command"] = _command_line()
    save_checkpoint(out, est)
    cal = est.info["calibration"]
    chosen = " (chosen)" if cal["jitter_selection"] else ""
    click.echo(f"wrote {out} ({est.kind} calibrated on {cal['seconds']:g} s from "
               f"{len(recordings)} recording(s) in {cal['elapsed_s']:g} s, jitter "
               f"{cal['jitter']:g}{chosen})")
    click.echo("on the calibration frames (training data, not a test):")
    click.echo("  before " + _accuracy_line(cal["accuracy_before"]))
    click.echo("  after  " + _accuracy_line(cal["accuracy_after"]))


def _refuse_copies(sources: list[dict]) -> None:
    """Refuse (a usage error naming both) two calibration recordings with the same content
    (a copy under another name): its frames would count twice."""
    for i, source in enumerate(sources):
        for other in sources[:i]:
            if source["sha256"] == other["sha256"]:
                raise click.UsageError(
                    f"RECORDING {other['file']} and RECORDING {source['file']} hold the same "
                    f"recording (sha256 {source['sha256'][:12]}…): its frames would count twice")


COMMANDS: list[click.Command] = [calibrate_command]
