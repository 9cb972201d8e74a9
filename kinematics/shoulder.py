"""Shoulder angle conventions: MoBL-ARMS coordinates, ISB Y-X'-Y'' Euler angles, quaternions.

Frames (right arm):

* Thorax frame (ISB, Wu et al. 2005): origin at the glenohumeral centre for our purposes,
  X anterior, Y superior, Z lateral (to the right).
* Humerus frame (ISB): Y along the humerus from the elbow to the shoulder (so the elbow lies
  along −Y), X anterior and Z lateral when the arm hangs in the anatomical pose.

Orientations are thorax ← humerus rotations.

MoBL-ARMS (Saul et al. 2015) shoulder coordinates: θ = ``elv_angle`` (plane of elevation),
φ = ``shoulder_elv`` (elevation), ψ = ``shoulder_rot`` (axial rotation). The model applies, in
body-fixed order, elv_angle about the vertical, shoulder_elv about the (negative) anterior axis,
a coupled rotation of −elv_angle about the vertical (a coupler constraint), then shoulder_rot
about the vertical. With ideal axes this is

    R = Ry(θ) · Rx(−φ) · Ry(ψ − θ)

so the ISB humerothoracic Y-X'-Y'' angles are (α, β, γ) = (θ, −φ, ψ − θ). The paper (Varghese
et al.) used (θ, −φ, ψ) instead: the same humerus direction, but an axial rotation that is off
by θ (see docs/conventions.md). Both are offered: ``convention="coupled"`` (correct, default)
and ``convention="paper"``.

All angles in radians.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from exohil.kinematics.rotations import (
    SINGULAR_EPS,
    X,
    Y,
    as_angles,
    axis_angle_quat,
    broadcast_hint,
    elementary_quat,
    intrinsic_euler_from_first_two,
    normalize_quat,
    quat_multiply,
    quat_to_matrix,
    wrap_angle,
)

Convention = Literal["coupled", "paper"]
Axes = Literal["ideal", "mobl"]

#: MoBL-ARMS joint axes (Saul et al. model file), in the parent body frame of each joint.
MOBL_ELV_ANGLE_AXIS = np.array([0.0048, 0.99908918, 0.04240001])
MOBL_SHOULDER_ELV_AXIS = np.array([-0.99826136, 0.0023, 0.05889802])
MOBL_SHOULDER_ROT_AXIS = MOBL_ELV_ANGLE_AXIS  # the coupled rotation uses the same axis

#: Shoulder elevation φ, degrees (a convention every layer scores by, so it is in degrees
#: like the files it is applied to), from which the plane of elevation θ counts as
#: observable: below it θ is ill-defined, undefined at φ = 0 (docs/conventions.md).
OBSERVABLE_ELEVATION_DEG = 20.0

#: Ranges of the MoBL-ARMS coordinates, radians.
MOBL_RANGES = {
    "elv_angle": (np.deg2rad(-90.0), np.deg2rad(130.0)),
    "shoulder_elv": (0.0, np.pi),
    "shoulder_rot": (np.deg2rad(-90.0), np.deg2rad(20.0)),
}


def ms_to_isb(theta, phi=None, psi=None, convention: Convention = "coupled") -> np.ndarray:
    """MoBL-ARMS (θ, φ, ψ) → ISB humerothoracic Y-X'-Y'' angles (α, β, γ), radians, ``(..., 3)``.

    α is the plane of elevation, β the (negative) elevation, γ the axial rotation.
    ``convention="coupled"`` gives (θ, −φ, ψ − θ) (the model's coupler constraint);
    ``convention="paper"`` gives the paper's (θ, −φ, ψ). γ is wrapped to [−π, π).
    Accepts three broadcastable arrays or one ``(..., 3)`` array.
    """
    ms = as_angles(theta, phi, psi)
    if not np.isfinite(ms).all():  # as ms_to_quat refuses them
        raise ValueError("MoBL-ARMS angles must be finite")
    t, p, s = ms[..., 0], ms[..., 1], ms[..., 2]
    if convention == "coupled":
        gamma = wrap_angle(s - t)
    elif convention == "paper":
        gamma = wrap_angle(s)
    else:
        raise ValueError(f"unknown convention {convention!r}; use 'coupled' or 'paper'")
    return np.stack([t, -p, gamma], axis=-1)


def isb_to_ms(alpha, beta=None, gamma=None, convention: Convention = "coupled") -> np.ndarray:
    """ISB Y-X'-Y'' (α, β, γ) → MoBL-ARMS (θ, φ, ψ), radians, ``(..., 3)``; inverse of
    :func:`ms_to_isb`. ψ is wrapped to [−π, π). ValueError for angles that are not finite
    (as :func:`ms_to_isb` and :func:`isb_to_quat` refuse them)."""
    isb = as_angles(alpha, beta, gamma)
    if not np.isfinite(isb).all():
        raise ValueError("ISB angles must be finite")
    a, b, g = isb[..., 0], isb[..., 1], isb[..., 2]
    if convention == "coupled":
        psi = wrap_angle(g + a)
    elif convention == "paper":
        psi = wrap_angle(g)
    else:
        raise ValueError(f"unknown convention {convention!r}; use 'coupled' or 'paper'")
    return np.stack([a, -b, psi], axis=-1)


def isb_to_quat(alpha, beta=None, gamma=None) -> np.ndarray:
    """ISB Y-X'-Y'' angles (rad) → thorax ← humerus quaternion ``(..., 4)``, (x, y, z, w), w ≥ 0."""
    isb = as_angles(alpha, beta, gamma)
    q = quat_multiply(
        quat_multiply(elementary_quat(Y, isb[..., 0]), elementary_quat(X, isb[..., 1])),
        elementary_quat(Y, isb[..., 2]),
    )
    return normalize_quat(q)


def quat_to_isb(q, plane_hint=0.0) -> np.ndarray:
    """Thorax ← humerus quaternion → ISB Y-X'-Y'' angles (α, β, γ), radians, ``(..., 3)``.

    β is returned in [−π, 0] (elevation φ = −β in [0, π]); α and γ in [−π, π).
    At the singularities β = 0 (arm hanging) and β = −π (arm straight up) only α + γ, resp.
    γ − α, is defined: α is then set to ``plane_hint`` wrapped to [−π, π) (pass the previous
    plane of elevation to keep a stream continuous) and γ absorbs the rest. Never NaN, never
    raises for unit input.
    """
    m = quat_to_matrix(q)
    # Column Y of R is (sin α sin β, cos β, cos α sin β); choose sin β ≤ 0.
    sin_b = -np.hypot(m[..., 0, 1], m[..., 2, 1])
    beta = np.arctan2(sin_b, m[..., 1, 1])
    alpha_regular = wrap_angle(np.arctan2(-m[..., 0, 1], -m[..., 2, 1]))  # atan2 gives ±π
    hint = broadcast_hint(plane_hint, beta.shape, "plane_hint")
    alpha = np.where(-sin_b < SINGULAR_EPS, hint, alpha_regular)
    out = intrinsic_euler_from_first_two(m, (Y, X, Y), alpha, beta)
    return np.stack([out[..., 0], out[..., 1], wrap_angle(out[..., 2])], axis=-1)


def ms_to_quat(theta, phi=None, psi=None, axes: Axes = "ideal",
               convention: Convention = "coupled") -> np.ndarray:
    """MoBL-ARMS (θ, φ, ψ) → thorax ← humerus quaternion ``(..., 4)``, (x, y, z, w), w ≥ 0.

    ``axes="ideal"``: the ISB axes exactly (via :func:`ms_to_isb` and :func:`isb_to_quat`).
    ``axes="mobl"``: the MoBL-ARMS model file's joint axes (elv_angle, shoulder_elv, the
    coupled −elv_angle and shoulder_rot in body-fixed order); it differs from the ideal form by
    up to about 8° over the model's range. ``convention`` applies to ideal axes only.
    """
    ms = as_angles(theta, phi, psi)
    if axes == "ideal":
        return isb_to_quat(ms_to_isb(ms, convention=convention))
    if axes != "mobl":
        raise ValueError(f"unknown axes {axes!r}; use 'ideal' or 'mobl'")
    if convention != "coupled":
        raise ValueError("axes='mobl' follows the model file, whose coupler is the 'coupled' form")
    t, p, s = ms[..., 0], ms[..., 1], ms[..., 2]
    q = axis_angle_quat(MOBL_ELV_ANGLE_AXIS, t)
    q = quat_multiply(q, axis_angle_quat(MOBL_SHOULDER_ELV_AXIS, p))
    q = quat_multiply(q, axis_angle_quat(MOBL_SHOULDER_ROT_AXIS, -t))
    q = quat_multiply(q, axis_angle_quat(MOBL_SHOULDER_ROT_AXIS, s))
    return normalize_quat(q)


def quat_to_ms(q, plane_hint=0.0, convention: Convention = "coupled") -> np.ndarray:
    """Thorax ← humerus quaternion → MoBL-ARMS (θ, φ, ψ), radians (ideal axes).

    φ in [0, π]; at φ = 0 or π, θ = ``plane_hint`` (see :func:`quat_to_isb`).
    """
    return isb_to_ms(quat_to_isb(q, plane_hint), convention=convention)


def ms_to_matrix(theta, phi=None, psi=None, axes: Axes = "ideal") -> np.ndarray:
    """MoBL-ARMS (θ, φ, ψ), radians → thorax ← humerus rotation matrix ``(..., 3, 3)``, the
    matrix of :func:`ms_to_quat` (coupled convention). ψ defaults to 0 when only θ and φ are
    given."""
    if psi is None and phi is None:
        return quat_to_matrix(ms_to_quat(theta, axes=axes))
    return quat_to_matrix(ms_to_quat(theta, phi, 0.0 if psi is None else psi, axes=axes))
