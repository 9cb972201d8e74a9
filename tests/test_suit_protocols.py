"""Movement protocols: Table III frame counts, ranges, smoothness, seeding; real motion."""


import numpy as np
import pytest
from shared_data import SHARED_DIR

from exohil.emulators.protocols import (
    CALIBRATION_DURATION_S,
    CALIBRATION_MOVEMENT_S,
    CALIBRATION_SWEEP_ELEVATION_DEG,
    MOCAP_RATE_HZ,
    PAPER_MOVEMENT_FRAMES,
    SWEEP_ELEVATIONS_DEG,
    Trajectory,
    calibration_protocol,
    minimum_jerk,
    mot_trajectory,
    paper_protocol,
)
from exohil.kinematics import humerus_direction

SHOULDER_IK = SHARED_DIR / "realdata" / "shoulder-ik"


@pytest.fixture(scope="module")
def protocol() -> Trajectory:
    return paper_protocol(7)


@pytest.fixture(scope="module")
def mocap(protocol):
    t = protocol.frame_times(MOCAP_RATE_HZ)
    return t, protocol.sample(t)


def frames_in(segment, rate=MOCAP_RATE_HZ) -> slice:
    return slice(int(round(segment.t0 * rate)), int(round(segment.t1 * rate)))


def test_table_iii_frame_counts_at_120_hz(protocol, mocap):
    t, _ = mocap
    assert len(t) == 29551 == sum(PAPER_MOVEMENT_FRAMES.values())
    assert [s.name for s in protocol.segments] == list(PAPER_MOVEMENT_FRAMES)
    for segment in protocol.segments:
        in_segment = np.count_nonzero((t >= segment.t0 - 1e-9) & (t < segment.t1 - 1e-9))
        assert in_segment == PAPER_MOVEMENT_FRAMES[segment.name]
        sl = frames_in(segment)
        assert sl.stop - sl.start == PAPER_MOVEMENT_FRAMES[segment.name]
    assert protocol.duration_s == pytest.approx(29551 / 120.0)
    assert len(protocol.frame_times(250.0)) == round(29551 / 120.0 * 250.0)


def test_angle_ranges_per_movement(protocol, mocap):
    _, deg = mocap
    theta, phi, psi = deg.T
    assert phi.min() >= 0.0 and phi.max() <= max(SWEEP_ELEVATIONS_DEG) + 1e-9
    assert np.all(psi == 0.0)
    ranges = {
        "flexion_extension": (-90.0, 90.0),
        "abduction_adduction": (0.0, 0.0),
        "azimuth_fixed_elevation_varied": (-40.0, 90.0),
        "elevation_fixed_azimuth_varied": (-40.0, 90.0),
        "random": (-40.0, 90.0),
    }
    for segment in protocol.segments:
        sl = frames_in(segment)
        raised = phi[sl] > 1.0  # θ is meaningless while the arm hangs
        lo, hi = ranges[segment.name]
        assert theta[sl][raised].min() >= lo - 1e-9 and theta[sl][raised].max() <= hi + 1e-9
        assert phi[sl].max() > 60.0
    fe = frames_in(protocol.segments[0])
    assert set(np.round(theta[fe][phi[fe] > 1.0])) == {-90.0, 90.0}
    az = frames_in(protocol.segments[2])
    assert len(set(np.round(theta[az][phi[az] > 1.0]))) == 5
    el = frames_in(protocol.segments[3])
    moving_theta = np.abs(np.gradient(theta[el])) > 1e-6
    # the plane of elevation sweeps only at elevations where it is observable (≥ 30°)
    assert set(np.round(phi[el][moving_theta & (phi[el] > 1.0)])) == set(SWEEP_ELEVATIONS_DEG)


