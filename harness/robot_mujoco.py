"""A simulated NAO arm in MuJoCo that follows teleoperation commands in real time.

:class:`MujocoNao` implements the :class:`~exohil.harness.teleop.JointTarget` protocol. The
model is the committed MJCF of NAO's torso and arms (``fixtures/robots/nao/``, generated from
NAO's URDF by :mod:`exohil.harness.robot_model`). One ``side``'s ShoulderPitch, ShoulderRoll
and ElbowYaw follow the commands through position servos; its ElbowRoll and the other arm
hold a fixed pose.

Threads: the physics steps in its own thread, one ``mj_step`` per period of wall time
(``1 / rate_hz``, 500 Hz by default) on absolute deadlines, so simulated time keeps up with
wall time. :meth:`MujocoNao.command` only swaps the newest command in under a lock; a command
that arrives before the previous one was stepped replaces it (counted as superseded).

Frames and units: NAO torso frame (X forward, Y left, Z up), metres, radians; the summary
reports degrees and milliseconds. Memory is bounded: statistics live in fixed-size
histograms (:class:`~exohil.harness.robot_stats.LogHistogram`), so a run may last hours.
"""

from __future__ import annotations

import math
import threading
import time
from pathlib import Path
from typing import Literal

import mujoco
import numpy as np

from exohil.harness.robot_model import ARM_JOINTS, NAO_ARMS_MJCF
from exohil.harness.robot_stats import LogHistogram
from exohil.kinematics import NAO_JOINTS
from exohil.realtime import sleep_until

#: Bodies of the model, in the order of :meth:`MujocoNao.body_positions`.
BODIES = ("torso", "RShoulder", "RBicep", "RElbow", "RForeArm", "r_wrist",
          "LShoulder", "LBicep", "LElbow", "LForeArm", "l_wrist")
#: Commands within this much (rad) beyond a limit are clipped without counting as out of
#: range: the URDF's limits are rounded to 6 decimals (e.g. −1.32645 rad for NAO's −76°).
LIMIT_TOLERANCE = 1e-6
#: When the physics thread is this far behind its schedule (s), it skips ahead instead of
#: catching up in a burst (counted as skipped steps; simulated time then lags wall time).
MAX_CATCH_UP_S = 0.1


