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


def test_abduction_through_the_roll_limit_follows_the_nearest_direction():
    # Pure abduction (θ = 0) from hanging to overhead. Below 76° and above 104° the direction
    # is reachable; between, the roll stays at −76° and the pitch leans the arm toward the
    # target (down below 90°, up above). At exactly 90° (roll singularity) every pitch is as
    # near, and the sink's hint keeps the previous one. The direction comes first, so the
    # pitch turns from +90° to −90° across 90° (docs/conventions.md).
    nao = SimulatedNao()
    sink = TeleopSink(nao)
    commands = {phi: np.rad2deg(sink.accept(0.0, 0.0, phi)) for phi in np.arange(0.0, 181.0)}
    assert all(np.all(np.isfinite(c)) for c in commands.values())
    assert commands[60.0][:2] == pytest.approx([90.0, -60.0])
    assert commands[85.0][:2] == pytest.approx([90.0, -76.0])
    assert commands[90.0][:2] == pytest.approx([90.0, -76.0])  # pitch from the hint
    assert commands[95.0][:2] == pytest.approx([-90.0, -76.0])
    assert commands[120.0][:2] == pytest.approx([-90.0, -60.0])  # reachable: exact
