"""Rotation primitives shared by the shoulder and robot conventions.

Conventions used throughout exohil:

* Angles in radians.
* Quaternions are scalar-last ``(x, y, z, w)`` and canonicalised to ``w >= 0`` on output
  (a half-turn, ``w == 0``: first non-zero of x, y, z positive).
* Rotation matrices are ``(..., 3, 3)`` and map child-frame coordinates to parent-frame
  coordinates (``v_parent = R @ v_child``).
* "Intrinsic A-B'-C''" means ``R = R_A(a) @ R_B(b) @ R_C(c)``: rotate about A, then about the
  new B, then about the newest C.

Everything is vectorised: leading dimensions broadcast.
"""

from __future__ import annotations

import numpy as np

# Axis index in a 3-vector.
X, Y, Z = 0, 1, 2

#: Below this |sin| of the middle Euler angle the first angle is taken from the hint.
SINGULAR_EPS = 1e-9


def as_angles(a, b=None, c=None) -> np.ndarray:
    """Stack three broadcastable angle arrays (or take one ``(..., 3)`` array) into ``(..., 3)``."""
    if b is None and c is None:
        arr = np.asarray(a, dtype=float)
        if arr.shape[-1:] != (3,):
            raise ValueError(f"expected three angles or an array (..., 3), got {arr.shape}")
        return arr
    if b is None or c is None:
        raise ValueError("give all three angles, or one array of shape (..., 3)")
    a, b, c = np.broadcast_arrays(
        np.asarray(a, dtype=float), np.asarray(b, dtype=float), np.asarray(c, dtype=float)
    )
    return np.stack([a, b, c], axis=-1)


def broadcast_hint(hint, shape: tuple[int, ...], name: str) -> np.ndarray:
    """``hint`` (radians) as a finite array of ``shape``, wrapped to [−π, π) like the angle it
    stands for; ValueError naming ``name`` for a value that is not finite or does not
    broadcast (a NaN hint would come back as a NaN angle)."""
    h = np.asarray(hint, dtype=float)
    if not np.isfinite(h).all():
        raise ValueError(f"{name} must be finite radians, got {hint!r}")
    try:
        return wrap_angle(np.broadcast_to(h, shape))
    except ValueError:
        raise ValueError(f"{name} of shape {h.shape} does not fit quaternions of "
                         f"shape {shape + (4,)}") from None


def wrap_angle(a) -> np.ndarray:
    """Wrap angles to [-π, π). (The modulo alone gives +π for an angle a hair below −π: the
    tiny negative remainder rounds to 2π.)"""
    wrapped = (np.asarray(a, dtype=float) + np.pi) % (2.0 * np.pi) - np.pi
    return np.where(wrapped >= np.pi, -np.pi, wrapped)[()]


def wrap_angle_above(a) -> np.ndarray:
    """Wrap angles to (−π, π]: :func:`wrap_angle`'s range with the other end kept."""
    return -wrap_angle(-np.asarray(a, dtype=float))


def axis_angle_quat(axis, angle) -> np.ndarray:
    """Quaternion ``(..., 4)`` of a rotation by ``angle`` about the (normalised) ``axis``."""
    axis = np.asarray(axis, dtype=float)
    axis = axis / np.linalg.norm(axis, axis=-1, keepdims=True)
    half = 0.5 * np.asarray(angle, dtype=float)[..., None]
    return np.concatenate([axis * np.sin(half), np.cos(half)], axis=-1)


def elementary_quat(axis_index: int, angle) -> np.ndarray:
    """Quaternion ``(..., 4)`` of a rotation by ``angle`` about X, Y or Z (0, 1, 2)."""
    angle = np.asarray(angle, dtype=float)
    q = np.zeros(angle.shape + (4,))
    q[..., axis_index] = np.sin(0.5 * angle)
    q[..., 3] = np.cos(0.5 * angle)
    return q


def quat_multiply(p, q) -> np.ndarray:
    """Hamilton product ``p ⊗ q`` (apply q, then p), scalar-last, broadcasting."""
    p = np.asarray(p, dtype=float)
    q = np.asarray(q, dtype=float)
    px, py, pz, pw = np.moveaxis(p, -1, 0)
    qx, qy, qz, qw = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
            pw * qw - px * qx - py * qy - pz * qz,
        ],
        axis=-1,
    )


def normalize_quat(q) -> np.ndarray:
    """Unit quaternion with ``w >= 0``; a half-turn (``w == 0``, where ``q`` and ``-q`` both
    have it) gets the sign that makes its first non-zero of x, y, z positive, so each
    rotation has one output (the tie-break of scipy's ``as_quat(canonical=True)``), and no
    component is −0. Raises ValueError for a non-finite quaternion or one shorter than 1e-12
    (zero, or too near it to have a direction)."""
    q = np.asarray(q, dtype=float)
    if q.shape[-1:] != (4,):
        raise ValueError(f"a quaternion has 4 components (x, y, z, w), got shape {q.shape}")
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    if not np.all(np.isfinite(q)) or np.any(norm < 1e-12):
        raise ValueError("quaternions must be finite, with a length of at least 1e-12")
    q = q / norm
    w = q[..., 3:4]
    if (w > 0.0).all():  # the common case, kept cheap (teleop converts every frame)
        return q + 0.0  # + 0.0 turns −0 into 0
    xyz = q[..., :3]
    lead = np.take_along_axis(xyz, np.argmax(xyz != 0.0, axis=-1)[..., None], axis=-1)
    flip = (w < 0.0) | ((w == 0.0) & (lead < 0.0))
    return np.where(flip, -q, q) + 0.0


