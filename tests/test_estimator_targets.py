"""The well-posed target (the humerus direction), the stateful ENNet and the per-model
defaults: what the networks learn and how it comes back out as angles."""

import numpy as np
import pytest
from click.testing import CliRunner
from estimator_synth import shoulder_recording
from hypothesis import given
from hypothesis import strategies as st

from exohil.estimator.checkpoint import load_checkpoint, save_checkpoint
from exohil.estimator.dataset import TargetSpec, default_target, recording_blocks
from exohil.estimator.defaults import DEFAULT_WINDOW, default_window
from exohil.estimator.evaluation import arm_direction_error_deg
from exohil.estimator.splits import time_block_split
from exohil.estimator.trained import Normalisation, TrainedEstimator
from exohil.estimator.training import TrainConfig, train
from exohil.estimator.workflow import model_config
from exohil.formats.recording_writer import write_recording
from exohil.harness.cli import main


def _estimator(angles=("elv_angle", "shoulder_elv"), output="direction"):
    from exohil.estimator.architecture import ModelConfig

    cfg = ModelConfig("ann", 4, 2, output=output)
    norm = Normalisation(np.zeros(4), np.ones(4), np.zeros(cfg.n_outputs),
                         np.ones(cfg.n_outputs))
    return TrainedEstimator(cfg, ("F", "SF", "SR", "R"), TargetSpec("shoulder", angles), norm)


@given(theta=st.floats(-180.0, 180.0), phi=st.floats(0.5, 179.5),
       swapped=st.booleans())
def test_direction_target_comes_back_as_the_same_arm_direction(theta, phi, swapped):
    angles = ("shoulder_elv", "elv_angle") if swapped else ("elv_angle", "shoulder_elv")
    est = _estimator(angles)
    y = np.array([[phi, theta]]) if swapped else np.array([[theta, phi]])
    target = est.encode(y)
    assert target.shape == (1, 3) and np.isclose(np.linalg.norm(target), 1.0)
    back = est.decode(2.5 * target)  # the length of the output does not matter
    th, ph = (1, 0) if swapped else (0, 1)
    assert abs(back[0, ph] - phi) < 1e-9
    # arccos of a dot product resolves ~1e-6 deg at best
    assert arm_direction_error_deg(back[0, th], back[0, ph], theta, phi) < 1e-5


def test_angles_output_is_the_identity():
    est = _estimator(output="angles")
    y = np.array([[10.0, 0.0], [-30.0, 90.0]])
    assert est.encode(y) is y and est.decode(y) is y


@pytest.fixture(scope="module")
def recording():
    return shoulder_recording(seconds=8.0, seed=3)


def _split(recording):
    return time_block_split(recording_blocks(recording, default_target(recording)), 0.3)


@pytest.mark.parametrize("stateful", [False, True])
def test_trained_direction_models_round_trip_with_their_config(recording, tmp_path, stateful):
    cfg = TrainConfig(kind="ennet", stateful=stateful, window=4, hidden=8, max_epochs=2,
                      dense=(16, 8))
    est = train(_split(recording), recording.sensor_names, default_target(recording), cfg)
    assert est.config.output == "direction" and est.config.n_outputs == 3
    assert est.config.stateful is stateful
    assert (est.config.window, est.config.dilation) == ((1, 1) if stateful else (4, 1))
    assert est.config.dense == (16, 8)
    path = tmp_path / "m.npz"
    save_checkpoint(path, est)
    back = load_checkpoint(path)
    assert back.config == est.config
    block = _split(recording).test[0]
    np.testing.assert_allclose(back.predict_block(block), est.predict_block(block), atol=1e-9)


