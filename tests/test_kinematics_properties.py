"""Property-based tests of the shoulder angle conversions (hypothesis).

Run with HYPOTHESIS_PROFILE=ci for ≥ 1000 examples per property. Warnings are errors here:
no conversion may leak a RuntimeWarning, even at singularities.
"""

import numpy as np
import pytest
import transforms3d.euler as t3e
from hypothesis import given
from hypothesis import strategies as st

from exohil.kinematics import (
    isb_to_quat,
    ms_to_isb,
    ms_to_quat,
    quat_to_isb,
    quat_to_ms,
    quat_to_zyx,
    rotation_angle_between,
)
from exohil.kinematics.rotations import (
    X,
    Y,
    Z,
    elementary_matrix,
    matrix_to_quat,
    normalize_quat,
    quat_to_matrix,
    wrap_angle,
)

pytestmark = pytest.mark.filterwarnings("error")

PI = np.pi
theta_range = st.floats(np.deg2rad(-90.0), np.deg2rad(130.0))
psi_range = st.floats(np.deg2rad(-90.0), np.deg2rad(20.0))
# "away from 0/180°": at least 1e-3 rad (0.057°) from the singular elevations.
phi_regular = st.floats(1e-3, PI - 1e-3)
any_angle = st.floats(-PI, PI)
hints = st.floats(-PI, PI)


@st.composite
def unit_quaternions(draw):
    """Uniform-ish random unit quaternions plus, often, exactly singular ones (β = 0 or −π)."""
    kind = draw(st.sampled_from(["random", "random", "hanging", "overhead", "axis"]))
    if kind == "random":
        v = np.array(draw(st.lists(st.floats(-1, 1), min_size=4, max_size=4)))
        if np.linalg.norm(v) < 1e-3:
            v = np.array([0.0, 0.0, 0.0, 1.0])
        return v / np.linalg.norm(v)
    if kind == "axis":  # rotations about a single principal axis, incl. half turns
        q = np.zeros(4)
        angle = draw(any_angle)
        q[draw(st.sampled_from([0, 1, 2]))] = np.sin(angle / 2)
        q[3] = np.cos(angle / 2)
        return q
    beta = 0.0 if kind == "hanging" else -PI
    return isb_to_quat(draw(any_angle), beta, draw(any_angle))


def angle_diff(a, b):
    return np.abs(wrap_angle(np.asarray(a) - np.asarray(b)))


@given(theta_range, phi_regular, psi_range)
def test_ms_quat_ms_round_trip(theta, phi, psi):
    back = quat_to_ms(ms_to_quat(theta, phi, psi))
    assert np.all(angle_diff(back, [theta, phi, psi]) < 1e-9)


@given(theta_range, phi_regular, psi_range)
def test_ms_quat_ms_round_trip_paper_convention(theta, phi, psi):
    q = ms_to_quat(theta, phi, psi, convention="paper")
    back = quat_to_ms(q, convention="paper")
    assert np.all(angle_diff(back, [theta, phi, psi]) < 1e-9)


@given(unit_quaternions(), hints)
def test_quat_isb_quat_same_rotation_everywhere(q, hint):
    isb = quat_to_isb(q, plane_hint=hint)
    assert np.all(np.isfinite(isb))
    assert -PI <= isb[1] <= 0.0
    assert rotation_angle_between(isb_to_quat(isb), q) < 1e-6


@given(any_angle, st.floats(-PI, 0.0), any_angle)
def test_isb_to_quat_matches_transforms3d(alpha, beta, gamma):
    ours = isb_to_quat(alpha, beta, gamma)
    w, x, y, z = t3e.euler2quat(alpha, beta, gamma, axes="ryxy")  # intrinsic Y-X'-Y''
    theirs = np.array([x, y, z, w])
    assert min(np.max(np.abs(ours - theirs)), np.max(np.abs(ours + theirs))) < 1e-12


@given(theta_range, theta_range, psi_range)
def test_orientation_at_zero_elevation_does_not_depend_on_plane(theta1, theta2, psi):
    q1 = ms_to_quat(theta1, 0.0, psi)
    q2 = ms_to_quat(theta2, 0.0, psi)
    assert rotation_angle_between(q1, q2) < 1e-12
    q1m = ms_to_quat(theta1, 0.0, psi, axes="mobl")
    q2m = ms_to_quat(theta2, 0.0, psi, axes="mobl")
    assert rotation_angle_between(q1m, q2m) < 1e-12


