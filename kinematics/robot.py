"""Robot-side conversions: Z-Y'-X'' Euler angles (V-REP/CoppeliaSim) and NAO arm joints.

NAO torso frame: X forward, Y left, Z up. The NAO shoulder chain is ShoulderPitch about Y,
ShoulderRoll about Z', ElbowYaw about X'' (intrinsic Y-Z'-X''); at zero the arm points forward
along X, and positive pitch lowers the arm. The thorax ← humerus quaternion is given in the
ISB thorax frame (X anterior, Y superior, Z lateral-right); for the left arm, pass the mirrored
ISB frame (Z lateral-left), i.e. the same angles describe the mirror-image pose.

Radians inside; the limits below are NAO V5 joint limits.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from exohil.kinematics.rotations import (
    SINGULAR_EPS,
    X,
    Y,
    Z,
    elementary_matrix,
    intrinsic_euler_from_first_two,
    quat_to_matrix,
    wrap_angle,
)

Side = Literal["right", "left"]

#: NAO joint names in output order.
NAO_JOINTS = ("ShoulderPitch", "ShoulderRoll", "ElbowYaw")

#: Joint limits (rad), per side: (low, high) for pitch, roll, elbow yaw.
NAO_LIMITS = {
    "right": np.deg2rad([[-119.5, 119.5], [-76.0, 18.0], [-119.5, 119.5]]),
    "left": np.deg2rad([[-119.5, 119.5], [-18.0, 76.0], [-119.5, 119.5]]),
}

#: NAO torso ← ISB thorax (x_nao = x_isb, y_nao = −z_isb, z_nao = y_isb).
NAO_FROM_ISB = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
#: Humerus ← NAO upper-arm frame (arm x = −humerus y, arm y = −humerus z, arm z = humerus x).
HUMERUS_FROM_NAO_ARM = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def quat_to_zyx(q, yaw_hint=0.0) -> np.ndarray:
    """Quaternion → intrinsic Z-Y'-X'' angles (yaw, pitch, roll), radians, ``(..., 3)``.

    This is the paper's last step toward V-REP/CoppeliaSim (equivalently extrinsic X-Y-Z).
    Pitch in [−π/2, π/2]; at gimbal lock (pitch = ±π/2) yaw = ``yaw_hint`` and roll absorbs the
    rest. Never NaN for unit input.
    """
    m = quat_to_matrix(q)
    pitch = np.arctan2(-m[..., 2, 0], np.hypot(m[..., 0, 0], m[..., 1, 0]))
    yaw_regular = np.arctan2(m[..., 1, 0], m[..., 0, 0])
    cos_p = np.hypot(m[..., 0, 0], m[..., 1, 0])
    hint = np.broadcast_to(np.asarray(yaw_hint, dtype=float), pitch.shape)
    yaw = np.where(cos_p < SINGULAR_EPS, hint, yaw_regular)
    return intrinsic_euler_from_first_two(m, (Z, Y, X), yaw, pitch)


@dataclass(frozen=True)
class NaoArm:
    """NAO arm joint angles.

    Attributes:
        angles: ``(..., 3)`` ShoulderPitch, ShoulderRoll, ElbowYaw in radians, clamped to limits.
        clamped: ``(..., 3)`` bool, True where the unclamped angle was outside the limit.
        unclamped: ``(..., 3)`` the angles before clamping, radians.
    """

    angles: np.ndarray
    clamped: np.ndarray
    unclamped: np.ndarray

    @property
    def any_clamped(self) -> np.ndarray:
        """``(...)`` bool: True where any joint was clamped."""
        return np.any(self.clamped, axis=-1)


def humerus_to_nao(q, side: Side = "right", hint=None) -> NaoArm:
    """Thorax ← humerus quaternion ``(..., 4)`` → NAO (ShoulderPitch, ShoulderRoll, ElbowYaw).

    Known poses (right arm): arm hanging → pitch +π/2, roll 0; forward flexion 90° → pitch 0,
    roll 0; abduction 90° → roll −π/2, outside the limit, so clamped to −76° and reported.

    Every orientation has two Y-Z'-X'' solutions, (p, r, y) and (p + π, π − r, y + π). The NAO
    cannot reach most of either (roll −76°..18°), so the one whose *clamped* angles come closest
    to the wanted orientation is returned (the first, |roll| ≤ π/2, on a tie). This keeps the
    arm near horizontal when it sweeps through pure abduction instead of flipping pitch by π.
    At roll = ±π/2 (the chain's singularity) pitch is taken from ``hint`` (``(..., 3)`` previous
    joint angles, or None for pitch 0) and elbow yaw absorbs the rest; pass the previous output
    to keep a stream continuous. Never NaN, never raises for unit input.
    """
    if side not in NAO_LIMITS:
        raise ValueError(f"side must be 'right' or 'left', got {side!r}")
    m = NAO_FROM_ISB @ quat_to_matrix(q) @ HUMERUS_FROM_NAO_ARM
    # Arm direction = first column = (cos p cos r, sin r, −sin p cos r).
    cos_r = np.hypot(m[..., 0, 0], m[..., 2, 0])
    roll = np.arctan2(m[..., 1, 0], cos_r)
    pitch_regular = np.arctan2(-m[..., 2, 0], m[..., 0, 0])
    pitch_hint = 0.0 if hint is None else np.asarray(hint, dtype=float)[..., 0]
    pitch = np.where(cos_r < SINGULAR_EPS, np.broadcast_to(pitch_hint, roll.shape), pitch_regular)
    first = intrinsic_euler_from_first_two(m, (Y, Z, X), pitch, roll)
    second = wrap_angle(np.stack([first[..., 0] + np.pi, np.pi - first[..., 1],
                                  first[..., 2] + np.pi], axis=-1))
    mirror = np.array([1.0, -1.0, -1.0]) if side == "left" else np.ones(3)
    limits = NAO_LIMITS[side]
    candidates = []
    for angles in (first * mirror, second * mirror):  # left arm: mirror image
        clamped = np.clip(angles, limits[:, 0], limits[:, 1])
        reached = _nao_matrix(clamped * mirror)
        error = np.arccos(np.clip(0.5 * (np.trace(np.swapaxes(reached, -1, -2) @ m,
                                                  axis1=-2, axis2=-1) - 1.0), -1.0, 1.0))
        candidates.append((angles, clamped, error))
    (a1, c1, e1), (a2, c2, e2) = candidates
    use_second = (e2 < e1 - 1e-9)[..., None]
    angles = np.where(use_second, a2, a1)
    clamped_angles = np.where(use_second, c2, c1)
    return NaoArm(angles=clamped_angles, clamped=clamped_angles != angles, unclamped=angles)


def _nao_matrix(angles: np.ndarray) -> np.ndarray:
    """NAO torso ← upper arm rotation of right-arm joint angles ``(..., 3)``."""
    return (elementary_matrix(Y, angles[..., 0]) @ elementary_matrix(Z, angles[..., 1])
            @ elementary_matrix(X, angles[..., 2]))
