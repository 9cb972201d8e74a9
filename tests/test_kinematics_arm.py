"""humerus_direction and its inverse humerus_angles (property tests, singular poses included)."""

import numpy as np
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
