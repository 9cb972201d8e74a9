"""`exohil simulate --protocol replay:FILE`: the motion capture of a recording drives the suit,
a calibrated suit of any joint included."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from exohil.emulators.discrepancy import run
from exohil.emulators.discrepancy.profile import (
    calibrated_suit,
    load_calibrated_profile,
    simulate_calibrated,
    write_calibrated_profile,
)
from exohil.emulators.protocols import ANGLE_NAMES, replay_trajectory, replayed_motion
from exohil.formats.recording import AngleStream, Recording, Segment, SensorStream
from exohil.formats.recording_reader import read_recording
from exohil.formats.recording_writer import write_recording
from exohil.harness.cli import main

RATE_HZ = 100.0
NOISE = 0.01


def _knee_truth(angle_deg: np.ndarray) -> np.ndarray:
    """Two textile bands over a knee, noise-free: a smooth function of the flexion each."""
    x = np.deg2rad(angle_deg)
    return np.column_stack([1.0 + 0.4 * x + 0.15 * x**2, 2.0 - 0.3 * np.sin(x)])


def _knee_recording(seconds: float = 60.0, start_s: float = 3.0) -> Recording:
    """A knee recording as an import of a sleeve's CSV gives one (sensors and motion capture
    at the same 100 Hz times), its clock starting at ``start_s``; the flexion swings at two
    rates, with a hold, and a 0.5 s dropout of the motion capture."""
    t = start_s + np.arange(int(seconds * RATE_HZ)) / RATE_HZ
    tau = t - start_s
    flexion = 45.0 - 40.0 * np.cos(2 * np.pi * 0.23 * tau) * np.cos(2 * np.pi * 0.031 * tau)
    held = (tau > 20.0) & (tau < 24.0)
    flexion[held] = flexion[np.argmax(held)] if held.any() else 0.0
    values = _knee_truth(flexion) + np.random.default_rng(7).normal(0.0, NOISE, (t.size, 2))
    kept = ~((tau > 40.0) & (tau < 40.5))
    return Recording(sensor_names=("s1", "s2"),
                     sensors=SensorStream(seq=np.arange(t.size), t=t, values=values),
                     mocap={"knee": AngleStream(t=t[kept], names=("knee_flexion",),
                                                angles=flexion[kept, None])},
                     sensor_units="dR/R0", sensor_rate_hz=RATE_HZ, mocap_rate_hz=RATE_HZ,
                     segments=[Segment("swing", start_s + 1.0, start_s + 30.0)],
                     metadata={"license": "MIT (test)", "notice.LICENSE": "terms",
                               "source": "knee.csv", "generator": "test"})


@pytest.fixture(scope="module")
def knee(tmp_path_factory):
    """The knee recording, where it and its calibrated profile (the workflow's) are, and
    the workflow's outcome."""
    folder = tmp_path_factory.mktemp("knee")
    rec = _knee_recording()
    write_recording(folder / "knee.mcap", rec)
    outcome = run(rec, "knee", workers=1)
    write_calibrated_profile(folder / "knee.toml", calibrated_suit(outcome, "knee"))
    return rec, folder, outcome


def test_a_knee_suit_calibrated_and_replayed_gives_back_its_recording(knee):
    """A calibrated profile of a knee is driven by the knee's own motion capture, on its
    clock: the replayed sensors are the workflow's final prediction where the frames are
    the trial's, and follow the measured suit within its noise; the angles are those
    recorded, and the segment, the license and the source notes go with them."""
    rec, folder, outcome = knee
    out = folder / "sim.mcap"
    result = CliRunner().invoke(main, ["simulate", "--profile", str(folder / "knee.toml"),
                                       "--protocol", f"replay:{folder / 'knee.mcap'}",
                                       "--without", "noise", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "of replay:knee.mcap (its clock, from 3 s) on calibrated suit profile" \
        in result.stderr
    sim = read_recording(out)
    assert sim.sensor_names == ("s1", "s2") and sim.sensor_units == "dR/R0"
    stream = sim.mocap["knee"]
    source = rec.mocap["knee"]
    np.testing.assert_allclose(stream.t, source.t, rtol=0, atol=1e-6)  # times kept to 1 µs
    np.testing.assert_allclose(stream.angles, source.angles, atol=1e-4)
    np.testing.assert_allclose(sim.sensors.t, rec.sensors.t, rtol=0, atol=1e-6)
    trial = outcome.trial
    assert trial.t[0] == pytest.approx(3.0) and trial.n == len(sim.sensors)
    np.testing.assert_allclose(sim.sensors.values[trial.valid], outcome.after.prediction[
        trial.valid], rtol=0, atol=0.5e-4 + 1e-6)  # four decimals kept by the format
    flexion = np.interp(sim.sensors.t, stream.t, stream.angles[:, 0])
    error = sim.sensors.values - _knee_truth(flexion)
    assert np.sqrt(np.mean(error**2)) < 2 * NOISE  # the model of the suit, not its noise
    assert [(s.name, s.t0, s.t1) for s in sim.segments] == [("swing", 4.0, 33.0)]
    assert sim.metadata["replayed.license"] == "MIT (test)"
    assert sim.metadata["replayed.notice.LICENSE"] == "terms"
    assert sim.metadata["replayed.source"] == "knee.csv"
    assert "replayed.generator" not in sim.metadata


def test_the_replay_runs_the_profile_on_its_frames(knee):
    """Noise-free, the replayed sensors are the profile's model at the interpolated angles
    (four decimals kept by the format); with noise, about the profile's noise on top."""
    _, folder, _ = knee
    suit = load_calibrated_profile(folder / "knee.toml")
    runs = {}
    for name, extra in (("clean", ["--without", "noise"]), ("noisy", [])):
        result = CliRunner().invoke(main, ["simulate", "--profile", str(folder / "knee.toml"),
                                           "--protocol", f"replay:{folder / 'knee.mcap'}",
                                           "--seed", "4", *extra, "--out",
                                           str(folder / f"{name}.mcap")])
        assert result.exit_code == 0, result.output
        runs[name] = read_recording(folder / f"{name}.mcap")
    clean = runs["clean"]
    stream = clean.mocap["knee"]
    angles = np.interp(clean.sensors.t, stream.t, stream.angles[:, 0])[:, None]
    expected = simulate_calibrated(suit, clean.sensors.t, angles)
    np.testing.assert_allclose(clean.sensors.values, expected, rtol=0, atol=0.5e-4 + 1e-9)
    noise = np.std(runs["noisy"].sensors.values - clean.sensors.values, axis=0)
    np.testing.assert_allclose(noise, suit.noise, rtol=0.05)  # 6,000 draws per sensor


def test_the_default_suit_replays_a_recorded_shoulder_motion(tmp_path):
    """A geometric profile replays the shoulder's motion capture: the same angles through
    every sample, on the suit's sensors."""
    t = 1.5 + np.arange(1200) / 120.0
    angles = np.column_stack([30.0 + 20.0 * np.sin(t), 50.0 + 30.0 * np.sin(0.7 * t),
                              10.0 * np.cos(t)])
    rec = Recording(sensor_names=("F", "SF", "SR", "R"),
                    sensors=SensorStream(seq=np.arange(2), t=np.array([1.5, 1.504]),
                                         values=np.zeros((2, 4))),
                    mocap={"shoulder": AngleStream(t=t, names=ANGLE_NAMES, angles=angles)})
    trajectory = replay_trajectory(rec, "shoulder.mcap")
    assert trajectory.source == "replay:shoulder.mcap from 1.5 s"
    np.testing.assert_allclose(trajectory.sample(t - 1.5), angles, atol=1e-9)
    write_recording(tmp_path / "shoulder.mcap", rec)
    result = CliRunner().invoke(main, ["simulate", "--protocol",
                                       f"replay:{tmp_path / 'shoulder.mcap'}", "--out",
                                       str(tmp_path / "sim.mcap")])
    assert result.exit_code == 0, result.output
    sim = read_recording(tmp_path / "sim.mcap")
    assert sim.sensor_names == ("F", "SF", "SR", "R")
    assert sim.sensors.t[-1] == pytest.approx(t[-1] - 1.5, abs=0.02)
    np.testing.assert_allclose(sim.mocap["shoulder"].angles,
                               trajectory.sample(sim.mocap["shoulder"].t), atol=1e-4)


def test_a_replay_without_the_joints_motion_is_one_error_line(knee, tmp_path):
    """A calibrated knee replaying a recording with no knee stream, or one sample of it, is
    refused in one line, and nothing is written; a
    recording that does not exist is a usage error."""
    _, folder, _ = knee
    rec = _knee_recording(seconds=1.0)  # its sensors only
    shoulder_only = Recording(sensor_names=rec.sensor_names, sensors=rec.sensors)
    write_recording(tmp_path / "none.mcap", shoulder_only)
    one = AngleStream(t=np.array([3.0]), names=("knee_flexion",), angles=np.array([[10.0]]))
    write_recording(tmp_path / "one.mcap", Recording(sensor_names=rec.sensor_names,
                                                     sensors=rec.sensors, mocap={"knee": one}))
    for name, words in (("none.mcap", "none.mcap: no /mocap/knee stream to replay (it holds "
                                      "no motion capture)"),
                        ("one.mcap", "holds 1 sample(s) with every one of knee_flexion finite")):
        result = CliRunner().invoke(main, ["simulate", "--profile", str(folder / "knee.toml"),
                                           "--protocol", f"replay:{tmp_path / name}",
                                           "--out", str(tmp_path / "x.mcap")])
        assert result.exit_code == 1 and words in result.output, result.output
        assert len(result.output.strip().splitlines()) == 1
    assert not (tmp_path / "x.mcap").exists()
    result = CliRunner().invoke(main, ["simulate", "--protocol", "replay:absent.mcap",
                                       "--out", str(tmp_path / "x.mcap")])
    assert result.exit_code == 2 and "no such recording: 'absent.mcap'" in result.output
    result = CliRunner().invoke(main, ["simulate", "--protocol",
                                       f"replay:{tmp_path / 'none.mcap'}", "--out",
                                       str(tmp_path / "none.mcap")])
    assert result.exit_code == 2 and "refusing to overwrite it" in result.output


def test_replayed_motion_keeps_the_samples_where_every_angle_is_finite():
    stream = AngleStream(t=np.array([2.0, 2.5, 3.0, 3.5]), names=("a", "b"),
                         angles=np.array([[1.0, 5.0], [2.0, np.nan], [3.0, 6.0], [4.0, 7.0]]))
    rec = Recording(sensor_names=("x",), sensors=SensorStream(
        seq=np.arange(1), t=np.array([2.0]), values=np.zeros((1, 1))),
        mocap={"leg": stream}, segments=[Segment("early", 0.0, 1.0), Segment("mid", 2.5, 9.0)])
    t, angles, segments = replayed_motion(rec, "leg", ("b", "a"), "leg.mcap")
    np.testing.assert_array_equal(t, [2.0, 3.0, 3.5])
    np.testing.assert_array_equal(angles, [[5.0, 1.0], [6.0, 3.0], [7.0, 4.0]])
    assert [(s.name, s.t0, s.t1) for s in segments] == [("mid", 2.5, 3.5)]
    with pytest.raises(ValueError, match="leg.mcap: /mocap/leg has no c"):
        replayed_motion(rec, "leg", ("a", "c"), "leg.mcap")