def test_motion_is_smooth_and_human_paced(protocol):
    rate = 250.0
    deg = protocol.sample(protocol.frame_times(rate))
    d = humerus_direction(np.deg2rad(deg[:, 0]), np.deg2rad(deg[:, 1]))  # elbow direction
    step = np.arccos(np.clip(np.sum(d[1:] * d[:-1], axis=1), -1.0, 1.0))
    speed = np.rad2deg(step) * rate  # deg/s of the arm itself
    assert speed.max() < 300.0
    assert speed.max() > 60.0
    accel = np.abs(np.diff(deg[:, 1], 2)) * rate**2
    assert accel.max() < 3000.0  # deg/s², no jumps in elevation velocity
    label_speed = np.abs(np.diff(deg[:, 0])) * rate  # θ may turn while the arm hangs
    assert label_speed.max() < 500.0


def test_protocol_has_holds_and_reversals_at_several_amplitudes(protocol, mocap):
    _, deg = mocap
    phi = deg[:, 1]
    still = np.abs(np.diff(phi)) * MOCAP_RATE_HZ < 1.0
    raised_and_still = still & (phi[1:] > 30.0)
    runs, longest, current = [], 0, 0
    for flag in raised_and_still:
        current = current + 1 if flag else 0
        longest = max(longest, current)
        if current == 1:
            runs.append(1)
    assert longest / MOCAP_RATE_HZ > 2.0  # at least one hold of 2+ s under elevation
    peaks = (phi[1:-1] > phi[:-2]) & (phi[1:-1] >= phi[2:]) & (phi[1:-1] > 10.0)
    amplitudes = np.round(phi[1:-1][peaks], -1)
    assert len(set(amplitudes)) >= 4
    troughs = (phi[1:-1] < phi[:-2]) & (phi[1:-1] <= phi[2:]) & (phi[1:-1] > 5.0)
    assert troughs.sum() >= 3  # partial reversals (minor loops) while elevated


def test_protocol_is_seeded(protocol):
    again = paper_protocol(7)
    np.testing.assert_array_equal(again.knot_deg, protocol.knot_deg)
    np.testing.assert_array_equal(again.knot_t, protocol.knot_t)
    assert not np.array_equal(paper_protocol(8).knot_deg, protocol.knot_deg)


def test_minimum_jerk_profile():
    tau = np.linspace(0, 1, 101)
    s = minimum_jerk(tau)
    assert s[0] == 0.0 and s[-1] == 1.0 and np.all(np.diff(s) >= 0)
    assert s[50] == pytest.approx(0.5)


# --- calibration protocol -----------------------------------------------------------------

@pytest.fixture(scope="module")
def calibration() -> Trajectory:
    return calibration_protocol(3)


@pytest.mark.parametrize("duration", [30.0, 45.0, 60.0, 75.5, 120.0])
def test_calibration_lasts_its_duration_and_its_segments_cover_it(duration):
    traj = calibration_protocol(5, duration)
    assert traj.duration_s == pytest.approx(duration, abs=1e-9)
    assert len(traj.frame_times(MOCAP_RATE_HZ)) == round(duration * MOCAP_RATE_HZ)
    assert [s.name for s in traj.segments] == list(CALIBRATION_MOVEMENT_S)
    assert traj.segments[0].t0 == 0.0
    assert traj.segments[-1].t1 == pytest.approx(duration, abs=1e-9)
    for before, after in zip(traj.segments, traj.segments[1:], strict=False):
        assert before.t1 == after.t0 and before.t1 > before.t0
    assert traj.knot_t[-1] == traj.duration_s
    assert traj.source == f"calibration_protocol seed=5 duration_s={duration:g}"


def test_calibration_default_is_60_s_with_the_documented_spans(calibration):
    assert calibration.duration_s == 60.0
    spans = {s.name: s.t1 - s.t0 for s in calibration.segments}
    assert spans == pytest.approx({k: full for k, (full, _) in CALIBRATION_MOVEMENT_S.items()})