class MujocoNao:
    """NAO arm target simulated by MuJoCo (see the module docstring).

    Args:
        side: "right" or "left": the arm that follows the commands.
        model_path: MJCF with the joints and actuators of :mod:`~exohil.harness.robot_model`.
        rate_hz: physics steps per second of wall time; the model's time step is set to
            ``1 / rate_hz``. At least 500.
        elbow_roll: ElbowRoll held by the commanded arm, radians (default: 2°, nearly
            straight; mirrored for the left arm), clipped to its limits.
        rest: (ShoulderPitch, ShoulderRoll, ElbowYaw) radians of the start pose and of the
            other arm (default: hanging, pitch 90°), mirrored for the left arm.
    """

    def __init__(self, side: Literal["right", "left"] = "right", *,
                 model_path: str | Path = NAO_ARMS_MJCF, rate_hz: float = 500.0,
                 elbow_roll: float = math.radians(2.0),
                 rest: tuple[float, float, float] = (math.pi / 2, 0.0, 0.0)) -> None:
        if side not in ("right", "left"):
            raise ValueError(f"side must be 'right' or 'left', got {side!r}")
        if np.shape(rest) != (3,) or not np.isfinite(rest).all() \
                or not math.isfinite(elbow_roll):
            raise ValueError(f"rest must be 3 finite joint angles and elbow_roll finite, "
                             f"radians; got {rest!r}, {elbow_roll!r}")
        if not (math.isfinite(rate_hz) and rate_hz >= 500.0):
            raise ValueError(f"rate_hz must be a finite number >= 500, got {rate_hz!r}")
        self.side = side
        self.prefix = "R" if side == "right" else "L"
        self.rate_hz = float(rate_hz)
        self.model = mujoco.MjModel.from_xml_path(str(model_path))
        self.model.opt.timestep = 1.0 / self.rate_hz
        self.data = mujoco.MjData(self.model)
        mirror = {"R": np.ones(4), "L": np.array([1.0, -1.0, -1.0, -1.0])}
        self._act, self._qadr = {}, {}
        for p in "RL":
            names = [f"{p}{j}" for j in ARM_JOINTS]
            self._act[p] = np.array([mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_ACTUATOR,
                                                       n) for n in names])
            joint_ids = [mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_JOINT, n)
                         for n in names]
            if min(self._act[p]) < 0 or min(joint_ids) < 0:
                raise ValueError(f"{model_path}: lacks the joints/actuators {names}")
            self._qadr[p] = self.model.jnt_qposadr[joint_ids]
            pose = np.array([*rest, elbow_roll]) * mirror[p]
            ranges = self.model.actuator_ctrlrange[self._act[p]]
            pose = np.clip(pose, ranges[:, 0], ranges[:, 1])
            self.data.qpos[self._qadr[p]] = pose
            self.data.ctrl[self._act[p]] = pose
        self._limits = self.model.actuator_ctrlrange[self._act[self.prefix][:3]].copy()
        self._body_ids = {b: mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, b)
                          for b in BODIES}
        if min(self._body_ids.values()) < 0:
            raise ValueError(f"{model_path}: lacks one of the bodies {BODIES}")
        mujoco.mj_kinematics(self.model, self.data)
        self._lock = threading.Lock()
        self._pending: tuple[np.ndarray, float] | None = None
        self._target = self.data.ctrl[self._act[self.prefix][:3]].copy()
        self._snapshot = self._take_snapshot()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._closed = False
        self._error: BaseException | None = None
        # statistics (bounded)
        self.commands = 0
        self.superseded = 0
        self.out_of_range = 0
        self.clamped_commands = 0
        self.steps = 0
        self.late_steps = 0
        self.skipped_steps = 0
        self._commanded = False
        self._t_first: float | None = None
        self._t_last: float | None = None
        self._tracking_deg = LogHistogram(1e-6, 360.0)
        self._delay_ms = LogHistogram(1e-3, 1e5)

    # -- lifecycle ---------------------------------------------------------------------------
    def start(self) -> None:
        """Start the physics thread (no-op when running). Raises RuntimeError after close."""
        if self._closed:
            raise RuntimeError("MujocoNao is closed")
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name=f"mujoco-nao-{self.side}",
                                            daemon=True)
            self._thread.start()

    def close(self) -> None:
        """Stop and join the physics thread. Idempotent. Re-raises an error of the thread."""
        self._closed = True
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            if self._thread.is_alive():
                raise RuntimeError("MuJoCo physics thread did not stop within 5 s")
        error, self._error = self._error, None
        if error is not None:
            raise RuntimeError(f"MuJoCo physics thread failed: {error}") from error

    def __enter__(self) -> MujocoNao:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def running(self) -> bool:
        """True while the physics thread runs."""
        return self._thread is not None and self._thread.is_alive()

    # -- JointTarget -------------------------------------------------------------------------
    def command(self, t: float, joints: np.ndarray, clamped: np.ndarray) -> None:
        """Take a command: ``joints`` (ShoulderPitch, ShoulderRoll, ElbowYaw), radians, for this
        side; ``clamped`` the mapping's per-joint clamp flags (counted). Angles outside the
        model's limits are clipped to them and counted (beyond ``LIMIT_TOLERANCE``). ``t``
        (s, the estimate's time) is not used for timing: the delay is measured on this
        process's clock.

        Raises RuntimeError before ``start()`` (no physics would take the command) or after
        close, ValueError for a wrong shape (of either) or non-finite angles.
        Never blocks beyond a lock swap.
        """
        if self._closed:
            raise RuntimeError("MujocoNao is closed")
        if self._thread is None:
            raise RuntimeError("MujocoNao is not running (call start() first)")
        received = time.perf_counter()
        angles = np.asarray(joints, dtype=float)
        if angles.shape != (3,):
            raise ValueError(f"joints must have shape (3,) {NAO_JOINTS}, got {angles.shape}")
        if not np.all(np.isfinite(angles)):
            raise ValueError(f"joints must be finite, got {angles.tolist()}")
        if np.shape(clamped) != (3,):
            raise ValueError(f"clamped must have shape (3,), one flag per joint, got "
                             f"{np.shape(clamped)}")
        target = np.clip(angles, self._limits[:, 0], self._limits[:, 1])
        with self._lock:
            if self._pending is not None:
                self.superseded += 1
            self._pending = (target, received)
            self.commands += 1
            self.out_of_range += int(np.any(np.abs(target - angles) > LIMIT_TOLERANCE))
            self.clamped_commands += int(np.any(clamped))

    # -- physics thread ----------------------------------------------------------------------
    def _run(self) -> None:
        try:
            self._loop()
        except BaseException as err:  # reported by close(); the thread must not die silently
            self._error = err

    def _loop(self) -> None:
        model, data = self.model, self.data
        act = self._act[self.prefix][:3]
        qadr = self._qadr[self.prefix][:3]
        period = 1.0 / self.rate_hz
        start = time.perf_counter()
        k = 0
        while True:
            deadline = start + k * period
            # no spin before the deadline: a spinning thread takes the GIL from the
            # acquisition and pipeline threads hundreds of times a second, and the robot
            # does not need sub-millisecond step times (late steps are counted)
            sleep_until(deadline, spin_s=0.0, cancel=self._stop)
            if self._stop.is_set():
                return
            now = time.perf_counter()
            if now - deadline > period:
                self.late_steps += 1
                if now - deadline > MAX_CATCH_UP_S:
                    skipped = int((now - deadline) / period)
                    self.skipped_steps += skipped
                    k += skipped
            with self._lock:
                pending, self._pending = self._pending, None
            if pending is not None:
                self._target = pending[0]
                data.ctrl[act] = self._target
            mujoco.mj_step(model, data)
            mujoco.mj_kinematics(model, data)
            stepped = time.perf_counter()
            self._snapshot = self._take_snapshot()
            self.steps += 1
            self._t_first = stepped if self._t_first is None else self._t_first
            self._t_last = stepped
            if pending is not None:
                self._commanded = True
                self._delay_ms.add((stepped - pending[1]) * 1e3)
            if self._commanded:
                error = np.max(np.abs(data.qpos[qadr] - self._target))
                self._tracking_deg.add(math.degrees(float(error)))
            k += 1

    def _take_snapshot(self) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
        """(simulated time s, this side's 4 joint angles, body positions, body rotations)."""
        ids = list(self._body_ids.values())
        return (float(self.data.time), self.data.qpos[self._qadr[self.prefix]].copy(),
                self.data.xpos[ids].copy(), self.data.xmat[ids].reshape(-1, 3, 3).copy())

    # -- readings ----------------------------------------------------------------------------
    def joint_angles(self) -> np.ndarray:
        """Reached (ShoulderPitch, ShoulderRoll, ElbowYaw) of the commanded arm, radians."""
        return self._snapshot[1][:3].copy()

    def body_positions(self) -> dict[str, np.ndarray]:
        """Position (m, NAO torso frame) of each body in :data:`BODIES` after the last step.
        Joint bodies sit at their joint: e.g. ``RShoulder`` is the shoulder, ``RElbow`` the
        elbow, ``r_wrist`` the wrist."""
        _, _, xpos, _ = self._snapshot
        return {name: xpos[i].copy() for i, name in enumerate(BODIES)}

    def upper_arm_axis(self, line: Literal["elbow", "axis"] = "elbow") -> np.ndarray:
        """Unit vector of the simulated upper arm, NAO torso frame.

        ``line="elbow"``: shoulder → elbow, NAO's elbow joint point (8.13° off the commanded
        axis, docs/conventions.md); ``line="axis"``: the upper-arm link's X axis, the line
        that :func:`~exohil.kinematics.humerus_to_nao` points along the human humerus.
        """
        _, _, xpos, xmat = self._snapshot
        p = self.prefix
        if line == "axis":
            return xmat[BODIES.index(f"{p}Bicep")][:, 0].copy()
        if line != "elbow":
            raise ValueError(f"line must be 'elbow' or 'axis', got {line!r}")
        v = xpos[BODIES.index(f"{p}Elbow")] - xpos[BODIES.index(f"{p}Shoulder")]
        return v / np.linalg.norm(v)

    @property
    def command_delay_ms(self) -> LogHistogram:
        """The command → stepped delays so far (ms, see :meth:`summary`); read, do not add."""
        return self._delay_ms

    def summary(self) -> dict:
        """JSON-able counts, the achieved physics rate (Hz, steps over the wall time they
        took), tracking error (degrees, per step: the largest |reached − commanded| of the
        three commanded joints, from the first command on) and command → stepped delay (ms:
        from ``command()`` to the end of the first physics step that used it)."""
        span = 0.0
        if self.steps > 1 and self._t_first is not None and self._t_last is not None:
            span = self._t_last - self._t_first
        names = [f"{self.prefix}{j}" for j in NAO_JOINTS]
        return {
            "side": self.side,
            "commands": self.commands,
            "superseded_commands": self.superseded,
            "out_of_range_commands": self.out_of_range,
            "clamped_commands": self.clamped_commands,
            "steps": self.steps,
            "target_rate_hz": self.rate_hz,
            "physics_rate_hz": round((self.steps - 1) / span, 2) if span > 0 else None,
            "late_steps": self.late_steps,
            "skipped_steps": self.skipped_steps,
            "simulated_s": round(self._snapshot[0], 6),
            "tracking_error_deg": self._tracking_deg.summary(),
            "command_delay_ms": self._delay_ms.summary(),
            "reached_deg": {n: round(math.degrees(float(v)), 3)
                            for n, v in zip(names, self.joint_angles(), strict=True)},
        }
