"""Recording → blocks: alignment, unlabelled frames, target selection, causal offsets."""

import numpy as np
import pytest
from estimator_synth import shoulder_recording

from exohil.estimator.dataset import (
    DatasetError,
    TargetSpec,
    default_target,
    initial_baseline,
    recording_blocks,
    resolve_target,
)
from exohil.formats.recording import AngleStream, Recording, SensorStream


def test_default_target_is_shoulder_theta_phi():
    assert default_target(shoulder_recording(seconds=1.0)) == TargetSpec(
        "shoulder", ("elv_angle", "shoulder_elv"))


def _knee(n=300):
    t = np.arange(n) / 100.0
    values = np.random.default_rng(0).random((n, 2))
    return Recording(("s1", "s2"), SensorStream(np.arange(n), t, values),
                     {"knee": AngleStream(t, ("knee_flexion",), 40 * np.sin(t)[:, None])},
                     sensor_rate_hz=100.0)


def test_default_target_for_a_single_joint_recording():
    assert default_target(_knee()) == TargetSpec("knee", ("knee_flexion",))


def test_resolve_target_reports_unknown_names():
    with pytest.raises(DatasetError, match="joint 'elbow'"):
        resolve_target(_knee(), "elbow", None)
    with pytest.raises(DatasetError, match="angles"):
        resolve_target(_knee(), "knee", ("nope",))


def test_targets_are_interpolated_at_sensor_times():
    rec = shoulder_recording(seconds=2.0)
    (block,) = recording_blocks(rec, default_target(rec))
    stream = rec.mocap["shoulder"]
    expected = np.interp(block.t, stream.t, stream.column("shoulder_elv"))
    np.testing.assert_allclose(block.y[:, 1], expected)
    assert block.t[0] >= stream.t[0] and block.t[-1] <= stream.t[-1]


def test_a_mocap_gap_splits_the_recording_and_its_frames_are_dropped():
    rec = _knee(400)
    angles = rec.mocap["knee"].angles
    angles[150:160] = np.nan
    blocks = recording_blocks(rec, TargetSpec("knee", ("knee_flexion",)))
    assert len(blocks) == 2
    assert all(np.isfinite(b.y).all() for b in blocks)
    assert blocks[0].t[-1] < 1.5 and blocks[1].t[0] > 1.58


def test_a_mocap_dropout_splits_the_recording_and_its_frames_are_dropped():
    """A time gap in the motion capture (the format's only way to mark lost markers) is
    not filled with a straight line to train or score on."""
    rec = _knee(400)
    stream = rec.mocap["knee"]
    keep = (stream.t < 1.5) | (stream.t > 1.8)
    rec.mocap["knee"] = AngleStream(stream.t[keep], stream.names, stream.angles[keep])
    blocks = recording_blocks(rec, TargetSpec("knee", ("knee_flexion",)))
    assert len(blocks) == 2
    assert blocks[0].t[-1] < 1.5 and blocks[1].t[0] > 1.8


def test_dropped_sensor_frames_do_not_split_a_block():
    rec = _knee(300)
    keep = np.r_[0:100, 103:300]
    rec.sensors = SensorStream(rec.sensors.seq[keep], rec.sensors.t[keep],
                               rec.sensors.values[keep])
    assert len(recording_blocks(rec, default_target(rec))) == 1


def test_initial_baseline_is_causal():
    x = np.arange(20, dtype=float)[:, None] * np.ones((1, 3))
    base = initial_baseline(x, 5)
    for i in range(20):
        np.testing.assert_allclose(base[i], x[: min(i + 1, 5)].mean(0))


def test_offset_removal_cancels_a_donning_shift():
    a = recording_blocks(shoulder_recording(seconds=2.0), TargetSpec(
        "shoulder", ("elv_angle",)), offset_frames=50)[0]
    b = recording_blocks(shoulder_recording(seconds=2.0, offset_mm=7.5), TargetSpec(
        "shoulder", ("elv_angle",)), offset_frames=50)[0]
    np.testing.assert_allclose(a.x, b.x, atol=1e-9)
