"""Streaming engine: frame-by-frame parity with the batch model for every backend."""

import numpy as np
import pytest
from estimator_synth import shoulder_recording

from exohil.estimator.dataset import default_target, recording_blocks
from exohil.estimator.inference import BACKENDS, StreamingEstimator
from exohil.estimator.splits import time_block_split
from exohil.estimator.training import TrainConfig, train

CASES = [("ennet", 1), ("ennet", 3), ("lnnet", 2), ("ann", 1), ("cnn", 1), ("classical", 1)]
SUPPORTED = {"numpy": {"ennet", "lnnet", "ann", "classical"},
             "torch": {"ennet", "lnnet", "ann", "cnn"},
             "torchscript": {"ennet", "lnnet", "ann", "cnn"},
             "onnxruntime": {"ennet", "lnnet", "ann", "cnn"}}


@pytest.fixture(scope="module")
def recording():
    return shoulder_recording(seconds=3.0, seed=5, offset_mm=2.0)


_CACHE: dict = {}


def _estimator(recording, kind, dilation):
    """One tiny trained model per (kind, dilation), shared by the backends' tests."""
    key = (kind, dilation)
    if key not in _CACHE:
        _CACHE[key] = _train(recording, kind, dilation)
    return _CACHE[key]


def _train(recording, kind, dilation):
    target = default_target(recording)
    split = time_block_split(recording_blocks(recording, target, offset_frames=25), 0.3)
    cfg = TrainConfig(kind=kind, max_epochs=2, hidden=12, window=6, dilation=dilation)
    return train(split, recording.sensor_names, target, cfg, offset_frames=25)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize(("kind", "dilation"), CASES)
def test_push_matches_batch_prediction(recording, backend, kind, dilation):
    if backend == "onnxruntime":
        pytest.importorskip("onnxruntime")
        pytest.importorskip("onnx")
    est = _estimator(recording, kind, dilation)
    if kind not in SUPPORTED[backend]:
        with pytest.raises(ValueError):
            StreamingEstimator(est, backend)
        return
    target = default_target(recording)
    reference = est.predict_block(recording_blocks(recording, target, offset_frames=25)[0])
    engine = StreamingEstimator(est, backend)
    raw = recording.sensors.values[: reference.shape[0]]
    for _ in range(2):  # a reset engine repeats itself exactly
        streamed = np.array([engine.push(v).copy() for v in raw])
        np.testing.assert_allclose(streamed, reference, rtol=0, atol=1e-5)  # degrees
        engine.reset()


def test_push_reuses_its_output_buffer(recording):
    engine = StreamingEstimator(_estimator(recording, "ennet", 1), "numpy")
    first = engine.push(recording.sensors.values[0])
    assert engine.push(recording.sensors.values[1]) is first


def test_unknown_backend(recording):
    with pytest.raises(ValueError, match="unknown backend"):
        StreamingEstimator(_estimator(recording, "ann", 1), "tensorrt")


def test_onnxruntime_push_reuses_its_output_buffer(recording):
    pytest.importorskip("onnxruntime")
    pytest.importorskip("onnx")
    engine = StreamingEstimator(_estimator(recording, "ennet", 1), "onnxruntime")
    first = engine.push(recording.sensors.values[0]).copy()
    out = engine.push(recording.sensors.values[60])
    assert engine.push(recording.sensors.values[61]) is out
    assert not np.array_equal(out, first)  # the bound input really changes per frame


def test_default_backend_prefers_onnxruntime_when_installed(recording, monkeypatch):
    from exohil.estimator import inference

    ennet, classical, cnn = (_estimator(recording, k, 1) for k in ("ennet", "classical", "cnn"))
    assert inference.default_backend(classical) == "numpy"
    monkeypatch.setattr(inference, "onnxruntime_available", lambda: False)
    assert inference.default_backend(ennet) == "numpy"
    assert StreamingEstimator(ennet).backend == "numpy"
    assert StreamingEstimator(cnn).backend == "torch"  # the numpy engine has no CNN
    with pytest.raises(ValueError, match="needs the onnxruntime"):
        StreamingEstimator(ennet, "onnxruntime")
    monkeypatch.setattr(inference, "onnxruntime_available", lambda: True)
    assert inference.default_backend(ennet) == "onnxruntime"


def test_demo_backend_choices_match_the_engine():
    from exohil.harness.cmd_demo import demo

    option = next(p for p in demo.params if p.name == "backend")
    assert set(option.type.choices) == {"auto", *BACKENDS}