def quat_to_matrix(q) -> np.ndarray:
    """Rotation matrix ``(..., 3, 3)`` of a quaternion (normalised first)."""
    x, y, z, w = np.moveaxis(normalize_quat(q), -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=-2,
    )


def matrix_to_quat(m) -> np.ndarray:
    """Quaternion ``(..., 4)``, ``w >= 0``, of a rotation matrix ``(..., 3, 3)`` (Shepperd's
    stable method). ValueError for another shape, or a matrix that is not a rotation
    (orthonormal with determinant +1, to 1e-6)."""
    m = np.asarray(m, dtype=float)
    if m.ndim < 2 or m.shape[-2:] != (3, 3):
        raise ValueError(f"rotation matrices are (..., 3, 3), got shape {m.shape}")
    gram = np.einsum("...ji,...jk->...ik", m, m)
    if not (np.allclose(gram, np.eye(3), atol=1e-6) and np.allclose(np.linalg.det(m), 1.0,
                                                                     atol=1e-6)):
        raise ValueError("not a rotation matrix: it must be orthonormal with determinant +1")
    m00, m11, m22 = m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]
    trace = m00 + m11 + m22
    # Four candidate formulas; use the one with the largest pivot for accuracy.
    cand = np.stack(
        [
            np.stack([1 + m00 - m11 - m22, m[..., 0, 1] + m[..., 1, 0],
                      m[..., 0, 2] + m[..., 2, 0], m[..., 2, 1] - m[..., 1, 2]], -1),
            np.stack([m[..., 0, 1] + m[..., 1, 0], 1 - m00 + m11 - m22,
                      m[..., 1, 2] + m[..., 2, 1], m[..., 0, 2] - m[..., 2, 0]], -1),
            np.stack([m[..., 0, 2] + m[..., 2, 0], m[..., 1, 2] + m[..., 2, 1],
                      1 - m00 - m11 + m22, m[..., 1, 0] - m[..., 0, 1]], -1),
            np.stack([m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0],
                      m[..., 1, 0] - m[..., 0, 1], 1 + trace], -1),
        ],
        axis=-2,
    )
    pivots = np.stack([m00, m11, m22, trace], -1)
    best = np.argmax(pivots, axis=-1)
    q = np.take_along_axis(cand, best[..., None, None], axis=-2)[..., 0, :]
    return normalize_quat(q)


def quat_conjugate(q) -> np.ndarray:
    """Inverse of a unit quaternion."""
    q = np.asarray(q, dtype=float)
    return np.concatenate([-q[..., :3], q[..., 3:]], axis=-1)


def rotation_angle_between(p, q) -> np.ndarray:
    """Angle (rad, in [0, π]) of the rotation taking ``q`` to ``p``; sign-invariant."""
    r = quat_multiply(normalize_quat(p), quat_conjugate(normalize_quat(q)))
    return 2.0 * np.arctan2(np.linalg.norm(r[..., :3], axis=-1), np.abs(r[..., 3]))


def elementary_matrix(axis_index: int, angle) -> np.ndarray:
    """Rotation matrix ``(..., 3, 3)`` about X, Y or Z by ``angle``."""
    angle = np.asarray(angle, dtype=float)
    c, s = np.cos(angle), np.sin(angle)
    m = np.zeros(angle.shape + (3, 3))
    i, j = (axis_index + 1) % 3, (axis_index + 2) % 3
    m[..., axis_index, axis_index] = 1.0
    m[..., i, i] = c
    m[..., j, j] = c
    m[..., j, i] = s
    m[..., i, j] = -s
    return m


def third_angle(m_rest, axis_index: int) -> np.ndarray:
    """Angle of ``m_rest``, assumed to be (close to) a rotation about the given axis."""
    i, j = (axis_index + 1) % 3, (axis_index + 2) % 3
    return np.arctan2(m_rest[..., j, i], m_rest[..., i, i])


def intrinsic_euler_from_first_two(
    m, axes: tuple[int, int, int], first, second
) -> np.ndarray:
    """Complete an intrinsic Euler triple: given the first two angles, solve the third exactly.

    Returns ``(..., 3)``. Used both in the regular case and at singularities, where the first
    angle comes from a hint; the third angle then absorbs the combined rotation.
    """
    r12 = elementary_matrix(axes[0], first) @ elementary_matrix(axes[1], second)
    rest = np.swapaxes(r12, -1, -2) @ m
    third = third_angle(rest, axes[2])
    return np.stack(np.broadcast_arrays(first, second, third), axis=-1)
