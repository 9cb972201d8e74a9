"""NAO arm mapping: known poses, limits and clamp reporting, singularity handling."""

import json

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import given
from hypothesis import strategies as st

from exohil.harness.cli import main
from exohil.kinematics import NAO_LIMITS, humerus_to_nao, ms_to_quat, rotation_angle_between
from exohil.kinematics.robot import HUMERUS_FROM_NAO_ARM, NAO_FROM_ISB
from exohil.kinematics.rotations import X, Y, Z, elementary_matrix, matrix_to_quat, quat_to_matrix

pytestmark = pytest.mark.filterwarnings("error")
deg = np.deg2rad


def nao(theta_deg, phi_deg, psi_deg=0.0, side="right"):
    return humerus_to_nao(ms_to_quat(deg(theta_deg), deg(phi_deg), deg(psi_deg)), side=side)


def test_arm_hanging_is_pitch_90_roll_0():
    arm = nao(0, 0)
    assert np.allclose(np.rad2deg(arm.angles[:2]), [90.0, 0.0], atol=1e-9)
    assert not arm.any_clamped


def test_forward_flexion_90_is_pitch_0_roll_0():
    arm = nao(90, 90)
    assert np.allclose(np.rad2deg(arm.angles[:2]), [0.0, 0.0], atol=1e-9)
    assert not arm.any_clamped


def test_right_abduction_90_is_roll_minus_90_clamped_and_reported():
    arm = nao(0, 90)
    assert np.rad2deg(arm.unclamped[1]) == pytest.approx(-90.0, abs=1e-9)
    assert np.rad2deg(arm.angles[1]) == pytest.approx(-76.0)
    assert arm.clamped.tolist() == [False, True, False]


def test_left_arm_mirrors_roll_and_yaw():
    right, left = nao(30, 60, -20), nao(30, 60, -20, side="left")
    assert np.allclose(left.unclamped, right.unclamped * [1, -1, -1])
    left_abd = nao(0, 90, side="left")
    assert np.rad2deg(left_abd.angles[1]) == pytest.approx(76.0)
    assert left_abd.clamped[1]


@given(st.floats(-np.pi, np.pi), st.floats(-1.5, 1.5), st.floats(-np.pi, np.pi))
def test_nao_angles_reconstruct_the_humerus_orientation(pitch, roll, yaw):
    # Build a humerus orientation from NAO joints, map back, compare rotations.
    arm_in_nao = (elementary_matrix(Y, pitch) @ elementary_matrix(Z, roll)
                  @ elementary_matrix(X, yaw))
    humerus = NAO_FROM_ISB.T @ arm_in_nao @ HUMERUS_FROM_NAO_ARM.T
    got = humerus_to_nao(matrix_to_quat(humerus))
    p, r, y = got.unclamped
    rebuilt = elementary_matrix(Y, p) @ elementary_matrix(Z, r) @ elementary_matrix(X, y)
    assert rotation_angle_between(matrix_to_quat(rebuilt), matrix_to_quat(arm_in_nao)) < 1e-6
    low, high = NAO_LIMITS["right"][:, 0], NAO_LIMITS["right"][:, 1]
    assert np.all((got.angles >= low) & (got.angles <= high))
    assert np.array_equal(got.clamped, (got.unclamped < low) | (got.unclamped > high))


def test_roll_singularity_uses_the_pitch_hint_and_never_nans():
    q = ms_to_quat(0.0, deg(90), deg(10))  # right abduction 90°: roll = -90°
    for hint_pitch in (-0.5, 0.0, 0.7):
        arm = humerus_to_nao(q, hint=np.array([hint_pitch, 0.0, 0.0]))
        assert arm.unclamped[0] == pytest.approx(hint_pitch)
        assert np.all(np.isfinite(arm.angles))


def test_cli_convert_ms_to_nao_prints_json_with_clamp_flags():
    result = CliRunner().invoke(main, ["convert", "--from", "ms", "--to", "nao", "0", "90", "0"])
    assert result.exit_code == 0, result.output
    out = json.loads(result.output)
    assert out["values"]["RShoulderRoll"] == pytest.approx(-76.0)
    assert out["clamped"]["RShoulderRoll"] is True and out["any_clamped"] is True
    flex = json.loads(CliRunner().invoke(main, ["convert", "--from", "ms", "--to", "nao",
                                                "90", "90", "0"]).output)
    assert flex["any_clamped"] is False
    assert flex["values"]["RShoulderPitch"] == pytest.approx(0.0, abs=1e-9)


def test_cli_convert_accepts_negative_values_and_rejects_bad_counts():
    ok = CliRunner().invoke(main, ["convert", "--from", "ms", "--to", "isb", "-90", "45", "10"])
    assert ok.exit_code == 0
    assert json.loads(ok.output)["values"]["axial_rotation"] == pytest.approx(100.0)
    bad = CliRunner().invoke(main, ["convert", "--from", "ms", "--to", "isb", "1", "2"])
    assert bad.exit_code != 0 and "takes 3" in bad.output


def test_straight_into_the_unreachable_wedge_takes_the_pitch_limit_nearer_the_hint():
    # Abducted 90° and 5° behind the frontal plane: the exact pitch is 180°, outside ±119.5°,
    # and both pitch limits are equally near; the hint picks one.
    q = ms_to_quat(deg(-5.0), deg(90.0), 0.0)
    for hint_pitch, expected in ((2.0, 119.5), (-2.0, -119.5)):
        arm = humerus_to_nao(q, hint=np.array([hint_pitch, 0.0, 0.0]))
        assert np.rad2deg(arm.angles[:2]) == pytest.approx([expected, -76.0])
        assert arm.clamped.tolist() == [True, True, False]


