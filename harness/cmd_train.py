"""``exohil train``, ``exohil evaluate`` and ``exohil table``: the estimators from the command
line (logic in :mod:`exohil.estimator`; see docs/estimator.md)."""

from __future__ import annotations

import math
import shlex
import sys
from typing import TYPE_CHECKING

import click
import numpy as np

from exohil.estimator.architecture import DENSE_STACK, OUTPUTS
from exohil.estimator.defaults import DEFAULT_DENSE, DEFAULT_WINDOW, MODEL_NAMES
from exohil.estimator.rates import RATE_REMEDY, rate_mismatch, same_rate
from exohil.formats import strict_json
from exohil.formats.atomic import write_text
from exohil.harness.cli_types import (
    MAX_DURATION_S,
    Count,
    Finite,
    InputFile,
    Name,
    NameList,
    OutputDir,
    OutputFile,
    Seed,
    Widths,
    refuse_overwriting_inputs,
    refuse_repeated_inputs,
)

if TYPE_CHECKING:
    pass

OUTPUT_CHOICES = ("auto", *OUTPUTS)

_recordings = click.argument("recordings", nargs=-1, required=True, type=InputFile())

#: Bounds of the training options (docs/reliability.md): far beyond any useful value, small
#: enough that a typo cannot exhaust memory or run for years.
MAX_HIDDEN = 4096
MAX_EPOCHS = 1_000_000
MAX_WINDOW = 1000
MAX_DILATION = 100
MAX_OFFSET_FRAMES = 1_000_000
MAX_LAYERS = 16


class AngleLimit(click.ParamType):
    """``ANGLE=DEG``: an angle name and a finite number of degrees within ±360, returned as
    (name, degrees) (whether the model has that angle is checked once it is loaded)."""

    name = "angle=deg"

    def convert(self, value, param, ctx):
        if isinstance(value, tuple):  # already converted
            return value
        text = str(value)
        name, sep, number = text.partition("=")
        if not sep or not name.strip():
            self.fail(f"{text!r} is not ANGLE=DEG", param, ctx)
        Name().convert(name, param, ctx)
        return name, Finite(-360.0, 360.0).convert(number, param, ctx)


def _angles(text: str | None) -> tuple[str, ...] | None:
    return tuple(a.strip() for a in text.split(",") if a.strip()) if text else None


def _common_training_options(fn):
    options = [
        click.option("--seed", type=Seed(), default=0, show_default=True,
                     help="Seed of initialisation and shuffling."),
        click.option("--time-budget", type=Finite(1.0, MAX_DURATION_S), default=300.0,
                     show_default=True, help="Wall-clock limit per model, seconds."),
        click.option("--max-epochs", type=Count(1, MAX_EPOCHS), default=10_000,
                     show_default=True, help="Epoch limit (use for bit-reproducible runs)."),
        click.option("--patience", type=Count(1, MAX_EPOCHS), default=25, show_default=True,
                     help="Early stopping: epochs without validation improvement."),
        click.option("--window", type=Count(1, MAX_WINDOW), help="Frames per window (n); "
                     f"default ennet and lnnet {DEFAULT_WINDOW['ennet'][0]}, cnn "
                     f"{DEFAULT_WINDOW['cnn'][0]} (docs/estimator.md, Defaults)."),
        click.option("--dilation", type=Count(1, MAX_DILATION), help="Frame step inside the "
                     "window (it spans (n-1)·dilation+1 frames); default: the step that spans "
                     f"{DEFAULT_WINDOW['ennet'][1]:g} s for ennet and lnnet, "
                     f"{DEFAULT_WINDOW['cnn'][1]:g} s for cnn, at the recording's rate."),
        click.option("--dense", type=Widths(MAX_HIDDEN, MAX_LAYERS), help="Widths of the dense "
                     "ReLU layers after the temporal encoder; default "
                     f"{','.join(map(str, DEFAULT_DENSE))} (docs/estimator.md, Defaults; the "
                     f"paper's is {','.join(map(str, DENSE_STACK))})."),
        click.option("--output", type=click.Choice(OUTPUT_CHOICES), default="auto",
                     show_default=True, help="What the network learns: the humerus direction "
                     "for a shoulder θ/φ target (auto), or the target angles themselves."),
        click.option("--joint", type=Name(), help="Mocap joint to estimate (default: "
                     "shoulder, or the recording's only joint)."),
        click.option("--angles", type=NameList(), help="Comma-separated angle fields "
                     "(default: elv_angle,shoulder_elv for the shoulder; all fields otherwise)."),
        click.option("--offset-frames", type=Count(0, MAX_OFFSET_FRAMES), default=0,
                     show_default=True, help="Subtract each recording's initial rest value "
                     "(causal mean of its first N frames) from the sensors; 0 = off."),
        click.option("--val-fraction", type=Finite(0.01, 0.9), default=0.15,
                     show_default=True, help="End of each training piece used for validation."),
    ]
    for option in reversed(options):
        fn = option(fn)
    return fn


