"""Teleoperation sink: estimated shoulder angles → NAO arm joint commands.

The chain is the paper's: MoBL-ARMS (θ, φ, ψ) → ISB Y-X'-Y'' → quaternion → NAO joints, with
the coupled MS→ISB convention (docs/conventions.md). The estimator gives θ and φ only; the axial
rotation ψ is held at a fixed value (0 by default). The previous command is the hint at the
NAO roll singularity, so the command stream stays continuous there; where a joint must choose
between its two limits (the arm behind the shoulder, an elbow yaw beyond ±119.5°) the previous
command's limit is kept until the other is nearer by more than :data:`HYSTERESIS_DEG`, so an
estimate that wavers across the boundary does not swing the joint from limit to limit.

:class:`TeleopSink` is a pipeline sink; it sends each command to its robot targets, anything
implementing :class:`JointTarget`: :class:`SimulatedNao` (keeps the commanded joint state and
counts clamps), the MuJoCo arm, the UDP/JSON bridge, CoppeliaSim.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from exohil.harness.pipeline import RobotCommand, Sample
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


#: The estimator outputs the teleoperation needs: MoBL-ARMS θ (plane of elevation), φ (elevation).
SHOULDER_ANGLES = ("elv_angle", "shoulder_elv")


#: How much nearer (deg) the other limit must be before a stream leaves its pitch or elbow-yaw
#: limit (``humerus_to_nao``'s ``hysteresis``), and so the most the arm may sit off the nearest
#: command there. Overhead the wanted elbow yaw turns at twice θ's rate (2θ + 180° at φ = 150°,
#: ψ = 0), and θ's error grows as 1/sin φ; 10° keeps a ±2° wavering θ there on one limit.
HYSTERESIS_DEG = 10.0


class TeleopSink:
    """A pipeline sink: each (θ, φ) estimate → one NAO command on every robot target.

    Args:
        targets: robots that receive the commands (simulated, MuJoCo, UDP, ...).
        angle_names: the estimator's output names, in order (a checkpoint's
            ``target.angles``); θ and φ are taken from them by name.
        side: arm side.
        shoulder_rot_deg: the axial rotation ψ to assume (the suit does not measure it), deg.

    Raises:
        ValueError: when ``angle_names`` lacks ``elv_angle`` or ``shoulder_elv``.
    """

    def __init__(self, targets: Sequence[JointTarget], angle_names: Sequence[str],
                 side: Side = "right", shoulder_rot_deg: float = 0.0) -> None:
        missing = [a for a in SHOULDER_ANGLES if a not in angle_names]
        if missing:
            raise ValueError(f"teleoperation needs the shoulder angles {', '.join(missing)}; "
                             f"the estimator gives {', '.join(angle_names) or 'nothing'}")
        self.targets = list(targets)
        self.side = side
        self.psi = np.deg2rad(shoulder_rot_deg)
        self._theta = list(angle_names).index("elv_angle")
        self._phi = list(angle_names).index("shoulder_elv")
        self._previous: np.ndarray | None = None

    def command_for(self, elv_angle_deg: float, shoulder_elv_deg: float) -> RobotCommand:
        """The NAO command for one pose (continuous with the previous one), not sent."""
        q = ms_to_quat(np.deg2rad(elv_angle_deg), np.deg2rad(shoulder_elv_deg), self.psi)
        arm = humerus_to_nao(q, side=self.side, hint=self._previous,
                             hysteresis=np.deg2rad(HYSTERESIS_DEG))
        self._previous = arm.angles
        return RobotCommand(joints=arm.angles, clamped=arm.clamped)

    def accept(self, sample: Sample) -> None:
        command = self.command_for(sample.angles[self._theta], sample.angles[self._phi])
        for target in self.targets:
            target.command(sample.frame.device_time_s, command.joints, command.clamped)
        sample.command = command
        sample.stamps["commanded"] = time.perf_counter_ns()

    def close(self) -> None:
        for target in self.targets:
            close = getattr(target, "close", None)
            if close is not None:
                close()
