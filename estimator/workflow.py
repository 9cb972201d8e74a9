"""Recording files → splits → trained and scored estimators (what the CLI commands run).

Splits (documented in docs/estimator.md):
- within recordings (``test_fraction > 0``, no separate test files): every recording is cut at
  its movement-segment boundaries; each piece gives its first part to training (the last
  ``val_fraction`` of that part to validation) and its last ``test_fraction`` to test;
- across recordings (test files given): training/validation come from the training files
  (validation = the last ``val_fraction`` of each segment piece), test = the test files whole.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from exohil.estimator.coverage import CoverageTally, block_coverage
from exohil.estimator.dataset import (
    Block,
    DatasetError,
    TargetSpec,
    check_sensors,
    recording_blocks,
    resolve_target,
)
from exohil.estimator.defaults import DEFAULT_HIDDEN, DEFAULT_WINDOW, MODEL_NAMES, default_window
from exohil.estimator.evaluation import evaluate
from exohil.estimator.rates import same_rate
from exohil.estimator.splits import Split, cut_at_segments, time_block_split, trial_split
from exohil.estimator.trained import DIRECTION_ANGLES, TrainedEstimator
from exohil.estimator.training import TrainConfig, train
from exohil.formats.recording import Recording
from exohil.formats.recording_metadata import rate_the_times_give, source_entry
from exohil.kinematics import OBSERVABLE_ELEVATION_DEG

#: The plane of elevation θ and the elevation φ (the humerus direction's angles).
THETA, PHI = DIRECTION_ANGLES


def model_config(name: str, base: TrainConfig, rate_hz: float,
                 hidden: int | None = None) -> TrainConfig:
    """The training configuration of model ``name`` (one of
    :data:`~exohil.estimator.defaults.MODEL_NAMES`) for data at ``rate_hz``: ``base`` with
    the model's kind and its defaults (:mod:`exohil.estimator.defaults`) wherever ``base``
    or ``hidden`` leave a setting open (None)."""
    if name not in MODEL_NAMES:
        raise ValueError(f"unknown model {name!r}; choose from {MODEL_NAMES}")
    window, dilation = default_window(name, rate_hz)
    stateful = name == "ennet-stateful"
    # the stateful ENNet carries state, the ANN reads the newest frame, the classical model
    # its operators' state: none of them reads a window, whatever base asks
    unwindowed = stateful or name not in DEFAULT_WINDOW
    return replace(base, kind=name.removesuffix("-stateful"), stateful=stateful,
                   hidden=hidden or DEFAULT_HIDDEN[name],
                   window=1 if unwindowed else base.window or window,
                   dilation=1 if unwindowed else base.dilation or dilation)


@dataclass
class LoadedData:
    """Recordings read from files, with their common sensor names, target and rate."""

    paths: list[Path]
    recordings: list[Recording]
    sensor_names: tuple[str, ...]
    target: TargetSpec
    rate_hz: float
    sources: list[dict] = field(default_factory=list)

    @property
    def units(self) -> str:
        """The recordings' sensor unit (one for all: :func:`load_recordings` refuses two)."""
        return self.recordings[0].sensor_units

    def blocks(self, offset_frames: int, indices: list[int] | None = None) -> list[Block]:
        """Segment-cut blocks of the chosen recordings (all by default)."""
        chosen = range(len(self.recordings)) if indices is None else indices
        out: list[Block] = []
        for i in chosen:
            out += recording_blocks(self.recordings[i], self.target,
                                    offset_frames=offset_frames, source=self.paths[i].name)
        return cut_at_segments(out)


def load_recordings(
    paths: list[Path], joint: str | None = None, angles: tuple[str, ...] | None = None,
    expected_sensors: tuple[str, ...] | None = None,
) -> LoadedData:
    """Read recordings and check they share sensors (and the expected ones, if given).

    Raises RecordingError (unreadable file) or DatasetError (mismatch), both one-line.
    """
    from exohil.formats.recording_reader import read_recording

    recs = [read_recording(p) for p in paths]
    for p, r in zip(paths, recs, strict=True):
        if len(r.sensors) == 0 or not r.sensor_names:
            raise DatasetError(f"{p}: no sensor frames (a mocap-only recording?)")
    sensors = expected_sensors or recs[0].sensor_names
    for p, r in zip(paths, recs, strict=True):
        check_sensors(r, tuple(sensors), str(p))
    try:
        target = resolve_target(recs[0], joint, angles)
    except DatasetError as exc:
        raise DatasetError(f"{paths[0]}: {exc}") from None
    rate = float(recs[0].sensor_rate_hz)
    for p, r in zip(paths[1:], recs[1:], strict=True):
        if r.sensor_units != recs[0].sensor_units:
            raise DatasetError(f"{p}: sensors in {r.sensor_units}, {paths[0]} in "
                               f"{recs[0].sensor_units}: one model cannot read both; "
                               "convert them to one unit")
        if not same_rate(r.sensor_rate_hz, rate):
            raise DatasetError(f"{p}: sensors at {r.sensor_rate_hz:g} Hz, {paths[0]} at "
                               f"{rate:g} Hz: a model's window would span another time in "
                               "each; resample them to one rate")
        stream = r.mocap.get(target.joint)
        if stream is None or any(a not in stream.names for a in target.angles):
            raise DatasetError(f"{p}: has no {target.joint} angles {list(target.angles)}")
    sources = [source_entry(p, r) for p, r in zip(paths, recs, strict=True)]
    return LoadedData(list(paths), recs, tuple(sensors), target, rate, sources)