@given(theta_range, st.floats(0.0, PI), psi_range)
def test_paper_convention_differs_by_an_axial_rotation_of_theta(theta, phi, psi):
    coupled = ms_to_quat(theta, phi, psi)
    paper = ms_to_quat(theta, phi, psi, convention="paper")
    assert abs(rotation_angle_between(coupled, paper) - abs(wrap_angle(theta))) < 1e-9
    # ... about the humerus long axis: the elbow stays where it was.
    elbow = np.array([0.0, -1.0, 0.0])
    assert np.allclose(quat_to_matrix(coupled) @ elbow, quat_to_matrix(paper) @ elbow, atol=1e-12)


@given(theta_range, st.floats(0.0, PI), psi_range)
def test_mobl_axes_stay_within_documented_distance_of_ideal_axes(theta, phi, psi):
    ideal = ms_to_quat(theta, phi, psi)
    mobl = ms_to_quat(theta, phi, psi, axes="mobl")
    assert rotation_angle_between(ideal, mobl) <= np.deg2rad(8.5)  # docs/conventions.md


@given(unit_quaternions(), hints)
def test_quat_to_zyx_reconstructs_rotation(q, hint):
    yaw, pitch, roll = quat_to_zyx(q, yaw_hint=hint)
    assert -PI / 2 <= pitch <= PI / 2
    m = elementary_matrix(Z, yaw) @ elementary_matrix(Y, pitch) @ elementary_matrix(X, roll)
    assert rotation_angle_between(matrix_to_quat(m), q) < 1e-6


@given(any_angle, st.floats(-PI / 2 + 1e-3, PI / 2 - 1e-3), any_angle)
def test_quat_to_zyx_matches_transforms3d_away_from_gimbal_lock(yaw, pitch, roll):
    w, x, y, z = t3e.euler2quat(yaw, pitch, roll, axes="rzyx")
    ours = quat_to_zyx([x, y, z, w])
    assert np.all(angle_diff(ours, [yaw, pitch, roll]) < 1e-9)


@given(unit_quaternions())
def test_matrix_quaternion_round_trip(q):
    back = matrix_to_quat(quat_to_matrix(q))
    assert rotation_angle_between(back, q) < 1e-9
    assert back[3] >= 0.0


half_turn_axes = st.lists(st.sampled_from([-1.0, -0.5, -0.0, 0.0, 0.25, 1.0]), min_size=3,
                          max_size=3).filter(lambda v: any(v))


@given(half_turn_axes)
def test_a_half_turn_has_one_quaternion_whichever_sign_comes_in(axis):
    """At w = 0, q and −q are the same rotation and both have w ≥ 0: the output took the
    input's sign (and kept a −0), so one rotation had two outputs."""
    q = np.array([*axis, -0.0])
    out, out_negated = normalize_quat(q), normalize_quat(-q)
    np.testing.assert_array_equal(out, out_negated)
    assert out[np.flatnonzero(out[:3])[0]] > 0.0
    assert not ((out == 0.0) & np.signbit(out)).any()  # no −0 either
    np.testing.assert_array_equal(matrix_to_quat(quat_to_matrix(q)).round(12), out.round(12))


def test_vectorised_matches_scalar():
    rng = np.random.default_rng(7)
    ms = np.stack([rng.uniform(-1.5, 2.2, 50), rng.uniform(0.01, 3.1, 50),
                   rng.uniform(-1.5, 0.3, 50)], axis=-1)
    batch = quat_to_ms(ms_to_quat(ms))
    for row, back in zip(ms, batch, strict=True):
        assert np.allclose(quat_to_ms(ms_to_quat(*row)), back, atol=1e-12)
    assert ms_to_isb(ms.reshape(5, 10, 3)).shape == (5, 10, 3)


def test_singular_orientations_take_the_plane_from_the_hint():
    q = ms_to_quat(0.7, 0.0, 0.2)  # arm hanging: plane of elevation undefined
    for hint in (-1.0, 0.0, 0.5, 2.0):
        theta, phi, psi = quat_to_ms(q, plane_hint=hint)
        assert theta == pytest.approx(hint)
        assert phi == pytest.approx(0.0, abs=1e-12)
        assert rotation_angle_between(ms_to_quat(theta, phi, psi), q) < 1e-12
    overhead = isb_to_quat(0.3, -PI, 0.1)
    alpha, beta, gamma = quat_to_isb(overhead, plane_hint=1.2)
    assert alpha == pytest.approx(1.2) and beta == pytest.approx(-PI)
    assert rotation_angle_between(isb_to_quat(alpha, beta, gamma), overhead) < 1e-12


