"""A loop in the pose: the hysteresis term's plays on the joint's angles (a sleeve that slips).

The suit below is the suite's geometry read at a pose the fabric holds back: its axial
rotation follows the arm's only once the arm has turned a backlash beyond it. That is
written here as a loop over the frames, apart from the workflow's play operators.
"""

from dataclasses import replace

import numpy as np
import pytest

from exohil.emulators.discrepancy import run
from exohil.emulators.discrepancy.hidden import (
    random_geometry,
    random_trajectory,
    suit_recording,
)
from exohil.emulators.discrepancy.model import (
    PLAY_FRACTIONS,
    Inputs,
    angle_play_columns,
    angle_thresholds,
    fit,
    legendre_products,
    make_inputs,
    scale_angles,
    static_slopes,
)
from exohil.emulators.discrepancy.profile import (
    calibrated_suit,
    load_calibrated_profile,
    simulate_calibrated,
    write_calibrated_profile,
)
from exohil.emulators.discrepancy.rules import candidate_evidence, pooled_noise
from exohil.emulators.discrepancy.workflow import _own_static_part, _pose_loop_over_richer_map
from exohil.emulators.effects import Signal

#: The sleeve's backlash in axial rotation, degrees.
SLIP_DEG = 6.0
NOISE_MM = 0.15


def _held_back(angle: np.ndarray, backlash: float) -> np.ndarray:
    """Where a sleeve that slips sits: it stays put until the limb has turned ``backlash``
    beyond it, then is dragged along at that distance."""
    out = np.empty_like(angle)
    sleeve = angle[0]
    for i, a in enumerate(angle):
        if a > sleeve + backlash:
            sleeve = a - backlash
        elif a < sleeve - backlash:
            sleeve = a + backlash
        out[i] = sleeve
    return out


def _knee_inputs(angle: np.ndarray, gain: float) -> Inputs:
    """Inputs of a one-angle joint whose static map is ``gain`` sensor units per degree."""
    lo, hi = np.array([angle.min()]), np.array([angle.max()])
    u = scale_angles(angle[:, None], lo, hi)
    # ŝ = c₀ + c₁·P₁(u), u = (α − mid) / half range: slope c₁ / half range per degree
    coef = np.array([[3.0], [gain * (hi[0] - lo[0]) / 2.0]])
    assert legendre_products(u, 1)[0].shape[1] == 2
    return Inputs(u=u, input_kind="angles", angle_lo=lo, angle_hi=hi, angles=angle[:, None],
                  angle_names=("knee",), static=np.empty(0), static_coef=coef,
                  static_degree=1, thresholds=np.empty(0), t_norm=np.zeros(angle.size),
                  t_span=(0.0, 1.0))


def test_each_play_on_an_angle_is_the_backlash_it_holds_through_the_maps_slope():
    """Up to 90°, back to 40°, up again: each column is the map's slope times how far the
    angle has run ahead of a play of that half-width (0 wherever the play has caught up
    after a reversal, ±r once it has), as the sleeve loop above computes it."""
    angle = np.concatenate([np.linspace(0.0, 90.0, 400), np.linspace(90.0, 40.0, 300),
                            np.linspace(40.0, 90.0, 300)])
    inputs = _knee_inputs(angle, gain=0.2)
    np.testing.assert_allclose(static_slopes(inputs)[:, 0, 0], 0.2, rtol=1e-9)
    widths = angle_thresholds(inputs)[0]
    np.testing.assert_allclose(widths, 90.0 * np.asarray(PLAY_FRACTIONS))
    columns = angle_play_columns(inputs)[:, 0, :]
    assert columns.shape == (angle.size, len(PLAY_FRACTIONS))
    for k, r in enumerate(widths):
        np.testing.assert_allclose(columns[:, k], 0.2 * (angle - _held_back(angle, r)),
                                   atol=1e-9)
    # the widest play's column after the first rise and after the fall
    assert columns[399, -1] == pytest.approx(0.2 * widths[-1])
    assert columns[699, -1] == pytest.approx(-0.2 * widths[-1])


def test_the_slopes_formed_in_processes_are_those_formed_in_turn():
    """ŝ's slopes of a two-angle map (a product term, so each slope depends on both angles)
    are the same values whether the shifted maps are formed in one process or in two."""
    rng = np.random.default_rng(5)
    angles = np.column_stack([rng.uniform(0.0, 120.0, 2000), rng.uniform(-40.0, 80.0, 2000)])
    lo, hi = angles.min(axis=0), angles.max(axis=0)
    u = scale_angles(angles, lo, hi)
    basis, _ = legendre_products(u, 2)
    coef = rng.normal(size=(basis.shape[1], 3))

    def inputs() -> Inputs:
        return Inputs(u=u, input_kind="angles", angle_lo=lo, angle_hi=hi, angles=angles,
                      angle_names=("a", "b"), static=basis @ coef, static_coef=coef,
                      static_degree=2, thresholds=np.empty(0), t_norm=np.zeros(len(u)),
                      t_span=(0.0, 1.0))

    in_turn = static_slopes(inputs(), workers=1)
    assert in_turn.shape == (2000, 3, 2) and np.ptp(in_turn[:, :, 0], axis=0).min() > 0
    assert np.array_equal(static_slopes(inputs(), workers=2), in_turn)


