"""Teleoperation sink: estimated shoulder angles → NAO arm joint commands.

The chain is the paper's: MoBL-ARMS (θ, φ, ψ) → ISB Y-X'-Y'' → quaternion → NAO joints, with
the coupled MS→ISB convention (docs/conventions.md). The estimator gives θ and φ only; the axial
rotation ψ is held at a fixed value (0 by default). The previous command is the hint at the
NAO roll singularity, so the command stream stays continuous.

Commands go to a :class:`JointTarget`; :class:`SimulatedNao` is the bundled one (it keeps the
commanded joint state and counts what was clamped). A robot bridge (e.g. CoppeliaSim's remote
API) would implement the same one-method protocol.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from exohil.kinematics import NAO_JOINTS, humerus_to_nao, ms_to_quat
from exohil.kinematics.robot import Side


class JointTarget(Protocol):
    """Anything that accepts NAO arm joint commands (radians, NAO_JOINTS order)."""

    def command(self, t: float, joints: np.ndarray, clamped: np.ndarray) -> None: ...


@dataclass
class SimulatedNao:
    """A stand-in NAO arm: remembers the last command and counts commands and clamps."""

    side: Side = "right"
    joints: np.ndarray = field(default_factory=lambda: np.array([np.pi / 2, 0.0, 0.0]))
    commands: int = 0
    clamped_commands: int = 0
    clamped_per_joint: np.ndarray = field(default_factory=lambda: np.zeros(3, dtype=int))

    def command(self, t: float, joints: np.ndarray, clamped: np.ndarray) -> None:
        self.joints = joints
        self.commands += 1
        if clamped.any():
            self.clamped_commands += 1
            self.clamped_per_joint += clamped

    def summary(self) -> dict:
        """Counts and the last joint state, degrees, for reports."""
        prefix = "R" if self.side == "right" else "L"
        return {
            "commands": self.commands,
            "clamped_commands": self.clamped_commands,
            "clamped_per_joint": {
                f"{prefix}{name}": int(n)
                for name, n in zip(NAO_JOINTS, self.clamped_per_joint, strict=True)
            },
            "last_joints_deg": {
                f"{prefix}{name}": round(float(np.rad2deg(v)), 3)
                for name, v in zip(NAO_JOINTS, self.joints, strict=True)
            },
        }


class TeleopSink:
    """Turns each (θ, φ) estimate (degrees) into a NAO command on ``target``."""

    def __init__(self, target: JointTarget, side: Side = "right",
                 shoulder_rot_deg: float = 0.0) -> None:
        self.target = target
        self.side = side
        self.psi = np.deg2rad(shoulder_rot_deg)
        self._previous: np.ndarray | None = None

    def accept(self, t: float, elv_angle_deg: float, shoulder_elv_deg: float) -> np.ndarray:
        """Send one command; returns the joint angles (rad) that were commanded."""
        q = ms_to_quat(np.deg2rad(elv_angle_deg), np.deg2rad(shoulder_elv_deg), self.psi)
        arm = humerus_to_nao(q, side=self.side, hint=self._previous)
        self._previous = arm.unclamped
        self.target.command(t, arm.angles, arm.clamped)
        return arm.angles