@pytest.mark.parametrize("duration", [30.0, 60.0])
def test_calibration_angle_ranges_stay_within_the_paper_protocol(duration):
    paper = paper_protocol(7)
    paper_deg = paper.sample(paper.frame_times(MOCAP_RATE_HZ))
    paper_raised = paper_deg[:, 1] > 1.0
    for seed in range(4):
        traj = calibration_protocol(seed, duration)
        deg = traj.sample(traj.frame_times(MOCAP_RATE_HZ))
        theta, phi, psi = deg.T
        assert np.all(psi == 0.0)
        assert phi.min() >= -1e-9 and phi.max() <= paper_deg[:, 1].max() + 1e-9
        raised = phi > 1.0  # θ is meaningless while the arm hangs
        assert theta[raised].min() >= paper_deg[paper_raised, 0].min() - 1e-9
        assert theta[raised].max() <= paper_deg[paper_raised, 0].max() + 1e-9
        for segment in traj.segments:
            sl = frames_in(segment)
            th, ph, up = theta[sl], phi[sl], raised[sl]
            if segment.name.startswith("stand"):
                assert np.abs(ph).max() < 1e-9
            elif segment.name == "flexion_extension":
                assert set(np.round(th[up])) == {-90.0, 90.0}
                assert 110.0 < ph[th > 0].max() <= 120.0  # flexion to ≈ 120°
                assert 35.0 < ph[th < 0].max() <= 45.0  # extension to ≈ 45°
            elif segment.name == "abduction_adduction":
                assert set(np.round(th[up])) == {0.0}
                assert 110.0 < ph.max() <= 120.0
            elif segment.name == "elevation_fixed_azimuth_varied":
                assert th[up].min() == pytest.approx(-40.0) and th[up].max() == pytest.approx(90.0)
                sweeping = (np.abs(np.gradient(th)) > 1e-6) & up
                assert np.ptp(ph[sweeping]) < 0.01  # one elevation, within the drawn range
                low, high = CALIBRATION_SWEEP_ELEVATION_DEG
                assert low <= ph[sweeping].mean() <= high
            else:  # random reaching
                assert segment.name in ("random_slow", "random_fast")
                assert 5.0 < ph.max() <= 90.0
                assert th[up].min() >= -40.0 and th[up].max() <= 90.0


def test_calibration_starts_and_ends_every_movement_hanging(calibration):
    for segment in calibration.segments:
        ends = calibration.sample(np.array([segment.t0, segment.t1]))
        np.testing.assert_allclose(ends[:, 1], 0.0, atol=1e-9)
    first_and_last = calibration.sample(np.array([0.0, calibration.duration_s]))
    np.testing.assert_allclose(first_and_last[:, 1:], 0.0, atol=1e-9)


@pytest.mark.parametrize("duration", [30.0, 49.9, 50.0, 60.0, 120.0])
def test_calibration_motion_is_smooth_human_paced_and_has_a_hold(duration):
    rate = 250.0
    for seed in range(3):
        traj = calibration_protocol(seed, duration)
        deg = traj.sample(traj.frame_times(rate))
        d = humerus_direction(np.deg2rad(deg[:, 0]), np.deg2rad(deg[:, 1]))
        step = np.arccos(np.clip(np.sum(d[1:] * d[:-1], axis=1), -1.0, 1.0))
        speed = np.rad2deg(step) * rate
        assert 60.0 < speed.max() < 300.0
        assert np.abs(np.diff(deg[:, 1], 2)).max() * rate**2 < 3000.0
        still_raised = (np.abs(np.diff(deg[:, 1])) * rate < 1.0) & (deg[1:, 1] > 30.0)
        edges = np.diff(np.r_[0, still_raised.astype(int), 0])
        longest = np.max(np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1))
        assert longest / rate > 1.0  # the abduction hold (≈ 3 s in 60 s, ≈ 2.5 s in the short one)


def test_calibration_random_reaching_is_slow_then_fast(calibration):
    rate = 250.0
    deg = calibration.sample(calibration.frame_times(rate))
    speed = np.abs(np.diff(deg[:, :2], axis=0)).max(axis=1) * rate
    by_name = {s.name: s for s in calibration.segments}

    def median_moving_speed(name: str) -> float:
        sl = frames_in(by_name[name], rate)
        moving = speed[sl] > 5.0
        return float(np.median(speed[sl][moving]))

    assert median_moving_speed("random_fast") > 1.3 * median_moving_speed("random_slow")