def _load(paths, joint=None, angles=None, expected=None):
    from exohil.estimator.dataset import DatasetError
    from exohil.formats.errors import RecordingError

    try:
        return _workflow().load_recordings(list(paths), joint, _angles(angles), expected)
    except (RecordingError, DatasetError) as exc:
        raise click.ClickException(str(exc)) from None


def _model_and_recordings(checkpoint, recordings):
    """The checkpoint and the recordings with its sensors and target angles (LoadedData), or
    a one-line error."""
    from exohil.estimator.checkpoint import CheckpointError, ensure_fits, load_checkpoint

    try:
        est = load_checkpoint(checkpoint)
    except CheckpointError as exc:
        raise click.ClickException(str(exc)) from None
    data = _load(recordings, est.target.joint, ",".join(est.target.angles))
    try:
        for path, rec in zip(data.paths, data.recordings, strict=True):
            ensure_fits(est, rec, str(path))
    except CheckpointError as exc:
        raise click.ClickException(str(exc)) from None
    return est, data


def _accuracy_line(accuracy: dict) -> str:
    """The one accuracy definition (estimator.evaluation.accuracy_measurements) as one line."""
    from exohil.estimator.evaluation import OBSERVABLE_ELEVATION_DEG

    rmse = {k.removeprefix("accuracy.rmse."): v for k, v in accuracy.items()
            if k.startswith("accuracy.rmse.") and v is not None}
    text = "accuracy: RMSE " + ", ".join(
        f"{a} {v:.2f}°" if math.isfinite(v) else f"{a} not measured" for a, v in rmse.items())
    direction = accuracy.get("accuracy.direction_rmse")
    if direction is not None:
        text += (f" where elevation ≥ {OBSERVABLE_ELEVATION_DEG:g}°; arm direction "
                 f"{direction:.2f}° over all frames")
    return text


def _workflow():
    from exohil.estimator import workflow

    return workflow


#: The training options a model kind does not read, and why.
IGNORED_BY: dict[str, tuple[tuple[str, ...], str]] = {
    "ann": (("hidden", "window", "dilation"),
            "it reads the newest frame through its dense layers"),
    "classical": (("hidden", "window", "dilation", "dense", "max_epochs", "patience"),
                  "it is one ridge fit of hysteresis, creep and static terms, no network"),
}


def _base_config(seed, time_budget, max_epochs, patience, window, dilation, dense, output):
    from exohil.estimator.training import TrainConfig

    return TrainConfig(window=window, dilation=dilation, seed=seed, time_budget_s=time_budget,
                       max_epochs=max_epochs, patience=patience, output=output,
                       dense=dense or DEFAULT_DENSE)


def _command_line() -> str:
    return "exohil " + " ".join(shlex.quote(a) for a in sys.argv[1:])


@click.command("train")
@click.option("--model", "kind", type=click.Choice(MODEL_NAMES), default="ennet",
              show_default=True, help="Estimator to train.")
@_recordings
@click.option("--out", required=True, type=OutputFile(),
              help="Checkpoint file to write (.npz).")
@click.option("--hidden", type=Count(1, MAX_HIDDEN), help="LSTM hidden size (per sensor for "
              "LNNet) or CNN channels; default ennet 64, lnnet 32, cnn 32.")