@pytest.fixture(scope="module")
def sleeve_slip():
    """A suit of the suite (seed 4) turned within ±35° about the humerus, whose tendons read
    the axial rotation through a sleeve with a 6° backlash; and the same suit read at the
    arm's own pose (its clean twin), each with 0.15 mm of noise."""
    trajectory = random_trajectory(4, 60.0, axial_deg=35.0)
    geometry, gains, offsets = random_geometry(4)
    t = trajectory.frame_times(250.0)
    ang = trajectory.sample(t)
    noise = np.random.default_rng(4).normal(0.0, NOISE_MM, (t.size, len(geometry.tendons)))
    runs = {}
    for name, psi in (("slip", _held_back(ang[:, 2], SLIP_DEG)), ("twin", ang[:, 2])):
        lengths = geometry.path_lengths(*np.deg2rad([ang[:, 0], ang[:, 1], psi]))
        y = lengths * gains + offsets + noise
        rec = suit_recording(trajectory, geometry, Signal.from_values(t, y), {"case": name})
        runs[name] = run(rec, name)
    return runs


def test_a_sleeve_that_slips_in_axial_rotation_is_named_a_loop_in_the_pose(sleeve_slip,
                                                                              tmp_path):
    """The slip loops only where ψ reverses, and with the arm raised ŝ need not reverse
    with it: the plays on ŝ follow it less well than plays on the angles do. Hysteresis is
    named first, as a loop in the pose, and takes most of what the slip adds to the clean
    twin's gap; the profile written simulates what the model fitted."""
    slip, twin = sleeve_slip["slip"], sleeve_slip["twin"]
    s = slip.summary
    assert twin.summary["effects"] == [], twin.summary["effects"]
    assert s["effects"][:1] == ["hysteresis"], s["effects"]
    params = s["steps"][0]["params"]
    assert params["on"] == "angles", params
    assert params["angles"] == ["elv_angle", "shoulder_elv", "shoulder_rot"]
    assert np.shape(params["weights"]) == (len(s["sensors"]), 3, len(PLAY_FRACTIONS))
    added = s["gap_before"] ** 2 - twin.summary["gap_before"] ** 2  # what the slip adds
    assert added > 2.0 * NOISE_MM**2, (s, twin.summary)
    # the loop in the pose takes at least three quarters of it
    assert s["gap_after"] ** 2 - twin.summary["gap_after"] ** 2 < 0.25 * added, (s, twin.summary)
    write_calibrated_profile(tmp_path / "p.toml", calibrated_suit(slip, "sleeve"))
    loaded = load_calibrated_profile(tmp_path / "p.toml")
    assert loaded.spec.hysteresis_angles
    np.testing.assert_allclose(simulate_calibrated(loaded, slip.trial.t, slip.trial.angles),
                               slip.after.prediction, atol=1e-6)


def test_a_loop_in_the_pose_must_also_beat_a_map_one_degree_richer(sleeve_slip):
    """Plays on the angles follow the direction of motion in each, so they can take up what
    a map too stiff for the suit misses while the arm moves; a loop in the pose is kept
    only where it also clears rules 1 and 2 over a map one degree richer, else the plays
    on ŝ stand in for it. The slip's loop does (and says so in its evidence); on the clean
    twin, over its own calibrated map, the plays on ŝ stand in."""
    slip, twin = sleeve_slip["slip"], sleeve_slip["twin"]
    richer = slip.summary["steps"][0]["evidence"]["over_richer_map"]
    assert richer["significant"] and richer["degree"] == slip.before.spec.degree + 1, richer
    for outcome, kept in ((slip, True), (twin, False)):
        trial, spec, floor = outcome.trial, outcome.before.spec, pooled_noise(outcome.trial)
        inputs = make_inputs(trial, spec)
        base = fit(trial, inputs, spec)
        loop = fit(trial, inputs, replace(spec, hysteresis=True, hysteresis_angles=True))
        cand, evidence = _pose_loop_over_richer_map(trial, inputs, spec, base, loop,
                                                    candidate_evidence(trial, base, loop, floor),
                                                    floor)
        assert cand.spec.hysteresis_angles is kept
        assert ("over_richer_map" in evidence) is kept
        if not kept:
            assert not evidence["loop_in_pose_over_richer_map"]["significant"], evidence
            assert evidence["config"] == cand.spec.config()  # the plays on ŝ's own evidence


def test_a_named_loop_is_refitted_in_its_other_configuration_and_the_lower_kept(sleeve_slip):
    """Where the step's comparison had kept the plays on ŝ, naming the loop refits the plays
    on the angles too (each on its own static part, beside the level powers) and keeps the
    lower: on the sleeve slip, the loop in the pose."""
    slip = sleeve_slip["slip"]
    trial, inputs = slip.trial, slip.inputs
    on_reading = fit(trial, inputs, replace(slip.after.spec, hysteresis_angles=False))
    assert on_reading.gap > slip.after.gap
    kept, _, _ = _own_static_part(trial, inputs, on_reading, loop_named=True)
    assert kept.spec.hysteresis_angles
    assert kept.gap < on_reading.gap
    # the refits are jobs that two processes share, from either configuration (from the
    # loop in the pose, the plays' powers wait for their own map): the same fits
    for start in (on_reading, slip.after):
        here = _own_static_part(trial, inputs, start, loop_named=True)
        apart = _own_static_part(trial, inputs, start, loop_named=True, workers=2)
        assert apart[0].spec == here[0].spec and apart[2] == here[2]
        np.testing.assert_array_equal(apart[0].residual, here[0].residual)
        np.testing.assert_array_equal(apart[1].static, here[1].static)
    # not named just now: refitted on its own static part only, as it stands
    alone, _, _ = _own_static_part(trial, inputs, on_reading, loop_named=False)
    assert not alone.spec.hysteresis_angles
