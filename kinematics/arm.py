"""Arm geometry: where the humerus points (the elbow direction), independent of axial rotation.

Thorax frame (ISB): X anterior, Y superior, Z lateral-right; radians; right arm.
"""

from __future__ import annotations

import numpy as np


def humerus_direction(theta, phi) -> np.ndarray:
    """Unit vector ``(..., 3)`` from the shoulder centre toward the elbow, thorax frame.

    θ = plane of elevation (0: abduction in the coronal plane, +π/2: forward flexion),
    φ = elevation (0: arm hanging), both radians. Equals
    ``(sin φ sin θ, −cos φ, sin φ cos θ)``; the axial rotation does not move the elbow.
    """
    theta, phi = np.broadcast_arrays(np.asarray(theta, dtype=float), np.asarray(phi, dtype=float))
    s = np.sin(phi)
    return np.stack([s * np.sin(theta), -np.cos(phi), s * np.cos(theta)], axis=-1)


def humerus_angles(direction) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`humerus_direction`: ``(θ, φ)`` in radians from vectors ``(..., 3)``
    in the thorax frame (any non-zero length; they are not normalised first).

    φ ∈ [0, π] is the angle from straight down; θ = atan2(x, z) ∈ (−π, π]. With the arm
    hanging or straight up (x = z = 0) θ is undefined and 0 is returned. A zero vector points
    nowhere: both angles are NaN. ValueError unless the last axis holds 3 components.
    """
    d = np.asarray(direction, dtype=float)
    if d.ndim == 0 or d.shape[-1] != 3:
        raise ValueError(f"humerus directions need 3 components (x, y, z) on the last axis, "
                         f"got shape {d.shape}")
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    horizontal = np.hypot(x, z)
    theta = np.where(horizontal == 0, 0.0, np.arctan2(x, z))  # signed zeros chose ±π
    theta = np.where(theta == -np.pi, np.pi, theta)
    phi = np.where((horizontal == 0) & (y == 0), np.nan, np.arctan2(horizontal, -y))
    theta = np.where(np.isnan(phi), np.nan, theta)
    return theta[()], phi[()]  # numpy scalars for one vector, as arctan2 gives