@click.option("--test-fraction", type=Finite(0.0, 0.9), default=0.0,
              show_default=True, help="Hold out the end of every movement piece as a test set "
              "and store its metrics in the checkpoint (0 = train on everything).")
@_common_training_options
def train_command(kind, recordings, out, hidden, test_fraction, seed, time_budget, max_epochs,
                  patience, window, dilation, dense, output, joint, angles, offset_frames,
                  val_fraction):
    """Train an estimator on RECORDING files (MCAP, format v1) and write a checkpoint.

    Adam (lr 1e-3, β 0.9/0.999), batch 500, MSE on the humerus direction for a shoulder θ/φ
    target (on the angles otherwise), early stopping on the same MSE over validation = the
    last --val-fraction of each movement segment of each recording (contiguous time blocks; no
    window crosses a boundary). Each model's defaults (window, head) are in docs/estimator.md
    and are stored in the checkpoint. Progress goes to stderr. Example:

    \b
        exohil train --model ennet fixtures/paper_protocol.mcap --out ennet.npz
    """
    from exohil.estimator.checkpoint import save_checkpoint
    from exohil.estimator.evaluation import evaluate
    from exohil.estimator.training import progress_printer, train

    if kind == "ennet-stateful" and (window or dilation):
        raise click.UsageError("a stateful ENNet has no window: drop --window/--dilation")
    refuse_overwriting_inputs([("--out", out)], recordings)
    refuse_repeated_inputs(("RECORDING", r) for r in recordings)
    unused_names, why = IGNORED_BY.get(kind, ((), ""))
    source = click.get_current_context().get_parameter_source
    unused = [f"--{name.replace('_', '-')}" for name in unused_names
              if source(name) is click.core.ParameterSource.COMMANDLINE]
    if unused:
        click.echo(f"warning: {', '.join(unused)} {'has' if len(unused) == 1 else 'have'} no "
                   f"effect on the {kind} model: {why}", err=True)
    wf = _workflow()
    data = _load(recordings, joint, angles)
    split = wf.make_split(data, offset_frames, test_fraction=test_fraction,
                          val_fraction=val_fraction)
    if not split.train:
        raise click.ClickException("no labelled sensor frames to train on")
    base = _base_config(seed, time_budget, max_epochs, patience, window, dilation, dense,
                        output)
    cfg = wf.model_config(kind, base, data.rate_hz, hidden)
    for line in wf.setting_warnings(data, split, cfg, offset_frames):
        click.echo(f"warning: {line}", err=True)
    est = train(split, data.sensor_names, data.target, cfg, offset_frames=offset_frames,
                sensor_rate_hz=data.rate_hz, sources=data.sources, progress=progress_printer(),
                sensor_units=data.units)
    if split.test:
        est.info.setdefault("metrics", {})["test"] = evaluate(est, split.test)
    est.info["command"] = _command_line()
    est.info["test_fraction"] = test_fraction
    save_checkpoint(out, est)
    metrics = est.info.get("metrics", {})
    part = "test" if "test" in metrics else "validation"
    shown = _accuracy_line(metrics[part]["accuracy"]) if part in metrics else "not measured"
    click.echo(f"wrote {out} ({kind}); {part} {shown}")


@click.command("evaluate")
@click.argument("checkpoint", type=InputFile())
@_recordings
@click.option("--json", "json_out", type=OutputFile(),
              help="Also write the metrics as JSON to this file.")
@click.option("--test-fraction", type=Finite(0.0, 0.9), default=0.0,
              show_default=True, help="Score only the last fraction of each movement piece "
              "(the part `train --test-fraction` held out); 0 = whole recordings.")
@click.option("--min", "min_angle", type=AngleLimit(), multiple=True, metavar="ANGLE=DEG",
              help="Score only frames whose true ANGLE ≥ DEG (repeatable), e.g. "
              "shoulder_elv=20 where the plane of elevation is observable.")
