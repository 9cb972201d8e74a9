"""The teleoperation sink drives a NAO arm through the conversion chain."""

import numpy as np
import pytest

from exohil.harness.teleop import SimulatedNao, TeleopSink


def test_known_poses_reach_the_simulated_nao():
    nao = SimulatedNao()
    sink = TeleopSink(nao)
    sink.accept(0.0, 0.0, 0.0)  # hanging
    assert np.allclose(np.rad2deg(nao.joints[:2]), [90.0, 0.0], atol=1e-9)
    sink.accept(0.004, 90.0, 90.0)  # forward flexion
    assert np.allclose(np.rad2deg(nao.joints[:2]), [0.0, 0.0], atol=1e-9)
    sink.accept(0.008, 0.0, 90.0)  # abduction: roll clamped
    assert np.rad2deg(nao.joints[1]) == pytest.approx(-76.0)
    summary = nao.summary()
    assert summary["commands"] == 3 and summary["clamped_commands"] == 1
    assert summary["clamped_per_joint"]["RShoulderRoll"] == 1


def test_commands_stay_continuous_through_the_roll_singularity():
    nao = SimulatedNao()
    sink = TeleopSink(nao)
    pitches = []
    for theta in np.linspace(-10.0, 10.0, 201):  # sweep through pure abduction at 90°
        pitches.append(sink.accept(0.0, theta, 90.0)[0])
    assert np.all(np.isfinite(pitches))
    assert np.max(np.abs(np.diff(pitches))) < np.deg2rad(2.0)
