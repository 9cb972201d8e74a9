"""Estimator checkpoints: one ``.npz`` file, no pickle anywhere.

Layout (NumPy ``savez``, read back with ``allow_pickle=False``):
- ``meta``: UTF-8 JSON as a uint8 array — format name/version, model config, sensor names,
  target joint/angles, normalisation, offset handling, sensor rate, and ``info`` (sha256 of the
  training recordings, split, seed, metrics …);
- ``net/<name>``: every tensor of the network's ``state_dict`` (neural kinds), float32;
- ``classical/<name>``: thresholds, alphas and ridge weights (classical kind), float64.

Any problem reading a checkpoint — missing file, not an npz, bad JSON, wrong format name or
version, missing/extra/misshapen weights — raises :class:`CheckpointError` with one line.
"""

from __future__ import annotations

import math
import zipfile
from pathlib import Path

import numpy as np

from exohil.estimator.architecture import OUTPUTS, ModelConfig, check_state, state_shapes
from exohil.estimator.classical import ClassicalModel
from exohil.estimator.dataset import TargetSpec
from exohil.estimator.trained import (
    DIRECTION_ANGLES,
    Normalisation,
    TrainedEstimator,
    is_direction_target,
)
from exohil.formats import strict_json
from exohil.formats.atomic import replacing
from exohil.formats.errors import InputError
from exohil.formats.recording import Recording

CHECKPOINT_FORMAT = "exohil-estimator"
CHECKPOINT_VERSION = 1


class CheckpointError(InputError):
    """A checkpoint is missing, unreadable, or does not fit the data it is used with."""


def save_checkpoint(path: str | Path, est: TrainedEstimator) -> None:
    """Write ``est`` to ``path`` (an .npz file; the suffix is not enforced), under a temporary
    name renamed when complete."""
    meta = {
        "format": CHECKPOINT_FORMAT,
        "version": CHECKPOINT_VERSION,
        "config": est.config.to_dict(),
        "sensor_names": list(est.sensor_names),
        "target": {"joint": est.target.joint, "angles": list(est.target.angles)},
        "norm": {k: getattr(est.norm, k).tolist()
                 for k in ("x_mean", "x_std", "y_mean", "y_std")},
        "offset_frames": est.offset_frames,
        "sensor_rate_hz": est.sensor_rate_hz,
        "info": est.info,
    }
    arrays: dict[str, np.ndarray] = {
        "meta": np.frombuffer(strict_json.dumps(meta, sort_keys=True).encode(), dtype=np.uint8)
    }
    if est.classical is not None:
        arrays["classical/thresholds"] = est.classical.thresholds
        arrays["classical/alphas"] = est.classical.alphas
        arrays["classical/weights"] = est.classical.weights
    else:
        for name, array in est.weights(dtype=np.float32).items():
            arrays[f"net/{name}"] = array
    with replacing(path) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, allow_pickle=False, **arrays)