def evaluate_command(checkpoint, recordings, json_out, test_fraction, min_angle):
    """Score CHECKPOINT on RECORDING files: first exohil's accuracy (RMSE per angle where the
    elevation is at least 20°, and the arm-direction RMSE over all frames), then per-angle
    RMSE, MAE and max |error| (degrees) over all frames, overall and per movement segment.
    A warning comes first when 1 % or more of the frames lie outside the readings the model
    was trained on (docs/estimator.md; another suit or movement: calibrate first), when
    the recordings run at another sensor rate than the model's, or when a recording is one
    the model was trained on, scored beyond the end `train --test-fraction` held out (its
    figures are then no test). A calibrated model is not
    scored on its calibration frames: a recording that would score one (a calibration
    recording, a part cut from it, or the recording it was cut from at its times, after
    --test-fraction) is refused. Example:

    \b
        exohil evaluate ennet.npz fixtures/paper_protocol_heldout.mcap --json metrics.json
    """
    from exohil.estimator.coverage import block_coverage
    from exohil.estimator.evaluation import evaluate
    from exohil.estimator.splits import tail_cut

    refuse_overwriting_inputs([("--json", json_out)], [checkpoint, *recordings])
    refuse_repeated_inputs(("RECORDING", r) for r in recordings)
    est, data = _model_and_recordings(checkpoint, recordings)
    scored = [[b for b in data.blocks(est.offset_frames, [i]) if len(b)]
              for i in range(len(data.paths))]
    if test_fraction > 0:
        scored = [[tail_cut(b, test_fraction)[1] for b in part] for part in scored]
    times = [np.concatenate([b.t for b in part]) if part else np.empty(0) for part in scored]
    refuse_calibration_frames(est.info, list(zip(data.sources, times, strict=True)),
                              "RECORDING")
    blocks = [b for part in scored for b in part if len(b)]
    if not blocks:
        raise click.ClickException("no labelled sensor frames to evaluate")
    limits = _angle_limits(min_angle, est.target.angles)
    try:
        result = evaluate(est, blocks, limits)
    except ValueError as exc:
        raise click.ClickException(str(exc)) from None
    for line in training_frame_warnings(est.info, data.sources, test_fraction):
        click.echo(f"warning: {line}", err=True)
    other_rate = rate_mismatch(data.rate_hz, est.sensor_rate_hz)
    if other_rate:
        click.echo(f"warning: {other_rate}; {RATE_REMEDY}", err=True)
    coverage = block_coverage(est, blocks)
    result["checkpoint"] = str(checkpoint)
    result["model"] = est.kind
    result["recordings"] = data.sources
    result["training_coverage"] = coverage.to_dict()
    warning = coverage.warning()
    if warning:
        click.echo(f"warning: {warning}", err=True)
    click.echo(_accuracy_line(result["accuracy"]))
    scope = "frames kept by --min" if limits else "all frames"
    if test_fraction > 0:
        scope += f" of the last {100 * test_fraction:g} % of each block"
    for stat in ("rmse", "mae", "max"):
        click.echo(f"{stat:>4} ({scope}): "
                   + ", ".join(f"{a} {v:.2f}°" for a, v in result[stat].items()))
    for name, seg in result["per_segment"].items():
        click.echo(f"  {name}: RMSE ({scope}) "
                   + ", ".join(f"{a} {v:.2f}°" for a, v in seg["rmse"].items()))
    if json_out:
        write_text(json_out, strict_json.dumps(result, indent=2) + "\n")


def _angle_limits(items: tuple[tuple[str, float], ...],
                  angles: tuple[str, ...]) -> dict[str, float]:
    """--min values ((name, degrees), parsed by AngleLimit) for a model with ``angles``."""
    for name, degrees in items:
        if name not in angles:
            raise click.ClickException(
                f"--min '{name}={degrees:g}': expected ANGLE=DEG with ANGLE one of "
                f"{', '.join(angles)}")
    return dict(items)


