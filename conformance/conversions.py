"""The conversion properties the ``conversions`` check runs under hypothesis.

Each property compares exohil's kinematics (called through their modules, so a change to any
of them is what gets measured) against an oracle written here from first principles, or
checks a round trip, over the whole range including the singular poses:

* MoBL-ARMS → quaternion → MoBL-ARMS round trip (φ away from 0 and π, where θ is undefined);
* any unit quaternion → ISB Y-X'-Y'' → quaternion round trip, exactly singular ones included;
* the humerus axis of MoBL-ARMS (θ, φ, ψ) equals the closed form
  (sin φ sin θ, −cos φ, sin φ cos θ) in the ISB thorax frame (catches sign errors that a
  round trip cannot see);
* at φ = 0 the orientation does not depend on θ;
* the whole orientation (axial rotation included, which the humerus axis cannot see) of
  MoBL-ARMS (θ, φ, ψ) equals R_y(θ) · R_x(−φ) · R_y(ψ − θ) built here from elementary
  rotations, at random poses and at every pose of docs/conventions.md's table; and any
  quaternion's MoBL-ARMS and ISB angles rebuild that quaternion's rotation through the same
  elementary rotations (catches an offset on the axial rotation that cancels in round trips);
* Z-Y'-X'' angles rebuild the same rotation;
* an unclamped NAO command points the robot's upper arm exactly along the human humerus, and
  a clamped one stays within NAO's joint limits;
* an unclamped NAO command, on either arm, reproduces the whole humerus orientation (elbow
  yaw included, which the direction cannot see) against the NAO arm frame built here from the
  documented frames and the hanging pose.

Runs are reproducible: a fixed seed, a set number of examples, no example database.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from hypothesis import HealthCheck, example, given, seed, settings
from hypothesis import strategies as st

from exohil.kinematics import robot, rotations, shoulder

ANGLE = st.floats(-math.pi, math.pi, allow_nan=False)
ELEVATION = st.floats(1e-3, math.pi - 1e-3, allow_nan=False)
UNIT = st.floats(-1.0, 1.0, allow_nan=False)
#: tolerance of round trips and oracles, degrees
TOLERANCE_DEG = 1e-6


@dataclass
class PropertyResult:
    """One property: how many examples ran, the largest error seen (deg), and the failure."""

    name: str
    examples: int
    max_error_deg: float
    failure: str | None


def _angle_between(a: np.ndarray, b: np.ndarray) -> float:
    """Angle between two vectors, deg (atan2 form: accurate near 0)."""
    return math.degrees(math.atan2(float(np.linalg.norm(np.cross(a, b))), float(np.dot(a, b))))


def _rotation_error_deg(q1: np.ndarray, q2: np.ndarray) -> float:
    """Angle of the rotation between two unit quaternions, deg (accurate near 0; q ≡ −q)."""
    q1, q2 = q1 / np.linalg.norm(q1), q2 / np.linalg.norm(q2)
    chord = min(float(np.linalg.norm(q1 - q2)), float(np.linalg.norm(q1 + q2)))
    return math.degrees(4.0 * math.asin(min(1.0, chord / 2.0)))


def _rx(angle: float) -> np.ndarray:
    """Active rotation by ``angle`` (rad) about X: ``v' = R v`` in the frame it is given in."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _ry(angle: float) -> np.ndarray:
    """Active rotation by ``angle`` (rad) about Y."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _ms_matrix(theta: float, phi: float, psi: float) -> np.ndarray:
    """Thorax ← humerus rotation of MoBL-ARMS (θ, φ, ψ) (rad), ideal axes, coupled form:
    intrinsic R_y(θ) · R_x(−φ) · R_y(ψ − θ) in the ISB thorax frame (X anterior, Y superior,
    Z lateral; docs/conventions.md, "Why the coupled form")."""
    return _ry(theta) @ _rx(-phi) @ _ry(psi - theta)


def _isb_matrix(alpha: float, beta: float, gamma: float) -> np.ndarray:
    """Thorax ← humerus rotation of ISB Y-X'-Y'' angles (α, β, γ) (rad)."""
    return _ry(alpha) @ _rx(beta) @ _ry(gamma)


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrix of a quaternion (x, y, z, w), normalised first (the textbook form)."""
    x, y, z, w = np.asarray(q, dtype=float) / float(np.linalg.norm(q))
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def _matrix_error_deg(m1: np.ndarray, m2: np.ndarray) -> float:
    """Angle of the rotation between two rotation matrices, deg: ‖R₁ − R₂‖_F = 2√2 sin(δ/2)
    (accurate near 0, and defined at every pose, singular ones included)."""
    chord = float(np.linalg.norm(m1 - m2)) / (2.0 * math.sqrt(2.0))
    return math.degrees(2.0 * math.asin(min(1.0, chord)))


#: (θ, φ, ψ), deg: the poses of docs/conventions.md's table "Example poses", singular ones
#: (φ = 0) included.
CONVENTION_TABLE_POSES_DEG = ((0, 0, 0), (0, 90, 0), (90, 90, 0), (-90, 45, 0), (45, 60, -30),
                              (130, 120, 20), (-40, 30, -90), (90, 0, 10))


def _quaternion(x: float, y: float, z: float, w: float) -> np.ndarray | None:
    q = np.array([x, y, z, w])
    n = np.linalg.norm(q)
    return None if n < 1e-3 else q / n


class _Tracker:
    def __init__(self) -> None:
        self.examples = 0
        self.max_error = 0.0

    def error(self, value_deg: float, what: str) -> None:
        self.examples += 1
        self.max_error = max(self.max_error, value_deg)
        assert value_deg <= TOLERANCE_DEG, f"{what}: error {value_deg:.3g} deg"


def _ms_quat_roundtrip(t: _Tracker) -> Callable[..., None]:
    @given(ANGLE, ELEVATION, ANGLE)
    def prop(theta: float, phi: float, psi: float) -> None:
        back = shoulder.quat_to_ms(shoulder.ms_to_quat(theta, phi, psi))
        err = max(abs(math.remainder(a - b, 2 * math.pi)) for a, b in
                  zip((theta, phi, psi), back, strict=True))
        t.error(math.degrees(err), f"MS {theta, phi, psi} -> quat -> MS {tuple(back)}")
    return prop


def _quat_isb_roundtrip(t: _Tracker) -> Callable[..., None]:
    singular = st.sampled_from([(0.0, 0.0, 0.0, 1.0), (0.0, 1.0, 0.0, 0.0),
                                (0.0, math.sqrt(0.5), 0.0, math.sqrt(0.5)),
                                (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 1.0, 0.0)])

    @given(st.one_of(st.tuples(UNIT, UNIT, UNIT, UNIT), singular))
    def prop(xyzw: tuple[float, float, float, float]) -> None:
        q = _quaternion(*xyzw)
        if q is None:
            return
        back = shoulder.isb_to_quat(shoulder.quat_to_isb(q))
        t.error(_rotation_error_deg(q, back), f"quat {tuple(q)} -> ISB -> quat")
    return prop


def _humerus_axis_oracle(t: _Tracker) -> Callable[..., None]:
    @given(ANGLE, st.floats(0.0, math.pi, allow_nan=False), ANGLE)
    def prop(theta: float, phi: float, psi: float) -> None:
        m = rotations.quat_to_matrix(shoulder.ms_to_quat(theta, phi, psi))
        axis = m @ np.array([0.0, -1.0, 0.0])  # humerus: shoulder → elbow is −Y
        oracle = np.array([math.sin(phi) * math.sin(theta), -math.cos(phi),
                           math.sin(phi) * math.cos(theta)])
        t.error(_angle_between(axis, oracle), f"humerus axis of MS {theta, phi, psi}")
    return prop


def _hanging_pose(t: _Tracker) -> Callable[..., None]:
    @given(ANGLE, ANGLE, ANGLE)
    def prop(theta1: float, theta2: float, psi: float) -> None:
        q1 = shoulder.ms_to_quat(theta1, 0.0, psi)
        q2 = shoulder.ms_to_quat(theta2, 0.0, psi)
        t.error(_rotation_error_deg(q1, q2), f"hanging arm, θ {theta1} vs {theta2}")
    return prop


def _orientation_oracle(t: _Tracker) -> Callable[..., None]:
    def prop(theta: float, phi: float, psi: float) -> None:
        m = _quat_matrix(shoulder.ms_to_quat(theta, phi, psi))
        t.error(_matrix_error_deg(m, _ms_matrix(theta, phi, psi)),
                f"orientation of MS {theta, phi, psi}")

    for pose in CONVENTION_TABLE_POSES_DEG:  # run first, before the generated examples
        prop = example(*(math.radians(v) for v in pose))(prop)
    return given(ANGLE, st.floats(0.0, math.pi, allow_nan=False), ANGLE)(prop)


def _angles_rebuild_orientation(t: _Tracker) -> Callable[..., None]:
    singular = st.sampled_from([(0.0, 0.0, 0.0, 1.0), (0.0, 1.0, 0.0, 0.0),
                                (0.0, math.sqrt(0.5), 0.0, math.sqrt(0.5)),
                                (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 1.0, 0.0)])

    @given(st.one_of(st.tuples(UNIT, UNIT, UNIT, UNIT), singular), ANGLE)
    def prop(xyzw: tuple[float, float, float, float], hint: float) -> None:
        q = _quaternion(*xyzw)
        if q is None:
            return
        m = _quat_matrix(q)
        given_q = tuple(round(float(v), 12) for v in q)
        theta, phi, psi = (float(v) for v in shoulder.quat_to_ms(q, hint))
        t.error(_matrix_error_deg(m, _ms_matrix(theta, phi, psi)),
                f"quat {given_q} -> MS {theta, phi, psi} -> rotation")
        alpha, beta, gamma = (float(v) for v in shoulder.quat_to_isb(q, hint))
        t.error(_matrix_error_deg(m, _isb_matrix(alpha, beta, gamma)),
                f"quat {given_q} -> ISB {alpha, beta, gamma} -> rotation")
    return prop


def _zyx_rebuild(t: _Tracker) -> Callable[..., None]:
    @given(st.tuples(UNIT, UNIT, UNIT, UNIT))
    def prop(xyzw: tuple[float, float, float, float]) -> None:
        q = _quaternion(*xyzw)
        if q is None:
            return
        yaw, pitch, roll = robot.quat_to_zyx(q)
        m = (rotations.elementary_matrix(rotations.Z, yaw)
             @ rotations.elementary_matrix(rotations.Y, pitch)
             @ rotations.elementary_matrix(rotations.X, roll))
        back = rotations.matrix_to_quat(m)
        t.error(_rotation_error_deg(q, back), f"quat {tuple(q)} -> Z-Y'-X'' -> rotation")
    return prop


def _nao_direction(t: _Tracker) -> Callable[..., None]:
    @given(ANGLE, st.floats(0.0, math.pi, allow_nan=False))
    def prop(theta: float, phi: float) -> None:
        arm = robot.humerus_to_nao(shoulder.ms_to_quat(theta, phi, 0.0), side="right")
        low, high = robot.NAO_LIMITS["right"][:, 0], robot.NAO_LIMITS["right"][:, 1]
        assert np.all(arm.angles >= low - 1e-12) and np.all(arm.angles <= high + 1e-12), \
            f"command {arm.angles} outside NAO's limits"
        if arm.any_clamped:
            t.examples += 1
            return
        pitch, roll = float(arm.angles[0]), float(arm.angles[1])
        # NAO torso frame X forward, Y left, Z up; ShoulderPitch about Y, then roll about Z'
        robot_axis = np.array([math.cos(pitch) * math.cos(roll), math.sin(roll),
                               -math.sin(pitch) * math.cos(roll)])
        human = np.array([math.sin(phi) * math.sin(theta), -math.sin(phi) * math.cos(theta),
                          -math.cos(phi)])
        t.error(_angle_between(robot_axis, human), f"NAO arm for MS {theta, phi}")
    return prop


#: NAO torso ← ISB thorax, from the two frames' definitions (NAO: X forward, Y left, Z up;
#: ISB: X anterior, Y superior, Z lateral-right): x = x, y = −z, z = y.
_NAO_TORSO_FROM_THORAX = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
#: The mirror through the sagittal plane (NAO's Y → −Y): the right arm's pose → the left's.
_SAGITTAL_MIRROR = np.diag([1.0, -1.0, 1.0])


def _rz(angle: float) -> np.ndarray:
    """Active rotation by ``angle`` (rad) about Z."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _nao_arm_oracle(theta: float, phi: float, psi: float, side: robot.Side) -> np.ndarray:
    """NAO torso ← upper arm rotation that reproduces MoBL-ARMS (θ, φ, ψ) (rad) on ``side``.

    The arm frames are tied by the documented pose with the arm hanging: the humerus frame
    equals the thorax frame there, and NAO's command is pitch +90°, roll 0, elbow yaw 0
    (docs/conventions.md), so arm ← humerus is fixed as (torso ← thorax)ᵀ · R_y(90°). The left
    arm is the mirror image of the right one (same angles, mirrored ISB frame)."""
    humerus_from_arm = _NAO_TORSO_FROM_THORAX.T @ _ry(math.pi / 2)
    right = _NAO_TORSO_FROM_THORAX @ _ms_matrix(theta, phi, psi) @ humerus_from_arm
    return right if side == "right" else _SAGITTAL_MIRROR @ right @ _SAGITTAL_MIRROR