def test_reachable_direction_is_kept_even_when_elbow_yaw_clamps():
    # (1.2°, 130.1°, 0°): the old branch choice gave pitch 91.5°, roll −76° (28° off).
    arm = nao(1.2, 130.1)
    assert np.rad2deg(arm.angles[:2]) == pytest.approx(np.rad2deg(arm.unclamped[:2]))
    assert np.rad2deg(arm.angles) == pytest.approx([-88.58, -49.89, -119.5], abs=0.01)
    assert arm.clamped.tolist() == [False, False, True]


def _on_hint(theta_deg, phi_deg, hint_deg, hysteresis_deg, side="right"):
    q = ms_to_quat(deg(theta_deg), deg(phi_deg), 0.0)
    return np.rad2deg(humerus_to_nao(q, side=side, hint=deg(np.asarray(hint_deg, dtype=float)),
                                     hysteresis=deg(hysteresis_deg)).angles)


def test_hysteresis_keeps_the_hints_pitch_limit_behind_the_shoulder():
    # 60° behind the side plane, the arm just below horizontal: the nearest pitch limit is
    # −119.5° (+119.5° just above), a choice that flipped at any noise. From +119.5° the
    # stream stays there until −119.5° is nearer by more than the hysteresis.
    assert _on_hint(-60.0, 90.05, [0.0, 0.0, 0.0], 0.0)[0] == pytest.approx(-119.5)
    assert _on_hint(-60.0, 89.95, [0.0, 0.0, 0.0], 0.0)[0] == pytest.approx(119.5)
    held = _on_hint(-60.0, 90.05, [119.5, -49.5, -11.4], 10.0)
    assert held[0] == pytest.approx(119.5)
    assert _on_hint(-60.0, 100.0, [119.5, -49.5, -11.4], 10.0)[0] == pytest.approx(-119.5)
    assert _on_hint(-60.0, 90.05, [119.5, -49.5, -11.4], 0.0)[0] == pytest.approx(-119.5)


@pytest.mark.parametrize("side, sign", [("right", 1.0), ("left", -1.0)])
def test_hysteresis_keeps_the_hints_elbow_yaw_limit_overhead(side, sign):
    # φ = 150°, ψ = 0: the wanted elbow yaw is near 180° and turns at twice θ's rate, so the
    # clamped yaw flipped from +119.5° to −119.5° as θ crossed 0.
    assert _on_hint(-1.0, 150.0, [0, 0, 0], 0.0, side)[2] == pytest.approx(sign * 119.5)
    assert _on_hint(1.0, 150.0, [0, 0, 0], 0.0, side)[2] == pytest.approx(-sign * 119.5)
    hint = [-90.0, sign * -30.0, sign * 119.5]
    assert _on_hint(2.0, 150.0, hint, 10.0, side)[2] == pytest.approx(sign * 119.5)
    assert _on_hint(4.0, 150.0, hint, 10.0, side)[2] == pytest.approx(-sign * 119.5)


def test_hysteresis_costs_at_most_itself_and_needs_a_hint():
    rng = np.random.default_rng(5)
    q = rng.normal(size=(4000, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    hints = np.column_stack([rng.uniform(-2.1, 2.1, 4000), rng.uniform(-1.3, 1.3, 4000),
                             rng.uniform(-2.1, 2.1, 4000)])
    sticky = deg(10.0)
    nearest = humerus_to_nao(q, hint=hints)
    held = humerus_to_nao(q, hint=hints, hysteresis=sticky)
    assert np.any(held.angles != nearest.angles)  # the sample does reach the choices

    def frames(angles):
        return (elementary_matrix(Y, angles[:, 0]) @ elementary_matrix(Z, angles[:, 1])
                @ elementary_matrix(X, angles[:, 2]))

    wanted = NAO_FROM_ISB @ quat_to_matrix(q) @ HUMERUS_FROM_NAO_ARM

    def axis_error(angles):
        a, b = frames(angles)[:, :, 0], wanted[:, :, 0]
        return np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.sum(a * b, axis=1))

    assert np.all(axis_error(held.angles) <= axis_error(nearest.angles) + sticky + 1e-9)
    same_axis = np.all(held.angles[:, :2] == nearest.angles[:, :2], axis=1)
    yaw_gap = np.abs(np.angle(np.exp(1j * (held.angles[:, 2] - nearest.angles[:, 2]))))
    off_best = np.abs(np.angle(np.exp(1j * (held.angles[:, 2] - held.unclamped[:, 2]))))
    nearest_off = np.abs(np.angle(np.exp(1j * (nearest.angles[:, 2] - held.unclamped[:, 2]))))
    reached = same_axis & ~held.clamped[:, 0] & ~held.clamped[:, 1]
    assert np.all(off_best[reached] <= nearest_off[reached] + sticky + 1e-9)
    assert np.all(yaw_gap[~held.clamped[:, 2] & reached] == 0.0)
    assert np.array_equal(humerus_to_nao(q, hysteresis=sticky).angles, humerus_to_nao(q).angles)
    for bad in (-1e-3, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="hysteresis"):
            humerus_to_nao(q[0], hint=hints[0], hysteresis=bad)