@pytest.mark.parametrize("rate", [100.0, 500.0])
def test_stateful_training_streams_span_seconds_at_any_rate(monkeypatch, rate):
    """Truncated backpropagation runs streams of 5 s (1250 frames at 250 Hz), not 1250
    frames: 12.5 s at 100 Hz, 2.5 s at 500 Hz."""
    from exohil.estimator.models import ENNet

    rec = shoulder_recording(seconds=20.0, rate=rate, seed=4)
    streams: list[int] = []  # frames of each group of streams run side by side
    sequence = ENNet.sequence

    def recorded(self, x, state=None, *args, **kwargs):
        if self.training:
            if state is None:
                streams.append(0)
            streams[-1] += x.shape[1]
        return sequence(self, x, state, *args, **kwargs)

    monkeypatch.setattr(ENNet, "sequence", recorded)
    split = time_block_split(recording_blocks(rec, default_target(rec)), 0.0)
    cfg = TrainConfig(kind="ennet", stateful=True, hidden=4, max_epochs=1, dense=(4,))
    train(split, rec.sensor_names, default_target(rec), cfg, sensor_rate_hz=rate)
    assert streams and max(streams) == round(5.0 * rate)


def test_knee_like_targets_are_learnt_as_angles(recording):
    target = TargetSpec("shoulder", ("elv_angle",))
    blocks = recording_blocks(recording, target)
    est = train(time_block_split(blocks, 0.3), recording.sensor_names, target,
                TrainConfig(kind="ann", max_epochs=1, dense=(8,)))
    assert est.config.output == "angles" and est.config.n_outputs == 1


def test_a_direction_output_needs_both_shoulder_angles(recording):
    target = TargetSpec("shoulder", ("elv_angle",))
    blocks = recording_blocks(recording, target)
    with pytest.raises(ValueError, match="direction output needs"):
        train(time_block_split(blocks, 0.3), recording.sensor_names, target,
              TrainConfig(kind="ann", max_epochs=1, output="direction"))


def test_default_window_spans_the_same_time_at_any_rate():
    frames, span = DEFAULT_WINDOW["ennet"]
    for rate in (100.0, 250.0, 1000.0):
        window, dilation = default_window("ennet", rate)
        assert window == frames
        assert abs((window - 1) * dilation / rate - span) <= 0.5 * (window - 1) / rate
    assert default_window("ann", 250.0) == (1, 1)


def test_model_config_fills_only_what_is_left_open():
    base = TrainConfig(window=None, dilation=None)
    cfg = model_config("ennet", base, 100.0)
    assert (cfg.kind, cfg.stateful, (cfg.window, cfg.dilation)) == (
        "ennet", False, default_window("ennet", 100.0))
    assert model_config("ennet", TrainConfig(window=3, dilation=2), 100.0).window == 3
    stateful = model_config("ennet-stateful", base, 250.0)
    assert (stateful.kind, stateful.stateful, stateful.window) == ("ennet", True, 1)


def test_a_stateful_ennet_takes_no_window(tmp_path, recording):
    write_recording(tmp_path / "r.mcap", recording)
    result = CliRunner().invoke(main, ["train", "--model", "ennet-stateful", "--window", "5",
                                       str(tmp_path / "r.mcap"), "--out",
                                       str(tmp_path / "m.npz")])
    assert result.exit_code == 2
    assert "a stateful ENNet has no window" in result.output
    assert not (tmp_path / "m.npz").exists()


def test_plane_of_elevation_errors_wrap_around():
    from exohil.estimator.evaluation import accuracy_measurements, angle_errors

    angles = ("elv_angle", "shoulder_elv")
    est, truth = np.array([[-179.0, 50.0], [90.0, 50.0]]), np.array([[179.0, 50.0], [-90.0, 30.0]])
    np.testing.assert_allclose(angle_errors(est, truth, angles), [[2.0, 0.0], [-180.0, 20.0]])
    rmse = {m.name: m.value for m in accuracy_measurements(est, truth, angles)}
    assert rmse["accuracy.rmse.elv_angle"] == pytest.approx(np.sqrt((4 + 180**2) / 2))
