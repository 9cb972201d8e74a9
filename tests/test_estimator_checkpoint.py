"""Checkpoint round trip for every model kind, and one clear CheckpointError for bad files."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from estimator_synth import shoulder_recording

from exohil.estimator.checkpoint import (
    CheckpointError,
    ensure_fits,
    load_checkpoint,
    save_checkpoint,
)
from exohil.estimator.dataset import default_target, recording_blocks
from exohil.estimator.splits import time_block_split
from exohil.estimator.training import TrainConfig, train

KINDS = ["ennet", "lnnet", "ann", "cnn", "classical"]


def _trained(kind: str, offset_frames: int = 0):
    rec = shoulder_recording(seconds=4.0, seed=3)
    target = default_target(rec)
    split = time_block_split(recording_blocks(rec, target, offset_frames=offset_frames), 0.3)
    cfg = TrainConfig(kind=kind, max_epochs=1, hidden=8, window=5, dilation=2)
    return rec, split, train(split, rec.sensor_names, target, cfg, offset_frames=offset_frames,
                             sources=[{"file": "x.mcap", "sha256": "0" * 64}])


@pytest.mark.parametrize("kind", KINDS)
def test_round_trip_keeps_predictions_and_metadata(kind, tmp_path):
    rec, split, est = _trained(kind, offset_frames=10)
    path = tmp_path / "m.npz"
    save_checkpoint(path, est)
    back = load_checkpoint(path)
    assert back.kind == kind
    assert back.sensor_names == rec.sensor_names
    assert back.target == est.target
    assert back.offset_frames == 10
    assert back.config == est.config
    assert back.info["sources"][0]["sha256"] == "0" * 64
    assert "validation" in back.info["metrics"]
    for block in split.test:
        np.testing.assert_array_equal(back.predict_block(block), est.predict_block(block))


def test_missing_file(tmp_path):
    with pytest.raises(CheckpointError, match="not found"):
        load_checkpoint(tmp_path / "nope.npz")


@pytest.mark.parametrize("payload", [b"", b"garbage" * 10, b"PK\x03\x04broken zip"])
def test_corrupt_file(tmp_path, payload):
    path = tmp_path / "bad.npz"
    path.write_bytes(payload)
    with pytest.raises(CheckpointError):
        load_checkpoint(path)


def test_plain_npy_array_is_not_a_checkpoint(tmp_path):
    path = tmp_path / "array.npz"
    with path.open("wb") as fh:
        np.save(fh, np.zeros(3))
    with pytest.raises(CheckpointError, match="not an .npz archive"):
        load_checkpoint(path)


def test_truncated_checkpoint(tmp_path):
    _, _, est = _trained("ennet")
    path = tmp_path / "m.npz"
    save_checkpoint(path, est)
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with pytest.raises(CheckpointError):
        load_checkpoint(path)


def test_npz_that_is_not_a_checkpoint(tmp_path):
    path = tmp_path / "other.npz"
    np.savez(path, a=np.zeros(3))
    with pytest.raises(CheckpointError, match="metadata"):
        load_checkpoint(path)


def test_weights_that_do_not_fit_the_architecture(tmp_path):
    _, _, est = _trained("ennet")
    path = tmp_path / "m.npz"
    save_checkpoint(path, est)
    with np.load(path) as npz:
        arrays = {k: npz[k] for k in npz.files}
    arrays["net/head.0.weight"] = arrays["net/head.0.weight"][:, :3]
    np.savez(path, **arrays)
    with pytest.raises(CheckpointError, match="do not match"):
        load_checkpoint(path)


def test_wrong_sensor_count_for_a_recording():
    _, _, est = _trained("ann")
    other = shoulder_recording(seconds=2.0, n_sensors=5)
    with pytest.raises(CheckpointError, match="expects 4 sensors"):
        ensure_fits(est, other, "five.mcap")
    ensure_fits(est, shoulder_recording(seconds=2.0))  # the right shape passes


def test_training_is_deterministic_for_a_seed():
    a, b = _trained("ennet")[2], _trained("ennet")[2]
    for (name, pa), pb in zip(a.network.state_dict().items(), b.network.state_dict().values(),
                              strict=True):
        assert (pa == pb).all(), name


def _damaged(tmp_path, change) -> str:
    """The ANN checkpoint with ``change(arrays)`` applied, written back."""
    _, _, est = _trained("ann")
    path = tmp_path / "m.npz"
    save_checkpoint(path, est)
    with np.load(path) as npz:
        arrays = {k: npz[k] for k in npz.files}
    change(arrays)
    np.savez(path, **arrays)
    return str(path)


def _set(name, value):
    def change(arrays):
        arrays[name] = value(arrays[name]) if callable(value) else value
    return change


def _nan_weight(array):
    array = array.copy()
    array.flat[3] = np.nan
    return array


def _meta(text: str):
    return np.frombuffer(text.encode(), dtype=np.uint8)


@pytest.mark.parametrize(("change", "problem"), [
    (lambda a: _set(_first_weight(a), _nan_weight)(a), "non-finite values"),
    (lambda a: _set(_first_weight(a), lambda w: np.full(w.shape, "x"))(a), "not real numbers"),
    (lambda a: _set(_first_weight(a), lambda w: np.full(w.shape, np.inf, np.float32))(a),
     "non-finite values"),
    (lambda a: _set("meta", lambda m: _meta(m.tobytes().decode().replace(
        '"x_std": [', '"x_std": [NaN, ')))(a), "no readable metadata"),
    (lambda a: _set("meta", lambda m: _meta(m.tobytes().decode().replace(
        '"x_std": [', '"x_std": [0.0, ').replace('"x_mean": [', '"x_mean": [0.0, ')
        .replace('"n_sensors": 4', '"n_sensors": 5').replace(
            '"sensor_names": [', '"sensor_names": ["E", ')))(a), "scales must be > 0"),
    (lambda a: _set("meta", _meta("[" * 100_000 + "]" * 100_000))(a), "no readable metadata"),
    (lambda a: _set("meta", lambda m: _meta(m.tobytes().decode().replace(
        '"kind": "ann"', '"kind": "rnn"')))(a), "unknown model kind 'rnn'"),
    (lambda a: _set("meta", lambda m: _meta(m.tobytes().decode().replace(
        '"hidden": 8', '"hidden": 0')))(a), "hidden = 0 is not a positive"),
    (lambda a: _set("meta", lambda m: _meta(m.tobytes().decode().replace(
        '"output": "direction"', '"output": "quaternion"')))(a), "unknown output"),
    (lambda a: _set("meta", lambda m: _meta(m.tobytes().decode().replace(
        '"stateful": false', '"stateful": true')))(a), "stateful is true only for an ENNet"),
    (lambda a: _set("meta", lambda m: _meta(m.tobytes().decode().replace(
        '"stateful": false', '"stateful": 1')))(a), "is not true or false"),
    (lambda a: _set("meta", lambda m: _meta(m.tobytes().decode().replace(
        '"shoulder_elv"]', '"shoulder_rot"]')))(a), "a direction output needs the angles"),
])
def test_damaged_checkpoints_are_refused_not_evaluated(tmp_path, change, problem):
    path = _damaged(tmp_path, change)
    with pytest.raises(CheckpointError, match=problem):
        load_checkpoint(path)


def _first_weight(arrays) -> str:
    return next(k for k in sorted(arrays) if k.startswith("net/") and k.endswith("weight"))


ROOT = Path(__file__).resolve().parents[1]
#: Load the fixture checkpoints and stream frames through the default and numpy engines in a
#: fresh interpreter; print the modules of torch that got imported (none, it is hoped).
_TORCH_FREE = """
import sys
import numpy as np
from exohil.estimator.checkpoint import load_checkpoint
from exohil.estimator.inference import StreamingEstimator, onnxruntime_available