def load_checkpoint(path: str | Path) -> TrainedEstimator:
    """Read a checkpoint written by :func:`save_checkpoint`; raises CheckpointError."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"checkpoint not found: {path}")
    if not zipfile.is_zipfile(path):  # np.load would read .npy or talk about pickles instead
        raise CheckpointError(f"{path}: not an exohil estimator checkpoint (not an .npz archive)")
    try:
        with np.load(path, allow_pickle=False) as npz:
            arrays = {k: npz[k] for k in npz.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise CheckpointError(f"{path}: not an exohil estimator checkpoint ({exc})") from None
    try:
        meta = strict_json.loads(arrays.pop("meta").tobytes())
    except (KeyError, ValueError):
        raise CheckpointError(f"{path}: checkpoint has no readable metadata") from None
    if not isinstance(meta, dict) or meta.get("format") != CHECKPOINT_FORMAT:
        raise CheckpointError(f"{path}: not an exohil estimator checkpoint")
    if meta.get("version") != CHECKPOINT_VERSION:
        raise CheckpointError(
            f"{path}: checkpoint version {meta.get('version')} unsupported "
            f"(this exohil reads {CHECKPOINT_VERSION})"
        )
    try:
        est = _from_meta(meta)
    except (KeyError, TypeError, ValueError) as exc:
        raise CheckpointError(f"{path}: checkpoint metadata incomplete ({exc})") from None
    _check_numbers(path, est, arrays)
    if est.kind == "classical":
        _attach_classical(path, est, arrays)
    else:
        _attach_network(path, est, arrays)
    return est


def ensure_fits(est: TrainedEstimator, rec: Recording, source: str = "recording") -> None:
    """Raise CheckpointError unless ``rec`` has the checkpoint's sensors, in the unit it was
    trained on (``info.sensor_units``; checkpoints written before it was recorded are not
    checked for it), and its target angles."""
    if tuple(rec.sensor_names) != est.sensor_names:
        raise CheckpointError(
            f"checkpoint expects {len(est.sensor_names)} sensors {list(est.sensor_names)}, "
            f"{source} has {len(rec.sensor_names)} {list(rec.sensor_names)}"
        )
    units = est.info.get("sensor_units")
    if units is not None and rec.sensor_units != units:
        raise CheckpointError(
            f"checkpoint was trained on sensor readings in {units}, {source} has them in "
            f"{rec.sensor_units}: it would read them as {units} (train a model on "
            f"recordings in {rec.sensor_units})")
    stream = rec.mocap.get(est.target.joint)
    missing = [a for a in est.target.angles if stream is None or a not in stream.names]
    if missing:
        raise CheckpointError(f"{source} has no {est.target.joint} angle(s) {missing} "
                              "that the checkpoint estimates")


def _from_meta(meta: dict) -> TrainedEstimator:
    cfg = ModelConfig.from_dict(meta["config"])
    norm = Normalisation(**{k: np.asarray(v, dtype=np.float64) for k, v in meta["norm"].items()})
    sensors = tuple(meta["sensor_names"])
    target = TargetSpec(meta["target"]["joint"], tuple(meta["target"]["angles"]))
    if norm.x_mean.shape != (len(sensors),) or len(sensors) != cfg.n_sensors:
        raise ValueError("sensor count inconsistent")
    if cfg.output not in OUTPUTS:
        raise ValueError(f"unknown output {cfg.output!r}")
    if cfg.output == "direction" and not is_direction_target(target):
        raise ValueError(f"a direction output needs the angles {list(DIRECTION_ANGLES)}")
    if norm.y_mean.shape != (cfg.n_outputs,) or len(target.angles) != cfg.n_angles:
        raise ValueError("angle count inconsistent")
    return TrainedEstimator(
        config=cfg,
        sensor_names=sensors,
        target=target,
        norm=norm,
        offset_frames=int(meta["offset_frames"]),
        sensor_rate_hz=float(meta["sensor_rate_hz"]),
        info=dict(meta.get("info", {})),
    )


def _check_numbers(path: Path, est: TrainedEstimator, arrays: dict[str, np.ndarray]) -> None:
    """Every weight array is real numbers, all finite; the normalisation is finite with
    positive scales; so a damaged checkpoint is refused instead of estimating NaN."""
    for name, array in arrays.items():
        if array.dtype.kind not in "fiu":
            raise CheckpointError(f"{path}: array {name!r} holds {array.dtype} values, not "
                                  "real numbers")
        if not np.isfinite(array).all():
            raise CheckpointError(f"{path}: array {name!r} has non-finite values (NaN or inf)")
    norm = est.norm
    for name in ("x_mean", "x_std", "y_mean", "y_std"):
        if not np.isfinite(getattr(norm, name)).all():
            raise CheckpointError(f"{path}: normalisation {name} is not finite")
    if (norm.x_std <= 0).any() or (norm.y_std <= 0).any():
        raise CheckpointError(f"{path}: normalisation scales must be > 0")
    if not (math.isfinite(est.sensor_rate_hz) and est.sensor_rate_hz > 0):
        raise CheckpointError(f"{path}: sensor rate {est.sensor_rate_hz!r} Hz is not positive")
    if est.offset_frames < 0:
        raise CheckpointError(f"{path}: offset_frames {est.offset_frames} is negative")


def _attach_classical(path: Path, est: TrainedEstimator, arrays: dict[str, np.ndarray]) -> None:
    try:
        model = ClassicalModel(arrays["classical/thresholds"], arrays["classical/alphas"],
                               arrays["classical/weights"])
    except KeyError as exc:
        raise CheckpointError(f"{path}: classical weights missing ({exc})") from None
    s, k, m = est.config.n_sensors, model.thresholds.shape[0], model.alphas.shape[0]
    n_features = 1 + s + s * (s + 1) // 2 + s * k + s * m
    if model.weights.shape != (n_features, est.config.n_outputs):
        raise CheckpointError(f"{path}: classical weights have shape {model.weights.shape}, "
                              f"expected {(n_features, est.config.n_outputs)}")
    est.classical = model


def _attach_network(path: Path, est: TrainedEstimator, arrays: dict[str, np.ndarray]) -> None:
    """The network's weights as NumPy arrays, checked against the architecture without torch
    (the torch module is built from them only when something asks for it)."""
    try:
        state_shapes(est.config)
    except ValueError as exc:  # an unknown kind, a size that is not positive
        raise CheckpointError(f"{path}: {exc}") from None
    state = {k[len("net/"):]: v.astype(np.float32) for k, v in arrays.items()
             if k.startswith("net/")}
    try:
        check_state(est.config, {k: v.shape for k, v in state.items()})
    except ValueError as exc:
        raise CheckpointError(f"{path}: weights do not match the architecture ({exc})") from None
    est.set_weights(state)