def test_calibration_is_seeded():
    a, b = calibration_protocol(11), calibration_protocol(11)
    np.testing.assert_array_equal(a.knot_t, b.knot_t)
    np.testing.assert_array_equal(a.knot_deg, b.knot_deg)
    other = calibration_protocol(12)
    assert not np.array_equal(other.knot_deg, a.knot_deg)
    assert [s.name for s in other.segments] == [s.name for s in a.segments]
    # its own stream: not the paper protocol's draws under the same seed
    raised = a.knot_deg[a.knot_deg[:, 1] > 0, 1]
    assert not np.isin(raised, paper_protocol(11).knot_deg[:, 1]).any()


@pytest.mark.parametrize("duration", [29.9, 120.5, float("nan"), float("inf"), -60.0])
def test_calibration_duration_out_of_range_is_refused(duration):
    with pytest.raises(ValueError, match="duration"):
        calibration_protocol(1, duration)
    assert CALIBRATION_DURATION_S == (30.0, 120.0)


@pytest.mark.skipif(not SHOULDER_IK.is_dir(), reason="shoulder-ik real data not present")
def test_mot_trajectory_follows_the_trials():
    from exohil.formats.opensim_mot import read_mot

    files = [SHOULDER_IK / "ABD01.mot", SHOULDER_IK / "FLX01.mot"]
    traj = mot_trajectory(files, bridge_s=1.0)
    assert [s.name for s in traj.segments] == ["ABD01", "FLX01"]
    for path, segment in zip(files, traj.segments, strict=True):
        mot = read_mot(path)
        t = segment.t0 + mot.time - mot.time[0]
        deg = traj.sample(t)
        np.testing.assert_allclose(deg[:, 0], mot.columns["plane_elv"], atol=1e-9)
        np.testing.assert_allclose(deg[:, 1], mot.columns["shoulder_elv"], atol=1e-9)
        assert deg[0, 2] == pytest.approx(0.0, abs=1e-9)
        assert segment.t1 - segment.t0 == pytest.approx(mot.time[-1] - mot.time[0])
    assert traj.segments[1].t0 - traj.segments[0].t1 == pytest.approx(1.0)
    bridge = traj.sample(np.linspace(traj.segments[0].t1, traj.segments[1].t0, 50))
    assert np.isfinite(bridge).all() and np.abs(np.diff(bridge, axis=0)).max() < 5.0


def test_mot_trajectory_needs_a_file():
    with pytest.raises(ValueError, match="at least one"):
        mot_trajectory([])


@pytest.mark.parametrize(("knot_t", "knot_deg", "duration", "said"), [
    ([0.0, 1.0], [[0.0, 10.0, 0.0], [0.0, 20.0, 0.0]], 1.0, None),  # lists are taken
    ([0.0, np.nan], [[0.0, 10.0, 0.0], [0.0, 20.0, 0.0]], 1.0, "must be finite"),
    ([0.0, 1.0], [[0.0, np.nan, 0.0], [0.0, 20.0, 0.0]], 1.0, "must be finite"),
    ([0.0, 1.0], [[0.0, 10.0, 0.0], [0.0, 20.0, 0.0]], np.nan, "duration_s must be"),
    ([[0.0, 1.0]], [[0.0, 10.0, 0.0], [0.0, 20.0, 0.0]], 1.0, "knot_t \\(K,\\)"),
])
def test_a_trajectory_checks_its_knots_where_it_is_made(knot_t, knot_deg, duration, said):
    """A list for knot_t failed with an AttributeError, NaN knot times were taken, NaN angles
    and a NaN duration failed deep inside the simulation."""
    from exohil.emulators.protocols import Trajectory

    if said is None:
        assert Trajectory(knot_t, knot_deg, "pchip", duration).sample([0.5]).shape == (1, 3)
        return
    with pytest.raises(ValueError, match=said):
        Trajectory(knot_t, knot_deg, "pchip", duration)