def make_split(
    data: LoadedData, offset_frames: int, *, test_paths_data: LoadedData | None = None,
    test_fraction: float = 0.0, val_fraction: float = 0.15,
) -> Split:
    """The within-recording or across-recording split described in the module docstring."""
    blocks = data.blocks(offset_frames)
    if test_paths_data is not None:
        return trial_split(blocks, test_paths_data.blocks(offset_frames), val_fraction)
    return time_block_split(blocks, test_fraction, val_fraction)


def setting_warnings(data: LoadedData, split: Split, cfg: TrainConfig,
                     offset_frames: int) -> list[str]:
    """One line for each setting the data leave without meaning, for ``cfg`` trained on
    ``split`` of ``data``: a window longer than every training piece (its windows are then
    mostly the piece's first frame, repeated by the edge padding), and an offset taken over
    more frames than a recording holds (its rest value never settles); a sensor that
    reads one value over every training frame (a model learns nothing from it); and a plane
    of elevation without the elevation (trained and scored where the arm hangs and it is
    undefined); and a recording whose timestamps run at another rate than its metadata's
    sensor_rate_hz, which the model's window is set up for."""
    lines: list[str] = []
    for path, rec in zip(data.paths, data.recordings, strict=True):
        measured = rate_the_times_give(rec)
        if measured is not None:
            lines.append(f"{path}: metadata sensor_rate_hz={rec.sensor_rate_hz:g} but its "
                         f"timestamps give {measured:.4g} Hz; the model is set up for "
                         f"{rec.sensor_rate_hz:g} Hz, so its window spans another time "
                         "(are the times in seconds?)")
    angles = data.target.angles
    if THETA in angles and PHI not in angles:
        lines.append(f"{THETA} without {PHI}: the plane of elevation is undefined with the arm "
                     "hanging, and without the elevation it is trained and scored on every "
                     "frame, those included; keep both (the default) to learn the arm "
                     f"direction and score {THETA} where {PHI} >= "
                     f"{OBSERVABLE_ELEVATION_DEG:g} deg")
    pieces = [b.x for b in split.train if len(b)]
    if pieces:
        x = np.concatenate(pieces)
        still = [name for name, lo, hi in zip(data.sensor_names, x.min(axis=0), x.max(axis=0),
                                              strict=True) if lo == hi]
        if still:
            which = ("every sensor reads" if len(still) == len(data.sensor_names) else
                     f"{', '.join(still)} read{'s' if len(still) == 1 else ''}")
            them = "it" if len(still) == 1 else "them"
            lines.append(f"{which} one value over every training frame: the model learns "
                         f"nothing from {them} (a stuck or unplugged channel?)")
    span = ((cfg.window or 1) - 1) * (cfg.dilation or 1) + 1
    longest = max((len(b) for b in split.train), default=0)
    if not cfg.stateful and longest and span > longest:
        lines.append(f"the window spans {span} frames ({span / data.rate_hz:.3g} s), more "
                     f"than the longest training piece ({longest} frames, "
                     f"{longest / data.rate_hz:.3g} s): most of each window repeats its "
                     "piece's first frame (docs/estimator.md, Data)")
    for path, rec in zip(data.paths, data.recordings, strict=True):
        if offset_frames > len(rec.sensors):
            lines.append(f"--offset-frames {offset_frames} is more than the "
                         f"{len(rec.sensors)} sensor frames of {path}: its rest value is "
                         "the mean of every frame before, to its last")
    return lines


@dataclass
class ModelResult:
    """One trained model of a comparison and its test metrics."""

    kind: str
    estimator: TrainedEstimator
    test: dict
    #: the test frames whose readings lie outside the model's training data (another suit
    #: or movement across recordings, a pose only the test part holds within them)
    coverage: CoverageTally


def compare_models(
    split: Split, data: LoadedData, kinds: list[str], base: TrainConfig, offset_frames: int,
    progress: Callable[[str], None] | None = None,
) -> list[ModelResult]:
    """Train every model kind on the same split and score each on its test part."""
    results: list[ModelResult] = []
    for kind in kinds:
        cfg = model_config(kind, base, data.rate_hz)
        est = train(split, data.sensor_names, data.target, cfg, offset_frames=offset_frames,
                    sensor_rate_hz=data.rate_hz, sources=data.sources, progress=progress,
                    sensor_units=data.units)
        test = evaluate(est, split.test)
        coverage = block_coverage(est, split.test)
        test["training_coverage"] = coverage.to_dict()
        est.info.setdefault("metrics", {})["test"] = test
        results.append(ModelResult(kind, est, test, coverage))
    return results
