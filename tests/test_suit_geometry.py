"""Tendon wrapping geometry: lengths, smoothness, designed sensitivities, symmetry."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from exohil.emulators.suit_geometry import SuitGeometry, Tendon, wrapped_length
from exohil.emulators.suit_profile import load_default_profile

D = np.deg2rad


@pytest.fixture(scope="module")
def geometry() -> SuitGeometry:
    return load_default_profile().geometry


def lengths(geometry: SuitGeometry, theta_deg, phi_deg, psi_deg=0.0) -> np.ndarray:
    return geometry.path_lengths(D(theta_deg), D(phi_deg), D(psi_deg))


def test_wrap_matches_closed_form_for_opposite_points():
    radius, d = 50.0, 80.0
    got = wrapped_length(np.array([d, 0, 0]), np.array([-d, 0, 0]), np.zeros(3), radius)
    expected = 2 * np.sqrt(d**2 - radius**2) + radius * (np.pi - 2 * np.arccos(radius / d))
    assert got == pytest.approx(expected, rel=1e-12)


def test_wrap_is_straight_when_the_segment_clears_the_sphere():
    p, q = np.array([100.0, 60.0, 0.0]), np.array([-100.0, 60.0, 0.0])
    assert wrapped_length(p, q, np.zeros(3), 50.0) == pytest.approx(200.0)


point = st.tuples(*[st.floats(-300, 300, allow_nan=False)] * 3).map(np.array).filter(
    lambda v: np.linalg.norm(v) > 56.0)


@given(point, point)
def test_wrap_is_never_shorter_than_straight_and_is_symmetric(p, q):
    straight = np.linalg.norm(p - q)
    forward = wrapped_length(p, q, np.zeros(3), 55.0)
    assert forward >= straight - 1e-9
    assert forward == pytest.approx(wrapped_length(q, p, np.zeros(3), 55.0), rel=1e-12, abs=1e-9)


def test_lengths_are_positive_and_finite_over_the_workspace(geometry):
    theta, phi = np.meshgrid(np.arange(-90, 91, 5.0), np.arange(0, 181, 5.0))
    for psi in (-60.0, 0.0, 40.0):
        out = lengths(geometry, theta.ravel(), phi.ravel(), psi)
        assert np.isfinite(out).all() and (out > 0).all()


def test_lengths_change_smoothly(geometry):
    # fine sweeps through the workspace: slopes bounded and continuous. A kink (e.g. at the onset
    # of wrapping) would make one slope change as large as the slope itself (~0.5 mm/deg).
    step = 0.05
    for theta in (-90.0, -40.0, 0.0, 45.0, 90.0):
        phi = np.arange(0.0, 120.0, step)
        slope = np.diff(lengths(geometry, theta, phi), axis=0) / step  # mm/deg
        assert np.abs(slope).max() < 3.0
        assert np.abs(np.diff(slope, axis=0)).max() < 0.05
    for phi in (20.0, 60.0, 90.0):
        theta = np.arange(-90.0, 90.0, step)
        slope = np.diff(lengths(geometry, theta, phi), axis=0) / step
        assert np.abs(slope).max() < 3.0
        assert np.abs(np.diff(slope, axis=0)).max() < 0.05


def sensitivity(geometry, theta, phi, wrt):
    h = 0.5
    if wrt == "phi":
        return (lengths(geometry, theta, phi + h) - lengths(geometry, theta, phi - h))[0] / (2 * h)
    return (lengths(geometry, theta + h, phi) - lengths(geometry, theta - h, phi))[0] / (2 * h)


@pytest.mark.parametrize("phi", [15.0, 30.0, 45.0, 60.0, 75.0])
def test_front_and_rear_respond_to_flexion_and_extension_oppositely(geometry, phi):
    f, sf, sr, r = sensitivity(geometry, 90.0, phi, "phi")  # flexion
    assert f < -0.4 and r > 0.1
    f, sf, sr, r = sensitivity(geometry, -90.0, phi, "phi")  # extension
    assert f > 0.1 and r < -0.4


@pytest.mark.parametrize("phi", [15.0, 30.0, 45.0, 60.0, 75.0, 90.0])
def test_side_tendons_shorten_in_abduction_with_opposite_plane_sensitivity(geometry, phi):
    f, sf, sr, r = sensitivity(geometry, 0.0, phi, "phi")
    assert sf < -0.5 and sr < -0.5
    assert abs(f) < abs(sf) and abs(r) < abs(sr)  # abduction mainly seen by SF/SR
    if phi >= 20.0:
        f, sf, sr, r = sensitivity(geometry, 0.0, phi, "theta")
        assert sf < -0.1 and sr > 0.1


def test_default_suit_is_mirror_symmetric_front_to_back(geometry):
    # mirroring X (anterior) maps plane θ → −θ and swaps F↔R, SF↔SR (up to constant offsets)
    theta, phi = np.meshgrid(np.arange(-90, 91, 10.0), np.arange(0, 121, 10.0))
    a = lengths(geometry, theta.ravel(), phi.ravel()) - lengths(geometry, 0, 0)
    b = lengths(geometry, -theta.ravel(), phi.ravel()) - lengths(geometry, 0, 0)
    np.testing.assert_allclose(a[:, [0, 1, 2, 3]], b[:, [3, 2, 1, 0]], atol=1e-9)


def test_arm_hanging_pose_does_not_depend_on_the_plane_of_elevation(geometry):
    out = lengths(geometry, np.linspace(-90, 90, 7), 0.0)
    np.testing.assert_allclose(out, out[:1].repeat(7, axis=0), atol=1e-9)


def test_vectorised_equals_scalar(geometry):
    rng = np.random.default_rng(3)
    angles = rng.uniform([-90, 0, -60], [90, 120, 40], size=(50, 3))
    batch = lengths(geometry, angles[:, 0], angles[:, 1], angles[:, 2])
    for row, expected in zip(angles, batch, strict=True):
        np.testing.assert_allclose(lengths(geometry, *row)[0], expected, rtol=0, atol=1e-9)


def test_a_tendon_along_the_humerus_axis_ignores_axial_rotation():
    tendon = Tendon("axis", np.array([[0.0, 90.0, 0.0]]), np.array([[0.0, -200.0, 0.0]]))
    geometry = SuitGeometry(np.zeros(3), 50.0, (tendon,))
    out = lengths(geometry, 30.0, 70.0, np.linspace(-80, 40, 9))
    np.testing.assert_allclose(out, out[:1].repeat(9, axis=0), atol=1e-9)


def test_any_number_of_tendons():
    tendons = tuple(
        Tendon(f"T{k}", np.array([[80 * np.cos(a), 60.0, 80 * np.sin(a)]]),
               np.array([[40 * np.cos(a), -120.0, 40 * np.sin(a)]]))
        for k, a in enumerate(np.linspace(0, 2 * np.pi, 6, endpoint=False)))
    geometry = SuitGeometry(np.zeros(3), 50.0, tendons)
    geometry.validate()
    out = lengths(geometry, np.zeros(4), np.linspace(0, 90, 4))
    assert out.shape == (4, 6) and (out > 0).all()


def test_validate_rejects_a_point_inside_the_cap():
    tendon = Tendon("bad", np.array([[10.0, 10.0, 0.0]]), np.array([[0.0, -200.0, 0.0]]))
    with pytest.raises(ValueError, match="outside the shoulder cap"):
        SuitGeometry(np.zeros(3), 50.0, (tendon,)).validate()
