"""Kinematics layer: pure math for shoulder conventions, conversions and arm geometry. No I/O.

Radians everywhere; degrees only at the edges (CLI, files). See docs/conventions.md.
"""

if __name__ != "exohil.kinematics":  # e.g. `import kinematics` from the repository root
    raise ImportError(f"import exohil.kinematics, not {__name__}: the folder is a subpackage of "
                      "exohil, and a second copy of its modules would not share their classes")

from exohil.kinematics.arm import humerus_angles, humerus_direction
from exohil.kinematics.robot import NAO_JOINTS, NAO_LIMITS, NaoArm, humerus_to_nao, quat_to_zyx
from exohil.kinematics.rotations import (
    matrix_to_quat,
    normalize_quat,
    quat_multiply,
    quat_to_matrix,
    rotation_angle_between,
)
from exohil.kinematics.shoulder import (
    MOBL_RANGES,
    OBSERVABLE_ELEVATION_DEG,
    isb_to_ms,
    isb_to_quat,
    ms_to_isb,
    ms_to_matrix,
    ms_to_quat,
    quat_to_isb,
    quat_to_ms,
)

__all__ = [
    "MOBL_RANGES",
    "NAO_JOINTS",
    "NAO_LIMITS",
    "NaoArm",
    "OBSERVABLE_ELEVATION_DEG",
    "humerus_angles",
    "humerus_direction",
    "humerus_to_nao",
    "isb_to_ms",
    "isb_to_quat",
    "matrix_to_quat",
    "ms_to_isb",
    "ms_to_matrix",
    "ms_to_quat",
    "normalize_quat",
    "quat_multiply",
    "quat_to_isb",
    "quat_to_matrix",
    "quat_to_ms",
    "quat_to_zyx",
    "rotation_angle_between",
]