def _nao_orientation(t: _Tracker) -> Callable[..., None]:
    @given(ANGLE, st.floats(0.0, math.pi, allow_nan=False), ANGLE,
           st.sampled_from(["right", "left"]))
    def prop(theta: float, phi: float, psi: float, side: robot.Side) -> None:
        arm = robot.humerus_to_nao(shoulder.ms_to_quat(theta, phi, psi), side=side)
        if arm.any_clamped:
            return
        pitch, roll, yaw = (float(v) for v in arm.angles)
        commanded = _ry(pitch) @ _rz(roll) @ _rx(yaw)  # ShoulderPitch, -Roll, ElbowYaw
        t.error(_matrix_error_deg(commanded, _nao_arm_oracle(theta, phi, psi, side)),
                f"NAO {side} arm orientation for MS {theta, phi, psi}")
    return prop


PROPERTIES: dict[str, Callable[[_Tracker], Callable[..., None]]] = {
    "ms_quat_roundtrip": _ms_quat_roundtrip,
    "quat_isb_roundtrip": _quat_isb_roundtrip,
    "humerus_axis_oracle": _humerus_axis_oracle,
    "hanging_pose_ignores_plane": _hanging_pose,
    "orientation_oracle": _orientation_oracle,
    "angles_rebuild_orientation": _angles_rebuild_orientation,
    "zyx_rebuilds_rotation": _zyx_rebuild,
    "nao_points_along_humerus": _nao_direction,
    "nao_reproduces_orientation": _nao_orientation,
}


def run_properties(examples: int, seed_value: int) -> list[PropertyResult]:
    """Run every property with ``examples`` examples each from ``seed_value``."""
    results = []
    for name, build in PROPERTIES.items():
        tracker = _Tracker()
        test = settings(max_examples=examples, database=None, deadline=None, derandomize=False,
                        suppress_health_check=list(HealthCheck))(seed(seed_value)(build(tracker)))
        failure = None
        try:
            test()
        except AssertionError as err:
            failure = str(err).splitlines()[0]
        results.append(PropertyResult(name, tracker.examples, tracker.max_error, failure))
    return results
