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
    broadcast_hint,
    elementary_matrix,
    intrinsic_euler_from_first_two,
    quat_to_matrix,
    wrap_angle,
    wrap_angle_above,
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
    Pitch in [−π/2, π/2]; at gimbal lock (pitch = ±π/2) yaw = ``yaw_hint`` (wrapped to
    [−π, π)) and roll absorbs the rest. Never NaN for unit input; ValueError for a
    ``yaw_hint`` that is not finite or does not broadcast to the quaternions.
    """
    m = quat_to_matrix(q)
    pitch = np.arctan2(-m[..., 2, 0], np.hypot(m[..., 0, 0], m[..., 1, 0]))
    yaw_regular = np.arctan2(m[..., 1, 0], m[..., 0, 0])
    cos_p = np.hypot(m[..., 0, 0], m[..., 1, 0])
    hint = broadcast_hint(yaw_hint, pitch.shape, "yaw_hint")
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


def _pitch_of(hint, shape: tuple[int, ...]) -> np.ndarray:
    """The pitch of ``hint`` (``(..., 3)`` joint angles, radians) for commands of ``shape``,
    wrapped to (−π, π] like the exact pitch; ValueError for another shape or a value that is
    not finite."""
    h = np.asarray(hint, dtype=float)
    if h.ndim == 0 or h.shape[-1] != 3 or not np.isfinite(h).all():
        raise ValueError(f"hint must be finite joint angles (..., 3), radians (the previous "
                         f"unclamped), got shape {h.shape}")
    try:
        return wrap_angle_above(np.broadcast_to(h[..., 0], shape))  # as pitch is
    except ValueError:
        raise ValueError(f"hint of shape {h.shape} does not fit commands of shape "
                         f"{shape + (3,)}") from None


def humerus_to_nao(q, side: Side = "right", hint=None, hysteresis: float = 0.0) -> NaoArm:
    """Thorax ← humerus quaternion ``(..., 4)`` → NAO (ShoulderPitch, ShoulderRoll, ElbowYaw).

    The upper-arm direction comes first. The matched line is the NAO upper arm's X axis (the
    ElbowYaw axis; NAO's elbow sits 15 mm beside it, docs/conventions.md): it is set to the
    humerus long axis (shoulder → elbow) whenever some (pitch, roll) within the limits reaches
    that direction, and otherwise to the nearest reachable direction (smallest angle). Elbow
    yaw is then the one that brings the arm frame closest to the wanted orientation, clamped.
    When nothing is clamped the command is the exact orientation.

    Known poses (right arm): arm hanging → pitch +π/2, roll 0; forward flexion 90° → pitch 0,
    roll 0; abduction 90° → roll −π/2, outside the limit, so the command is roll −76°.

    Returns a :class:`NaoArm`: ``unclamped`` is the exact joint solution with |roll| ≤ π/2
    (pitch in (−π, π]), ``clamped`` marks its joints outside the limits, and ``angles`` is the
    command (within the limits; where a direction is unreachable it is the nearest reachable
    one, not the clipped ``unclamped``). Where the nearest direction is not unique (the arm
    pointing straight along ±Y, roll = ±π/2, or straight into the unreachable wedge behind the
    shoulder), the pitch closest to ``hint`` is taken: ``hint`` is ``(..., 3)`` previous joint
    angles (radians, the previous command ``angles``), or None for pitch 0. Pass the previous
    output to keep a stream continuous; away from these ties the command is a continuous
    function of the wanted direction, but it moves fast near them (docs/conventions.md).

    Two choices flip from one limit to the other across a surface of poses, not only at a
    point: the pitch limit for an arm pointing behind the shoulder (the two are equally near
    whenever the arm is horizontal there), and the elbow-yaw limit when the wanted yaw lies
    beyond ±119.5° (equally near at 180°, which an arm overhead reaches as θ turns). With a
    ``hint``, ``hysteresis`` (radians, ≥ 0) keeps the hint's limit in both choices until the
    other one is nearer by more than that: the arm axis (pitch) or the arm frame (yaw) may be
    up to ``hysteresis`` farther from the wanted pose than the nearest command, and a stream
    that wavers across the surface no longer swings the joint from limit to limit (239° of
    pitch, 239° of yaw). Without a hint it is ignored. Never NaN, never raises for unit input.
    """
    if side not in NAO_LIMITS:
        raise ValueError(f"side must be 'right' or 'left', got {side!r}")
    if not hysteresis >= 0.0 or not np.isfinite(hysteresis):
        raise ValueError(f"hysteresis must be finite and >= 0 (radians), got {hysteresis!r}")
    sticky = 0.0 if hint is None else float(hysteresis)
    m = NAO_FROM_ISB @ quat_to_matrix(q) @ HUMERUS_FROM_NAO_ARM
    # Arm direction = first column = (cos p cos r, sin r, −sin p cos r).
    direction = m[..., :, 0]
    cos_r = np.hypot(direction[..., 0], direction[..., 2])
    roll = np.arctan2(direction[..., 1], cos_r)
    pitch_hint = np.broadcast_to(0.0 if hint is None else _pitch_of(hint, roll.shape),
                                 roll.shape)
    pitch = np.where(cos_r < SINGULAR_EPS, pitch_hint,  # atan2 gives ±π; keep (−π, π]
                     wrap_angle_above(np.arctan2(-direction[..., 2], direction[..., 0])))
    exact = intrinsic_euler_from_first_two(m, (Y, Z, X), pitch, roll)
    # The left arm is the mirror image: solve in right-arm angles with mirrored limits.
    mirror = np.array([1.0, -1.0, -1.0]) if side == "left" else np.ones(3)
    limits = NAO_LIMITS[side]
    right_limits = np.sort(limits * mirror[:, None], axis=1)
    p_cmd, r_cmd = _nearest_reachable(direction, pitch, roll, pitch_hint, right_limits, sticky)
    yaw = exact[..., 2]
    reached = (p_cmd == pitch) & (r_cmd == roll)
    if not np.all(reached):  # the yaw that brings R_y(p) R_z(r) R_x(yaw) closest to m
        arm = np.swapaxes(_nao_matrix(np.stack([p_cmd, r_cmd, np.zeros_like(p_cmd)], axis=-1)),
                          -1, -2) @ m
        yaw_best = np.arctan2(arm[..., 2, 1] - arm[..., 1, 2], arm[..., 1, 1] + arm[..., 2, 2])
        yaw = np.where(reached, yaw, yaw_best)
    yaw_hint = None if hint is None else np.asarray(hint, dtype=float)[..., 2] * mirror[2]
    yaw = _nearest_yaw(yaw, right_limits[2], yaw_hint, sticky)
    command = np.stack([p_cmd, r_cmd, yaw], axis=-1) * mirror
    unclamped = exact * mirror
    outside = (unclamped < limits[:, 0]) | (unclamped > limits[:, 1])
    return NaoArm(angles=command, clamped=outside, unclamped=unclamped)


def _nearest_yaw(yaw, limits, yaw_hint, sticky: float):
    """Elbow yaw ``yaw`` (radians, in (−π, π]) within ``limits``: itself, or the nearer limit
    around the circle (the one ``np.clip`` gives, as the limits straddle 0); with a
    ``yaw_hint`` the limit nearer the hint is kept unless the other is nearer by more than
    ``sticky`` radians."""
    low, high = limits
    clipped = np.clip(yaw, low, high)
    if yaw_hint is None or sticky == 0.0:
        return clipped
    outside = (yaw < low) | (yaw > high)
    to_high, to_low = np.abs(wrap_angle(yaw - high)), np.abs(wrap_angle(yaw - low))
    hint_high = (np.abs(wrap_angle(yaw_hint - high)) <= np.abs(wrap_angle(yaw_hint - low)))
    take_high = np.where(hint_high, to_high <= to_low + sticky, to_high < to_low - sticky)
    return np.where(outside, np.where(take_high, high, low), clipped)


def _nearest_reachable(direction, pitch, roll, pitch_hint, limits, sticky: float = 0.0):
    """Right-arm (pitch, roll) within ``limits`` whose arm X axis is closest to ``direction``.

    ``direction`` ``(..., 3)`` is a unit vector in the NAO torso frame, ``pitch``/``roll`` its
    exact angles (roll in [−π/2, π/2]). Directions form a latitude (roll, about ±Y) / longitude
    (pitch) grid, and the reachable set is a rectangle in it. If the pitch is within its limits
    the nearest point keeps it and clamps the roll. Otherwise it lies on one of the two pitch
    limits (for any fixed roll, the nearer longitude is better since cos r ≥ 0), at the roll
    that maximises sin r sin r* + cos r cos r* cos Δ on that meridian, or at a roll limit; all
    six candidates are compared, and ties within 1e-12 rad go to the pitch limit nearer the
    hint, then to the order above; ``sticky`` (radians) widens that margin for the hint's
    pitch limit: the other wins only when nearer by more than it.
    """
    (p_low, p_high), (r_low, r_high) = limits[0], limits[1]
    shape = np.shape(pitch)
    p_cmd = np.clip(pitch, p_low, p_high).reshape(-1)
    r_cmd = np.clip(roll, r_low, r_high).reshape(-1)
    outside = ((pitch < p_low) | (pitch > p_high)).reshape(-1)
    if np.any(outside):
        d = direction.reshape(-1, 3)[outside]
        p_star, r_star = pitch.reshape(-1)[outside], roll.reshape(-1)[outside]
        hint = pitch_hint.reshape(-1)[outside]
        high_first = (np.abs(wrap_angle(hint - p_high)) <= np.abs(wrap_angle(hint - p_low)))
        p_cand, r_cand = [], []
        for p_b in (np.where(high_first, p_high, p_low), np.where(high_first, p_low, p_high)):
            r_best = np.arctan2(np.sin(r_star), np.cos(r_star) * np.cos(p_star - p_b))
            for r in (np.clip(r_best, r_low, r_high), np.full_like(r_star, r_low),
                      np.full_like(r_star, r_high)):
                p_cand.append(p_b)
                r_cand.append(r)
        p_c, r_c = np.stack(p_cand, axis=-1), np.stack(r_cand, axis=-1)  # (n, 6)
        points = np.stack([np.cos(p_c) * np.cos(r_c), np.sin(r_c), -np.sin(p_c) * np.cos(r_c)],
                          axis=-1)
        errors = np.arctan2(np.linalg.norm(np.cross(points, d[:, None, :]), axis=-1),
                            np.einsum("nkj,nj->nk", points, d))
        errors[:, :3] -= sticky  # the first three lie on the pitch limit nearer the hint
        best = np.argmax(errors <= errors.min(axis=-1, keepdims=True) + 1e-12, axis=-1)
        rows = np.arange(len(best))
        p_cmd[outside], r_cmd[outside] = p_c[rows, best], r_c[rows, best]
    return p_cmd.reshape(shape), r_cmd.reshape(shape)


def _nao_matrix(angles: np.ndarray) -> np.ndarray:
    """NAO torso ← upper arm rotation of right-arm joint angles ``(..., 3)``."""
    return (elementary_matrix(Y, angles[..., 0]) @ elementary_matrix(Z, angles[..., 1])
            @ elementary_matrix(X, angles[..., 2]))