def test_hint_keeps_a_stream_continuous_through_the_hanging_pose():
    # Lower the arm to 0 and raise it again in the same plane: θ must not jump.
    phi = np.concatenate([np.linspace(0.5, 0.0, 50), np.linspace(0.0, 0.5, 50)])
    q = ms_to_quat(0.8, phi, 0.0)
    hint = 0.8
    thetas = []
    for qi in q:
        theta = quat_to_ms(qi, plane_hint=hint)[0]
        thetas.append(theta)
        hint = theta
    assert np.max(np.abs(np.diff(thetas))) < 1e-6


def test_bad_quaternions_raise_value_error():
    with pytest.raises(ValueError):
        quat_to_isb([0.0, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError):
        quat_to_isb([np.nan, 0.0, 0.0, 1.0])
    with pytest.raises(ValueError):
        quat_to_isb([1.0, 0.0, 0.0])


def test_quat_to_zyx_refuses_a_yaw_hint_it_cannot_use():
    """At gimbal lock a NaN or infinite yaw_hint came back as NaN yaw and roll (with a
    RuntimeWarning), and a hint of the wrong shape raised NumPy's broadcast error, where
    quat_to_isb names its plane_hint."""
    lock = np.array([[0.0, np.sqrt(0.5), 0.0, np.sqrt(0.5)], [0.0, 0.0, 0.0, 1.0]])
    for bad in (np.nan, np.inf, [0.0, np.nan]):
        with pytest.raises(ValueError, match="yaw_hint must be finite"):
            quat_to_zyx(lock, yaw_hint=bad)
    with pytest.raises(ValueError, match="yaw_hint of shape .* does not fit"):
        quat_to_zyx(lock, yaw_hint=[0.0, 1.0, 2.0])
    yaw, pitch, roll = quat_to_zyx(lock[0], yaw_hint=0.5)
    assert (yaw, pitch) == pytest.approx((0.5, PI / 2))


def test_hints_are_wrapped_to_the_range_of_the_angle_they_stand_for():
    """A hint of 300° came back unwrapped as α = 300° (documented [−180°, 180°)) or yaw 300°;
    for NAO the pitch 300° lay outside the limits, so the command went to the pitch limit
    −119.5° where the same hint written −60° commands pitch −60°."""
    from exohil.kinematics import humerus_to_nao

    hanging = ms_to_quat(0.7, 0.0, 0.2)
    alpha = quat_to_isb(hanging, plane_hint=np.deg2rad(300.0))[0]
    assert np.rad2deg(alpha) == pytest.approx(-60.0)
    lock = [0.0, np.sqrt(0.5), 0.0, np.sqrt(0.5)]
    assert np.rad2deg(quat_to_zyx(lock, yaw_hint=np.deg2rad(-300.0))[0]) == pytest.approx(60.0)
    abducted = ms_to_quat(0.0, PI / 2, 0.0)  # NAO roll −90°: the pitch comes from the hint
    for wrapped in (300.0, -420.0):
        far = humerus_to_nao(abducted, hint=np.deg2rad([wrapped, 0.0, 0.0]))
        near = humerus_to_nao(abducted, hint=np.deg2rad([-60.0, 0.0, 0.0]))
        np.testing.assert_allclose(far.angles, near.angles, atol=1e-12)
        np.testing.assert_allclose(far.unclamped, near.unclamped, atol=1e-12)
        assert np.rad2deg(far.angles[0]) == pytest.approx(-60.0)


def test_returned_angles_keep_to_their_documented_half_open_ranges():
    """On a 15° grid, α (and θ) came back as +180° for 1.9% of the poses, ψ as +180° and NAO's
    exact pitch as −180°: wrap_angle gave +π for an angle a hair below −π, and atan2 gives
    both ±π. Documented: α, γ, θ, ψ in [−π, π), NAO unclamped pitch in (−π, π]."""
    from exohil.kinematics import humerus_to_nao

    assert wrap_angle(-PI - 1e-17) == -PI and wrap_angle(PI) == -PI
    grid = np.deg2rad(np.arange(-360.0, 361.0, 15.0))
    poses = np.stack(np.meshgrid(grid, grid, grid, indexing="ij"), axis=-1).reshape(-1, 3)
    q = isb_to_quat(poses)
    for angles in (quat_to_isb(q), quat_to_ms(q)):
        assert np.all((angles[:, [0, 2]] >= -PI) & (angles[:, [0, 2]] < PI))
    pitch = humerus_to_nao(q).unclamped[:, 0]
    assert np.all((pitch > -PI) & (pitch <= PI))
