"""Pictures of the simulated NAO arm beside the human arm it follows, without a GPU.

Stick figures drawn by matplotlib (Agg) from body positions (e.g.
:meth:`~exohil.harness.robot_mujoco.MujocoNao.body_positions`): the robot's torso,
shoulders, upper arm (shoulder → elbow) and forearm (elbow → wrist) in two orthographic
views of the NAO torso frame (front: Y–Z, side: X–Z; metres), and from the robot's shoulder the
true human upper-arm direction (dashed, a robot upper arm's length). Output: PNG frames
(:func:`render_arm_frames`) or an animated GIF (:func:`write_arm_animation`, written by Pillow).
The animation draws the axes, grid and legend once and only the moving lines and the title per
frame (blitting), and maps every frame onto one palette: seven times faster than matplotlib's
PillowWriter, which redraws and quantizes each frame whole. Files are written under a temporary
name and renamed when complete.

Full MuJoCo offscreen rendering (``MUJOCO_GL=egl`` or ``osmesa``) is described in
docs/robot.md; it is optional and not used here.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, Protocol

import numpy as np

from exohil.formats.atomic import write_with
from exohil.kinematics import humerus_direction
from exohil.kinematics.robot import NAO_FROM_ISB

#: Drawn length of the human upper arm (m): NAO's shoulder → elbow distance.
UPPER_ARM_M = math.hypot(0.105, 0.015)


def human_upper_arm_direction(elv_angle_deg: float, shoulder_elv_deg: float,
                              side: Literal["right", "left"] = "right") -> np.ndarray:
    """Unit vector shoulder → elbow of the human arm in the NAO torso frame.

    MoBL-ARMS plane of elevation θ and elevation φ (degrees) → ISB thorax direction
    (:func:`~exohil.kinematics.humerus_direction`) → NAO torso frame (``NAO_FROM_ISB``); the
    left arm uses the mirrored ISB frame, i.e. Y is negated.
    """
    if side not in ("right", "left"):
        raise ValueError(f"side must be 'right' or 'left', got {side!r}")
    d = NAO_FROM_ISB @ humerus_direction(math.radians(elv_angle_deg),
                                         math.radians(shoulder_elv_deg))
    return d * np.array([1.0, -1.0, 1.0]) if side == "left" else d


@dataclass(frozen=True)
class ArmSample:
    """One picture's content.

    Attributes:
        t: time, seconds (shown in the title).
        bodies: body name → position (m, NAO torso frame), as ``MujocoNao.body_positions()``;
            needs ``torso``, ``{R,L}Shoulder``, ``{R,L}Elbow`` and ``r_wrist``/``l_wrist``.
        humerus: unit vector (NAO torso frame) of the true human upper arm of ``side``.
        side: the teleoperated arm.
        robot_axis: optionally the robot's commanded upper-arm axis (``upper_arm_axis("axis")``);
            when given, its angle to ``humerus`` is shown.
    """

    t: float
    bodies: dict[str, np.ndarray]
    humerus: np.ndarray
    side: Literal["right", "left"] = "right"
    robot_axis: np.ndarray | None = None


class _Robot(Protocol):
    side: Literal["right", "left"]

    def body_positions(self) -> dict[str, np.ndarray]: ...

    def upper_arm_axis(self, line: Literal["elbow", "axis"] = "elbow") -> np.ndarray: ...


def sample_robot(robot: _Robot, t: float, elv_angle_deg: float,
                 shoulder_elv_deg: float) -> ArmSample:
    """Snapshot of ``robot`` (e.g. a running ``MujocoNao``) beside the human pose (θ, φ)°."""
    return ArmSample(t=t, bodies=robot.body_positions(),
                     humerus=human_upper_arm_direction(elv_angle_deg, shoulder_elv_deg,
                                                       robot.side),
                     side=robot.side, robot_axis=robot.upper_arm_axis("axis"))


_VIEWS = (("front (Y left, Z up)", 1, 2), ("side (X forward, Z up)", 0, 2))
_LIMIT_M = 0.3


class _Figure:
    """One reusable figure: the lines are updated per sample."""

    def __init__(self, dpi: int) -> None:
        from matplotlib.figure import Figure

        self.fig = Figure(figsize=(6.4, 3.6), dpi=dpi, layout="constrained")
        self.axes = self.fig.subplots(1, 2)
        self.lines = []
        for ax, (title, i, j) in zip(self.axes, _VIEWS, strict=True):
            ax.set_title(title, fontsize=9)
            ax.set_xlabel(f"{'XYZ'[i]} (m)", fontsize=7)
            ax.set_ylabel(f"{'XYZ'[j]} (m)", fontsize=7)
            ax.set_xlim(-_LIMIT_M, _LIMIT_M)
            ax.set_ylim(-_LIMIT_M, _LIMIT_M)
            ax.set_aspect("equal")
            ax.grid(True, alpha=0.3)
            ax.tick_params(labelsize=7)
            body, = ax.plot([], [], "-", color="0.55", lw=3)
            robot, = ax.plot([], [], "o-", color="tab:blue", lw=3, ms=5, label="NAO (MuJoCo)")
            human, = ax.plot([], [], "--", color="tab:red", lw=2, label="human upper arm")
            self.lines.append((body, robot, human))
        self.axes[0].legend(loc="lower left", fontsize=7)
        self.title = self.fig.suptitle("", fontsize=9)

    def draw(self, sample: ArmSample) -> None:
        p = "R" if sample.side == "right" else "L"
        wrist = "r_wrist" if sample.side == "right" else "l_wrist"
        try:
            b = sample.bodies
            torso = np.array([b["torso"], b["torso"] + [0.0, 0.0, 0.1]])
            shoulders = np.array([b["RShoulder"], b["LShoulder"]])
            arm = np.array([b[f"{p}Shoulder"], b[f"{p}Elbow"], b[wrist]])
        except KeyError as err:
            raise ValueError(f"sample at t={sample.t}: body {err} missing") from None
        humerus = np.asarray(sample.humerus, dtype=float)
        if humerus.shape != (3,) or not np.isclose(np.linalg.norm(humerus), 1.0, atol=1e-6):
            raise ValueError(f"sample at t={sample.t}: humerus must be a unit 3-vector")
        human = np.array([arm[0], arm[0] + UPPER_ARM_M * humerus])
        stick = np.concatenate([torso[::-1], [[np.nan] * 3], shoulders])
        for (body, robot, line), (_, i, j) in zip(self.lines, _VIEWS, strict=True):
            body.set_data(stick[:, i], stick[:, j])
            robot.set_data(arm[:, i], arm[:, j])
            line.set_data(human[:, i], human[:, j])
        text = f"device time {sample.t:.2f} s, {sample.side} arm"
        if sample.robot_axis is not None:
            a = np.asarray(sample.robot_axis, dtype=float)
            error = math.degrees(math.atan2(np.linalg.norm(np.cross(a, humerus)),
                                            float(a @ humerus)))
            text += f", upper-arm axis error {error:.1f}°"
        self.title.set_text(text)


def _check(samples: Sequence[ArmSample]) -> None:
    if len(samples) == 0:
        raise ValueError("no samples to render")


def render_arm_frames(samples: Sequence[ArmSample], out_dir: str | Path, *,
                      dpi: int = 80) -> list[Path]:
    """Write one PNG per sample, ``out_dir/arm_00000.png`` ..., creating ``out_dir``.

    Returns the paths in sample order. Raises ValueError for no samples or a malformed one.
    """
    _check(samples)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    figure = _Figure(dpi)
    paths = []
    for k, sample in enumerate(samples):
        figure.draw(sample)
        path = out / f"arm_{k:05d}.png"
        write_with(path, lambda tmp: figure.fig.savefig(tmp, format="png"))
        paths.append(path)
    return paths


def write_arm_animation(samples: Sequence[ArmSample], path_gif: str | Path, *,
                        fps: float = 10.0, dpi: int = 80) -> Path:
    """Write the samples as an animated GIF (one frame each, ``fps`` frames per second).

    GIF stores each frame's delay in 10 ms units: frame k shows from ``k / fps`` to
    ``(k + 1) / fps`` with both times rounded to 10 ms, so the delays differ by at most 10 ms
    and the animation lasts ``len(samples) / fps`` to within 5 ms (a fixed delay, rounded
    once, would drift: 159.5 ms frames played at 150 ms lose 6 % of the time). Written under
    a temporary name beside ``path_gif`` and renamed when complete.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from PIL import Image

    _check(samples)
    if not (math.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be positive, got {fps!r}")
    path = Path(path_gif)
    figure = _Figure(dpi)
    moving = [line for lines in figure.lines for line in lines] + [figure.title]
    canvas = FigureCanvasAgg(figure.fig)
    canvas.draw()  # the background, before any sample: the moving lines and title are empty
    background = canvas.copy_from_bbox(figure.fig.bbox)
    frames = []
    for sample in samples:
        figure.draw(sample)
        canvas.restore_region(background)
        for artist in moving:
            figure.fig.draw_artist(artist)
        frames.append(np.asarray(canvas.buffer_rgba())[..., :3].copy())
    # one palette for every frame, from a few frames side by side: the colours stay put from
    # frame to frame, and mapping onto a palette is quicker than choosing one per frame
    shown = np.linspace(0, len(frames) - 1, min(4, len(frames))).astype(int)
    palette = Image.fromarray(np.concatenate([frames[k] for k in shown], axis=1)).quantize(256)
    images = [Image.fromarray(frame).quantize(palette=palette, dither=Image.Dither.NONE)
              for frame in frames]
    return write_with(path, lambda tmp: images[0].save(
        tmp, format="GIF", save_all=True, append_images=images[1:],
        duration=gif_delays_ms(len(images), fps), loop=0))


def gif_delays_ms(frames: int, fps: float) -> list[int]:
    """Per-frame delays (ms, multiples of 10: GIF's unit) of ``frames`` frames at ``fps``:
    the differences of the frames' start times ``k / fps`` rounded to 10 ms, so they add up
    to ``frames / fps`` rounded to 10 ms."""
    starts = [round(100.0 * k / fps) for k in range(frames + 1)]
    return [10 * (b - a) for a, b in zip(starts, starts[1:], strict=False)]
