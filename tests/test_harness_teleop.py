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


def test_abduction_through_the_roll_limit_follows_the_nearest_direction():
    # Pure abduction (θ = 0) from hanging to overhead. Below 76° and above 104° the direction
    # is reachable; between, the roll stays at −76° and the pitch leans the arm toward the
    # target (down below 90°, up above). At exactly 90° (roll singularity) every pitch is as
    # near, and the sink's hint keeps the previous one. The direction comes first, so the
    # pitch turns from +90° to −90° across 90° (docs/conventions.md).
    nao = SimulatedNao()
    sink = TeleopSink([nao], NAMES)
    commands = {phi: np.rad2deg(sink.command_for(0.0, phi).joints)
                for phi in np.arange(0.0, 181.0)}
    assert all(np.all(np.isfinite(c)) for c in commands.values())
    assert commands[60.0][:2] == pytest.approx([90.0, -60.0])
    assert commands[85.0][:2] == pytest.approx([90.0, -76.0])
    assert commands[90.0][:2] == pytest.approx([90.0, -76.0])  # pitch from the hint
    assert commands[95.0][:2] == pytest.approx([-90.0, -76.0])
    assert commands[120.0][:2] == pytest.approx([-90.0, -60.0])  # reachable: exact


@pytest.mark.parametrize("poses, joint", [
    ([(-60.0, 89.95), (-60.0, 90.05)] * 50, 0),  # the arm horizontal behind the side plane
    ([(-2.0, 150.0), (2.0, 150.0)] * 50, 2),     # overhead, θ wavering across 0
])
def test_a_pose_wavering_across_a_limit_choice_does_not_swing_the_joint(poses, joint):
    """The probe's reproducers: 0.05° about the horizontal behind the shoulder swung
    ShoulderPitch between +119.5° and −119.5° on every frame, and ±2° of θ overhead swung
    ElbowYaw the same way. The sink keeps the previous command's limit."""
    sink = TeleopSink([], NAMES)
    stream = np.rad2deg([sink.command_for(t, p).joints for t, p in poses])
    assert np.ptp(stream[:, joint]) < 1e-9
    assert np.max(np.abs(np.diff(stream, axis=0))) < 3.0
