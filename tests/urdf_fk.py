"""Independent forward kinematics of NAO's arms, straight from the URDF (xml.etree + NumPy).

Test helper: shares no code with exohil. Frames: NAO torso (X forward, Y left, Z up), metres,
radians. Each URDF joint is ``T_parent←child(q) = Trans(xyz) · RPY(rpy) · Rot(axis, q)``.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
URDF = ROOT / "fixtures" / "robots" / "nao" / "nao_v50.urdf"


@dataclass(frozen=True)
class Joint:
    name: str
    parent: str
    child: str
    xyz: np.ndarray
    rpy: np.ndarray
    axis: np.ndarray
    lower: float
    upper: float


def load_joints(path: Path = URDF) -> dict[str, Joint]:
    """Every joint of the URDF by child link name."""
    joints = {}
    for j in ET.parse(path).getroot().findall("joint"):
        origin, axis, limit = j.find("origin"), j.find("axis"), j.find("limit")
        joints[j.find("child").get("link")] = Joint(
            name=j.get("name"),
            parent=j.find("parent").get("link"),
            child=j.find("child").get("link"),
            xyz=np.array([float(v) for v in origin.get("xyz", "0 0 0").split()]),
            rpy=np.array([float(v) for v in origin.get("rpy", "0 0 0").split()]),
            axis=np.array([float(v) for v in (axis.get("xyz") if axis is not None
                                             else "1 0 0").split()]),
            lower=float(limit.get("lower")) if limit is not None else 0.0,
            upper=float(limit.get("upper")) if limit is not None else 0.0,
        )
    return joints


def axis_angle(axis: np.ndarray, q) -> np.ndarray:
    """Rodrigues rotation matrices ``(..., 3, 3)`` about a unit ``axis`` by ``q``."""
    q = np.asarray(q, dtype=float)
    k = axis / np.linalg.norm(axis)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    s, c = np.sin(q)[..., None, None], np.cos(q)[..., None, None]
    return np.eye(3) + s * kx + (1.0 - c) * (kx @ kx)


def rpy_matrix(rpy: np.ndarray) -> np.ndarray:
    """URDF fixed-axis roll-pitch-yaw: Rz(yaw) · Ry(pitch) · Rx(roll)."""
    return (axis_angle(np.array([0.0, 0.0, 1.0]), rpy[2])
            @ axis_angle(np.array([0.0, 1.0, 0.0]), rpy[1])
            @ axis_angle(np.array([1.0, 0.0, 0.0]), rpy[0]))


def chain(joints: dict[str, Joint], link: str, base: str = "torso") -> list[Joint]:
    """Joints from ``base`` down to ``link``, in order."""
    out = []
    while link != base:
        joint = joints[link]
        out.append(joint)
        link = joint.parent
    return out[::-1]


def link_pose(joints: dict[str, Joint], link: str, q: dict[str, np.ndarray]):
    """(R ``(..., 3, 3)``, p ``(..., 3)``) of ``link`` in the torso frame; ``q`` by joint name,
    missing revolute joints at 0."""
    shape = np.broadcast_shapes(*(np.shape(v) for v in q.values())) if q else ()
    rot = np.broadcast_to(np.eye(3), shape + (3, 3))
    pos = np.zeros(shape + (3,))
    for joint in chain(joints, link):
        pos = pos + rot @ joint.xyz
        rot = rot @ rpy_matrix(joint.rpy) @ axis_angle(joint.axis, q.get(joint.name, 0.0))
    return rot, pos


def upper_arm_x_axis(joints: dict[str, Joint], side: str, pitch, roll) -> np.ndarray:
    """The commanded line: X axis of the ``{R,L}Bicep`` link in the torso frame, ``(..., 3)``."""
    s = "R" if side == "right" else "L"
    q = {f"{s}ShoulderPitch": np.asarray(pitch), f"{s}ShoulderRoll": np.asarray(roll)}
    rot, _ = link_pose(joints, f"{s}Bicep", q)
    return rot[..., :, 0]
