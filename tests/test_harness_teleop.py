"""The teleoperation sink drives a NAO arm through the conversion chain."""

import time

import numpy as np
import pytest

from exohil.harness.frame_source import Frame
from exohil.harness.pipeline import Sample
from exohil.harness.teleop import SimulatedNao, TeleopSink

NAMES = ("elv_angle", "shoulder_elv")


def _sample(theta, phi, names=NAMES):
    frame = Frame(seq=0, device_time_s=0.0, values_mm=np.zeros(4), host_ns=time.perf_counter_ns())
    angles = {"elv_angle": theta, "shoulder_elv": phi, "shoulder_rot": 0.0}
    return Sample(frame, np.array([angles[n] for n in names]))


def test_known_poses_reach_the_simulated_nao():
    nao = SimulatedNao()
    sink = TeleopSink([nao], NAMES)
    sink.accept(_sample(0.0, 0.0))  # hanging
    assert np.allclose(np.rad2deg(nao.joints[:2]), [90.0, 0.0], atol=1e-9)
    sink.accept(_sample(90.0, 90.0))  # forward flexion
    assert np.allclose(np.rad2deg(nao.joints[:2]), [0.0, 0.0], atol=1e-9)
    sample = _sample(0.0, 90.0)  # abduction: roll clamped
    sink.accept(sample)
    assert np.rad2deg(nao.joints[1]) == pytest.approx(-76.0)
    assert sample.command is not None and sample.command.clamped[1]
    assert "commanded" in sample.stamps
    summary = nao.summary()
    assert summary["commands"] == 3 and summary["clamped_commands"] == 1
    assert summary["clamped_per_joint"]["RShoulderRoll"] == 1


def test_angle_columns_come_from_the_estimator_names():
    reordered = ("shoulder_elv", "shoulder_rot", "elv_angle")
    a, b = SimulatedNao(), SimulatedNao()
    TeleopSink([a], NAMES).accept(_sample(30.0, 60.0))
    TeleopSink([b], reordered).accept(_sample(30.0, 60.0, reordered))
    assert np.array_equal(a.joints, b.joints)
    with pytest.raises(ValueError, match="elv_angle"):
        TeleopSink([a], ("knee_flexion",))


def test_commands_stay_continuous_through_the_roll_singularity():
    sink = TeleopSink([SimulatedNao()], NAMES)
    pitches = []
    for theta in np.linspace(-10.0, 10.0, 201):  # sweep through pure abduction at 90°
        pitches.append(sink.command_for(theta, 90.0).joints[0])
    assert np.all(np.isfinite(pitches))
    assert np.max(np.abs(np.diff(pitches))) < np.deg2rad(2.0)
