"""Where a simulated robot's arm was during a session, sampled for scoring and pictures.

:class:`RobotTraceSink` is a pipeline sink placed after the teleoperation sink: at most
``rate_hz`` times per second of device time it reads the robot's upper-arm axis and body
positions (e.g. a running :class:`~exohil.harness.robot_mujoco.MujocoNao`) and keeps them with
the frame's device time, in a fixed-size numpy ring (the oldest samples go first; 4 + 3·B
float64 per sample for B bodies, 296 B for the 11 NAO bodies: an hour's 90,000 samples hold
27 MB, allocated at the first sample). The true arm pose is known only after the run, by
device time (``session.truth_at``), so the samples are scored
afterwards: :meth:`RobotTrace.axis_error_deg`.

Frames and units: NAO torso frame (X forward, Y left, Z up), metres; device time in seconds;
angles in degrees.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np

from exohil.harness.pipeline import Sample
from exohil.harness.robot_render import ArmSample, human_upper_arm_direction

#: Default sampling rate, per second of device time.
TRACE_RATE_HZ = 25.0
#: Default bound on the samples kept: an hour at 25 Hz.
TRACE_MAX_SAMPLES = 90_000


class TracedRobot(Protocol):
    """A robot whose arm can be read (``MujocoNao``)."""

    side: Literal["right", "left"]

    def body_positions(self) -> dict[str, np.ndarray]: ...

    def upper_arm_axis(self, line: Literal["elbow", "axis"] = "elbow") -> np.ndarray: ...


@dataclass(frozen=True)
class RobotTrace:
    """The robot's arm at sampled frames.

    Attributes:
        device_time_s: (K,) device time of the frame after whose command the robot was read, s.
        axis: (K, 3) the robot's upper-arm axis (``upper_arm_axis("axis")``, the line the
            mapping points along the humerus), unit vectors, NAO torso frame.
        bodies: (K, B, 3) positions of ``body_names``, m, NAO torso frame.
        body_names: the B bodies.
        side: the teleoperated arm.
        truth_deg: (K, 2) true (elv_angle θ, shoulder_elv φ) at ``device_time_s``, degrees,
            NaN where the reference has no motion capture; None without a reference.
    """

    device_time_s: np.ndarray
    axis: np.ndarray
    bodies: np.ndarray
    body_names: tuple[str, ...]
    side: Literal["right", "left"]
    truth_deg: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.device_time_s.shape[0])

    def human_axes(self) -> np.ndarray:
        """(K, 3) true human upper-arm directions, NAO torso frame; NaN where unknown."""
        out = np.full((len(self), 3), np.nan)
        if self.truth_deg is None:
            return out
        for k, (theta, phi) in enumerate(self.truth_deg):
            if math.isfinite(theta) and math.isfinite(phi):
                out[k] = human_upper_arm_direction(float(theta), float(phi), self.side)
        return out

    def axis_error_deg(self) -> np.ndarray:
        """(K,) angle between the robot's upper-arm axis and the true humerus, degrees (NaN
        where the truth is unknown)."""
        human = self.human_axes()
        cross = np.linalg.norm(np.cross(self.axis, human), axis=1)
        return np.degrees(np.arctan2(cross, np.einsum("ij,ij->i", self.axis, human)))

    def arm_samples(self, indices: np.ndarray) -> list[ArmSample]:
        """Pictures' content (``robot_render``) at the given sample indices with known truth."""
        human = self.human_axes()
        return [ArmSample(t=float(self.device_time_s[k]),
                          bodies=dict(zip(self.body_names, self.bodies[k], strict=True)),
                          humerus=human[k], side=self.side, robot_axis=self.axis[k])
                for k in indices if np.all(np.isfinite(human[k]))]


class RobotTraceSink:
    """Pipeline sink sampling ``robot`` (see the module docstring).

    Args:
        robot: the robot to read; must be the one the teleoperation sink before this one
            commands.
        rate_hz: samples per second of device time (> 0).
        max_samples: samples kept; older ones are dropped first (≥ 1).
    """

    def __init__(self, robot: TracedRobot, rate_hz: float = TRACE_RATE_HZ,
                 max_samples: int = TRACE_MAX_SAMPLES) -> None:
        if not (math.isfinite(rate_hz) and rate_hz > 0):
            raise ValueError(f"rate_hz must be positive, got {rate_hz!r}")
        if max_samples < 1:
            raise ValueError(f"max_samples must be >= 1, got {max_samples!r}")
        self.robot = robot
        self.period_s = 1.0 / rate_hz
        self.max_samples = max_samples
        self._names: tuple[str, ...] = ()
        self._times = np.empty(0)
        self._axes = np.empty((0, 3))
        self._bodies = np.empty((0, 0, 3))
        self._count = 0  # samples taken; the ring holds the last min(count, max_samples)
        self._anchor_s: float | None = None  # sampling grid: anchor + k · period
        self._next_s = -math.inf

    def accept(self, sample: Sample) -> None:
        """Read the robot when the frame's device time reaches the next grid point (or went
        back before the last one: the grid restarts there)."""
        t = sample.frame.device_time_s
        if self._anchor_s is None or t < self._next_s - self.period_s:
            self._anchor_s = t
        elif t < self._next_s:
            return
        self._add(t, self.robot.upper_arm_axis("axis"), self.robot.body_positions())
        periods = math.floor((t - self._anchor_s) / self.period_s + 1e-9) + 1
        self._next_s = self._anchor_s + periods * self.period_s

    def _add(self, t: float, axis: np.ndarray, bodies: dict[str, np.ndarray]) -> None:
        if self._count == 0:  # the ring is sized by the robot's bodies, known now
            self._names = tuple(bodies)
            self._times = np.empty(self.max_samples)
            self._axes = np.empty((self.max_samples, 3))
            self._bodies = np.empty((self.max_samples, len(self._names), 3))
        k = self._count % self.max_samples
        self._times[k] = t
        self._axes[k] = axis
        for b, name in enumerate(self._names):
            self._bodies[k, b] = bodies[name]
        self._count += 1

    def close(self) -> None:
        """Nothing to release (the teleoperation sink closes the robot)."""

    def trace(self) -> RobotTrace:
        """The samples kept so far, oldest first (copies)."""
        kept = min(self._count, self.max_samples)
        order = (np.arange(kept) + self._count - kept) % self.max_samples if kept else \
            np.arange(0)
        return RobotTrace(
            device_time_s=self._times[order], axis=self._axes[order].reshape(-1, 3),
            bodies=self._bodies[order].reshape(-1, len(self._names), 3),
            body_names=self._names, side=self.robot.side)
