"""humerus_direction and its inverse humerus_angles (property tests, singular poses included)."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from exohil.kinematics import humerus_angles, humerus_direction

angle = st.floats(-np.pi, np.pi, allow_nan=False)
elevation = st.floats(0.0, np.pi, allow_nan=False)


@given(theta=angle, phi=elevation, scale=st.floats(1e-3, 1e3))
def test_angles_give_back_the_same_direction(theta, phi, scale):
    d = humerus_direction(theta, phi)
    th, ph = humerus_angles(scale * d)
    assert np.allclose(humerus_direction(th, ph), d, atol=1e-9)
    assert abs(ph - phi) < 1e-9


@given(theta=st.floats(-np.pi + 1e-3, np.pi, allow_nan=False),
       phi=st.floats(1e-3, np.pi - 1e-3, allow_nan=False))
def test_plane_of_elevation_comes_back_away_from_the_poles(theta, phi):
    th, _ = humerus_angles(humerus_direction(theta, phi))
    assert abs(th - theta) < 1e-6


def test_hanging_and_raised_arm_have_plane_zero():
    th, ph = humerus_angles(np.array([[0.0, -1.0, 0.0], [0.0, 2.0, 0.0]]))
    assert th.tolist() == [0.0, 0.0]
    assert np.allclose(ph, [0.0, np.pi])


def test_humerus_angles_at_the_poles_and_for_no_direction_keep_their_docstring():
    """With the arm hanging θ came back as ±π (the signed zeros of x and z chose), −π lay
    outside (−π, π], a zero vector read as 'straight up' and a 4-vector was accepted."""
    for theta in (2.5, -2.5, 0.0):
        assert tuple(map(float, humerus_angles(humerus_direction(theta, 0.0)))) == (0.0, 0.0)
    th, ph = humerus_angles([[-0.0, 0.0, -1.0], [0.0, 0.0, -1.0]])
    np.testing.assert_array_equal(th, [np.pi, np.pi])  # behind: +π, never −π
    assert np.isnan(humerus_angles([0.0, 0.0, 0.0])).all()
    for bad in ([0.0, 1.0, 0.0, 0.0], [0.0, 1.0], 3.0):
        with pytest.raises(ValueError, match="need 3 components"):
            humerus_angles(bad)


def test_conversions_refuse_what_they_cannot_convert():
    """matrix_to_quat read a 4x4 or a matrix of ones as the identity; ms_to_isb and
    isb_to_ms let NaN through where ms_to_quat refused it; a NaN plane_hint gave NaN
    ('never NaN')."""
    from exohil.kinematics import isb_to_ms, ms_to_isb, quat_to_ms
    from exohil.kinematics.rotations import matrix_to_quat

    for bad, said in ((np.eye(4), r"\(\.\.\., 3, 3\)"), (np.ones(3), r"\(\.\.\., 3, 3\)"),
                      (np.ones((3, 3)), "not a rotation matrix"),
                      (np.diag([1.0, 1.0, -1.0]), "not a rotation matrix")):
        with pytest.raises(ValueError, match=said):
            matrix_to_quat(bad)
    np.testing.assert_allclose(matrix_to_quat(np.eye(3)), [0, 0, 0, 1])
    with pytest.raises(ValueError, match="must be finite"):
        ms_to_isb(np.nan, 0.2, 0.3)
    for angles in ((np.nan, -0.2, 0.3), (0.1, np.inf, 0.3), [[0.1, -0.2, 0.3], [0, 0, np.nan]]):
        with pytest.raises(ValueError, match="ISB angles must be finite"):  # was NaN out
            isb_to_ms(angles if isinstance(angles, list) else np.array(angles))
    with pytest.raises(ValueError, match="plane_hint must be finite"):
        quat_to_ms([0.0, 0.0, 0.0, 1.0], plane_hint=np.nan)
    with pytest.raises(ValueError, match="does not fit"):
        quat_to_ms(np.tile([0.0, 0.0, 0.0, 1.0], (3, 1)), plane_hint=[0.0, 0.0])
    from exohil.kinematics import humerus_to_nao

    for hint in ([0.0, 0.0], 0.5, [np.nan, 0.0, 0.0]):  # hint=0.5 was an IndexError
        with pytest.raises(ValueError, match="hint must be finite joint angles"):
            humerus_to_nao(np.tile([0.0, 0.0, 0.0, 1.0], (3, 1)), hint=hint)
    with pytest.raises(ValueError, match="does not fit"):
        humerus_to_nao(np.tile([0.0, 0.0, 0.0, 1.0], (3, 1)), hint=np.zeros((2, 3)))