frames = np.random.default_rng(0).normal(550.0, 30.0, size=(40, 4))
for name in ("ennet", "ann"):
    est = load_checkpoint(f"fixtures/models/{name}.npz")
    for backend in (None, "numpy"):
        engine = StreamingEstimator(est, backend)
        out = np.array([engine.push(v).copy() for v in frames])
        assert out.shape == (40, 2) and np.isfinite(out).all(), (name, backend)
        print(name, engine.backend)
print("ort", onnxruntime_available())
print("torch:", sorted(m for m in sys.modules if m == "torch" or m.startswith("torch.")))
"""


def test_checkpoints_load_and_stream_without_torch():
    done = subprocess.run([sys.executable, "-c", _TORCH_FREE], cwd=ROOT, capture_output=True,
                          text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[-1] == "torch: []", done.stdout
    if lines[-2] == "ort True":  # the default engine then is ONNX Runtime, also torch-free
        assert "ennet onnxruntime" in lines and "ann onnxruntime" in lines


def test_loaded_weights_become_the_module_when_torch_is_asked_for(tmp_path):
    import torch

    est = load_checkpoint(ROOT / "fixtures" / "models" / "ann.npz")
    assert est.has_network and "has no network" not in repr(est)
    arrays = est.weights(np.float32)
    net = est.network  # built now, from the arrays
    assert isinstance(net, torch.nn.Module) and not net.training
    for name, tensor in net.state_dict().items():
        np.testing.assert_array_equal(tensor.numpy(), arrays[name])
    with torch.no_grad():
        net.state_dict()["head.0.bias"].add_(1.0)  # the module holds the weights from now on
    np.testing.assert_array_equal(est.weights(np.float32)["head.0.bias"],
                                  arrays["head.0.bias"] + 1.0)
    save_checkpoint(tmp_path / "changed.npz", est)
    back = load_checkpoint(tmp_path / "changed.npz")
    np.testing.assert_array_equal(back.weights(np.float32)["head.0.bias"],
                                  arrays["head.0.bias"] + 1.0)


def test_weights_are_copies():
    est = load_checkpoint(ROOT / "fixtures" / "models" / "ann.npz")
    est.weights()["head.0.bias"][:] = 0.0
    assert est.weights()["head.0.bias"].any()


def test_evaluate_reports_the_one_accuracy_definition_beside_all_frames():
    from exohil.estimator.coverage import block_coverage
    from exohil.estimator.evaluation import OBSERVABLE_ELEVATION_DEG, evaluate
    from exohil.estimator.report import comparison_markdown
    from exohil.estimator.workflow import ModelResult

    _, split, est = _trained("ann")
    result = evaluate(est, split.test)
    observable = evaluate(est, split.test, {"shoulder_elv": OBSERVABLE_ELEVATION_DEG})
    for angle in est.target.angles:  # the headline RMSE: only where θ is observable
        assert result["accuracy"][f"accuracy.rmse.{angle}"] == pytest.approx(
            observable["rmse"][angle], rel=1e-12)
    assert result["accuracy"]["accuracy.direction_rmse"] > 0
    assert result["accuracy"]["accuracy.frames_scored"] == result["frames"]
    scored = ModelResult("ann", est, result, block_coverage(est, split.test))
    table = comparison_markdown([scored], est.target.angles, title="t", command="c", split="s",
                                data="d")
    header = table.splitlines()[6]
    assert "elv_angle RMSE where φ ≥ 20° (°)" in header and "arm direction" in header
    row = table.splitlines()[8]
    assert f"{result['accuracy']['accuracy.rmse.elv_angle']:.2f}" in row


def test_a_figure_measured_on_no_frame_is_saved_as_null_and_the_checkpoint_loads(tmp_path):
    """Validation with no frame at 20° elevation or more leaves its accuracy NaN: the
    checkpoint keeps it as not measured (null) and every reader can load it."""
    est = load_checkpoint(ROOT / "fixtures" / "models" / "ann.npz")
    est.info["metrics"] = {"validation": {"accuracy": {"accuracy.rmse.elv_angle": float("nan"),
                                                       "accuracy.direction_rmse": 1.5}}}
    save_checkpoint(tmp_path / "m.npz", est)
    back = load_checkpoint(tmp_path / "m.npz")
    assert back.info["metrics"]["validation"]["accuracy"] == {
        "accuracy.rmse.elv_angle": None, "accuracy.direction_rmse": 1.5}
