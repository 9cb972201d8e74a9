"""Arm geometry: where the humerus points (the elbow direction), independent of axial rotation.

Thorax frame (ISB): X anterior, Y superior, Z lateral-right; radians; right arm.
"""

from __future__ import annotations

import numpy as np


def humerus_direction(theta, phi) -> np.ndarray:
    """Unit vector ``(..., 3)`` from the shoulder centre toward the elbow, thorax frame.

    θ = plane of elevation (0: abduction in the coronal plane, +π/2: forward flexion),
    φ = elevation (0: arm hanging). Equals ``(sin φ sin θ, −cos φ, sin φ cos θ)``; the
    axial rotation does not move the elbow.
    """
    theta, phi = np.broadcast_arrays(np.asarray(theta, dtype=float), np.asarray(phi, dtype=float))
    s = np.sin(phi)
    return np.stack([s * np.sin(theta), -np.cos(phi), s * np.cos(theta)], axis=-1)