def _refuse_training_frames(train: list[dict], test: list[dict]) -> None:
    """Refuse (a usage error) a --test recording that may share frames with a --train one:
    the same recording by another path, or one cut from the other or both from one
    recording at times that meet (the heldout check's rule, formats.recording_metadata)."""
    from exohil.formats.recording_metadata import shared_frames

    for scored in test:
        for trained in train:
            overlap, why = shared_frames(scored, trained)
            if overlap:
                raise click.UsageError(f"--test {scored['file']}: {why}: a model would be "
                                       "scored on frames it was trained on")


def training_frame_warnings(info: dict, scored: list[dict], test_fraction: float) -> list[str]:
    """One line per scored recording (``info.sources``-style entries) that may hold frames
    the model (checkpoint ``info``) was trained or validated on: one of its training
    recordings, or related to one (the heldout check's rule, formats.recording_metadata).
    Only the training recording itself, scored on no more than the end of each block that
    ``train --test-fraction`` held out (``info["test_fraction"]``), is a test; a checkpoint
    made before it kept that fraction does not tell, and that end is said to be unknown."""
    from exohil.formats.recording_metadata import shared_frames

    held_out = info.get("test_fraction")
    lines = []
    for entry in scored:
        for source in info.get("sources", []):
            if source.get("role") == "calibration":
                continue  # refuse_calibration_frames judges those
            overlap, why = shared_frames(entry, source)
            itself = entry.get("sha256") == source.get("sha256") and test_fraction > 0
            if not overlap or (itself and held_out is not None and test_fraction <= held_out):
                continue
            include = ("may include frames it was trained or validated on: the checkpoint "
                       "does not say what `train --test-fraction` held out"
                       if itself and held_out is None else
                       "include frames it was trained or validated on, not a test")
            lines.append(f"{why}: these figures {include} (score a held-out recording, or the "
                         "part `train --test-fraction F` held out with --test-fraction F or "
                         "less)")
            break
    return lines


def refuse_calibration_frames(info: dict, scored: list[tuple[dict, np.ndarray]],
                              label: str) -> None:
    """Refuse (a usage error) to score a calibrated model (checkpoint ``info``) on one of its
    calibration frames: ``scored`` holds each recording's ``info.sources``-style entry and
    the times of the frames scored on it. A calibration fits every frame of its recordings,
    so a recording related to one (the heldout check's rule, formats.recording_metadata) is
    refused where a scored frame lies within that recording's span, on their common clock
    (``exohil record cut`` keeps times), or where the span is not known."""
    from exohil.formats.recording_metadata import shared_frames

    calibration = [s for s in info.get("sources", []) if s.get("role") == "calibration"]
    for entry, t in scored:
        for source in calibration:
            overlap, why = shared_frames(entry, source)
            span = source.get("span_s")
            if overlap and (not span or np.any((t >= span[0]) & (t <= span[1]))):
                raise click.UsageError(f"{label} {entry['file']}: {why}, and frames scored "
                                       "here are among its calibration frames: a model would "
                                       "be scored on frames it was trained on")


@click.command("table")
@click.option("--train", "train_paths", multiple=True, required=True, type=InputFile(),
              help="Training recording (repeat the option for several).")
@click.option("--test", "test_paths", multiple=True, type=InputFile(),
              help="Test recording(s) (across-trial split), at the --train recordings' "
              "sensor rate; without them the end of each training movement piece is the "
              "test set (--test-fraction).")
@click.option("--test-fraction", type=Finite(0.05, 0.9), default=0.3,
              show_default=True, help="Within-recording split: test = last fraction.")
@click.option("--models", type=NameList(MODEL_NAMES),
              default=",".join(("ann", "classical", "cnn", "lnnet", "ennet", "ennet-stateful")),
              show_default=True, help="Comma-separated model kinds, in table order.")
@click.option("--out", type=OutputFile(),
              help="Markdown file to put the table into (e.g. docs/results.md).")
@click.option("--section", type=Name(), default="comparison", show_default=True,
              help="Name of the table section inside --out (replaced when present).")
@click.option("--title", type=Name(), default="Model comparison", show_default=True,
              help="Table heading.")
@click.option("--json", "json_out", type=OutputFile(),
              help="Also write all metrics as JSON.")
@click.option("--save-dir", type=OutputDir(),
              help="Also save every trained model's checkpoint here.")
