"""Tendon path geometry: tendon path lengths (mm) from the humerus orientation.

Frames: the ISB thorax frame with its origin at the glenohumeral (GH) centre (X anterior,
Y superior, Z lateral-right), and the humerus frame, which coincides with the thorax frame when
the arm hangs (θ = φ = ψ = 0) and rotates with the arm about the GH centre (thorax ← humerus
rotation from :func:`exohil.kinematics.shoulder.ms_to_matrix`). Lengths are mm.

Each tendon runs from the string pot through routing points fixed on the thorax (back support,
shoulder harness) to routing points fixed on the upper arm, ending at its termination above the
elbow. Every straight run between consecutive points wraps over the shoulder cap — a sphere
around the GH region — when the straight line would pass through it: the shortest path is then
tangent line + great-circle arc + tangent line in the plane through the sphere's centre and the
two points. Lengths change smoothly (C¹) with the arm's orientation. Runs between two points on
the same body are rigid and contribute a constant.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from exohil.kinematics import ms_to_matrix


def wrapped_length(p: np.ndarray, q: np.ndarray, centre: np.ndarray, radius: float) -> np.ndarray:
    """Shortest path length from ``p`` to ``q`` (mm) that stays outside a sphere.

    ``p`` and ``q`` are (..., 3) points in mm, broadcastable, both outside the sphere of
    ``radius`` mm around ``centre``. When the straight segment clears the sphere the answer is
    ``|p − q|``; otherwise tangent lengths plus the great-circle arc between the tangent points.
    """
    a = np.asarray(p, dtype=np.float64) - centre
    b = np.asarray(q, dtype=np.float64) - centre
    ra = np.linalg.norm(a, axis=-1)
    rb = np.linalg.norm(b, axis=-1)
    cos_gamma = np.clip(np.sum(a * b, axis=-1) / (ra * rb), -1.0, 1.0)
    gamma = np.arccos(cos_gamma)  # angle between the points seen from the centre
    alpha_a = np.arccos(np.clip(radius / ra, -1.0, 1.0))  # angle from a to its tangent point
    alpha_b = np.arccos(np.clip(radius / rb, -1.0, 1.0))
    arc = gamma - alpha_a - alpha_b
    straight = np.linalg.norm(a - b, axis=-1)
    wrapped = np.sqrt(ra**2 - radius**2) + np.sqrt(rb**2 - radius**2) + radius * arc
    return np.where(arc > 0.0, wrapped, straight)


@dataclass(frozen=True)
class Tendon:
    """One sensing tendon.

    Attributes:
        name: sensor name (e.g. "F").
        thorax_points_mm: (P, 3) points fixed in the thorax frame, mm, from the string pot
            toward the arm (P ≥ 1).
        humerus_points_mm: (Q, 3) points fixed in the humerus frame, mm, from the shoulder
            toward the elbow; the last is the termination above the elbow (Q ≥ 1).
    """

    name: str
    thorax_points_mm: np.ndarray
    humerus_points_mm: np.ndarray


@dataclass(frozen=True)
class SuitGeometry:
    """Shoulder cap and tendons.

    Attributes:
        cap_centre_mm: (3,) centre of the wrapping sphere in the thorax frame, mm.
        cap_radius_mm: its radius, mm.
        tendons: the tendons in sensor-column order.
    """

    cap_centre_mm: np.ndarray
    cap_radius_mm: float
    tendons: tuple[Tendon, ...]

    @property
    def sensor_names(self) -> tuple[str, ...]:
        return tuple(t.name for t in self.tendons)

    def validate(self) -> None:
        """Raise ValueError unless every point stays outside the cap in every arm orientation."""
        centre, radius = self.cap_centre_mm, self.cap_radius_mm
        if radius <= 0:
            raise ValueError(f"cap radius_mm must be > 0, got {radius}")
        for tendon in self.tendons:
            for label, pts in (("thorax", tendon.thorax_points_mm),
                               ("humerus", tendon.humerus_points_mm)):
                if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] < 1:
                    raise ValueError(f"tendon {tendon.name}: {label}_points_mm must be a "
                                     f"non-empty list of [x, y, z] points")
            clear_thorax = np.linalg.norm(tendon.thorax_points_mm - centre, axis=1) > radius
            # a humerus point sweeps a sphere of its own radius about the GH centre (origin)
            reach = np.linalg.norm(tendon.humerus_points_mm, axis=1) - np.linalg.norm(centre)
            if not (clear_thorax.all() and (reach > radius).all()):
                raise ValueError(f"tendon {tendon.name}: every point must lie outside the shoulder "
                                 f"cap (radius {radius} mm) in every arm orientation")

    def rigid_lengths_mm(self) -> np.ndarray:
        """(S,) constant part of each path (runs within the thorax and within the arm), mm."""
        out = []
        for tendon in self.tendons:
            total = 0.0
            for pts in (tendon.thorax_points_mm, tendon.humerus_points_mm):
                if pts.shape[0] > 1:
                    total += float(np.sum(wrapped_length(pts[:-1], pts[1:], self.cap_centre_mm,
                                                         self.cap_radius_mm)))
            out.append(total)
        return np.asarray(out)

    def path_lengths(self, theta: np.ndarray, phi: np.ndarray, psi: np.ndarray | float = 0.0
                     ) -> np.ndarray:
        """Tendon path lengths (N, S) in mm for MoBL-ARMS angles in radians (each (N,) or
        scalar; θ = elv_angle, φ = shoulder_elv, ψ = shoulder_rot)."""
        theta, phi, psi = np.broadcast_arrays(np.atleast_1d(np.asarray(theta, dtype=np.float64)),
                                              np.asarray(phi, dtype=np.float64),
                                              np.asarray(psi, dtype=np.float64))
        rotation = ms_to_matrix(theta, phi, psi)  # (N, 3, 3) thorax ← humerus
        crossing = np.empty((theta.shape[0], len(self.tendons)))
        for j, tendon in enumerate(self.tendons):
            first_on_arm = rotation @ tendon.humerus_points_mm[0]  # (N, 3) thorax frame
            crossing[:, j] = wrapped_length(tendon.thorax_points_mm[-1], first_on_arm,
                                            self.cap_centre_mm, self.cap_radius_mm)
        return crossing + self.rigid_lengths_mm()