@_common_training_options
def table_command(train_paths, test_paths, test_fraction, models, out, section, title,
                  json_out, save_dir, seed, time_budget, max_epochs, patience, window,
                  dilation, dense, output, joint, angles, offset_frames, val_fraction):
    """Train every model on the same split and print the RMSE table (paper's Table I layout).

    Within recordings (default): each movement piece → first 70% train (its last 15% =
    validation), last 30% test. Across recordings: --test files. Example:

    \b
        exohil table --train fixtures/paper_protocol.mcap --out docs/results.md --section paper \\
            --title 'Default protocol (simulated suit, fixtures/paper_protocol.mcap)'

    A section is replaced whole, heading included: give its --title again.
    """
    from exohil.estimator.checkpoint import save_checkpoint
    from exohil.estimator.report import check_section, comparison_markdown, write_section
    from exohil.estimator.training import progress_printer

    refuse_overwriting_inputs([("--out", out), ("--json", json_out)],
                              [*train_paths, *test_paths])
    if out:  # before the training, not after it
        check_section(out, section)
    refuse_repeated_inputs([*(("--train", p) for p in train_paths),
                            *(("--test", p) for p in test_paths)])
    kinds = [k.strip() for k in models.split(",")]
    wf = _workflow()
    data = _load(train_paths, joint, angles)
    test_data = _load(test_paths, data.target.joint, ",".join(data.target.angles),
                      data.sensor_names) if test_paths else None
    if test_data is not None:
        _refuse_training_frames(data.sources, test_data.sources)
        units, test_units = data.recordings[0].sensor_units, test_data.recordings[0].sensor_units
        if test_units != units:  # as train refuses two units
            raise click.ClickException(
                f"--test recordings in {test_units}, --train recordings in {units}: each "
                "model would read the test in another unit; convert them to one unit")
        if not same_rate(test_data.rate_hz, data.rate_hz):  # as train refuses two rates
            raise click.ClickException(
                f"--test recordings at {test_data.rate_hz:g} Hz, --train recordings at "
                f"{data.rate_hz:g} Hz: each model's window would span another time in the "
                "test; resample them to one rate")
    split = wf.make_split(data, offset_frames, test_paths_data=test_data,
                          test_fraction=test_fraction, val_fraction=val_fraction)
    if not split.train or not split.test:
        raise click.ClickException("the split has no training or no test frames")
    base = _base_config(seed, time_budget, max_epochs, patience, window, dilation, dense,
                        output)
    warned: dict[str, list[str]] = {}  # one line for the models it holds for
    for kind in kinds:
        cfg = wf.model_config(kind, base, data.rate_hz)
        for line in wf.setting_warnings(data, split, cfg, offset_frames):
            warned.setdefault(line, []).append(kind)
    for line, which in warned.items():
        click.echo(f"warning: {', '.join(which)}: {line}", err=True)
    results = wf.compare_models(split, data, kinds, base, offset_frames, progress_printer())
    for r in results:
        warning = r.coverage.warning()
        if warning:
            click.echo(f"warning: {r.kind}: {warning}", err=True)
    names = ", ".join(p.name for p in train_paths)
    described = f"train {names}" + (
        f"; test {', '.join(p.name for p in test_paths)}" if test_paths else "")
    if offset_frames:
        described += f"; offset removal: initial {offset_frames} frames"
    text = comparison_markdown(results, data.target.angles, title=title,
                               command=_command_line(), split=split.description, data=described)
    click.echo(text)
    if out:
        write_section(out, section, text)
    if save_dir:
        save_dir.mkdir(parents=True, exist_ok=True)
        for r in results:
            r.estimator.info["command"] = _command_line()
            r.estimator.info["test_fraction"] = 0.0 if test_paths else test_fraction
            save_checkpoint(save_dir / f"{r.kind}.npz", r.estimator)
    if json_out:
        payload = {r.kind: {"test": r.test, "info": r.estimator.info} for r in results}
        write_text(json_out, strict_json.dumps(payload, indent=2) + "\n")


COMMANDS: list[click.Command] = [train_command, evaluate_command, table_command]
