"""The MuJoCo NAO following the suit in real time: physics rate, command → stepped delay,
joint tracking error, and how far the simulated arm points from the human arm.

The bundled fixture's motion capture (θ, φ; the estimator's ideal output) is replayed at
250 Hz of wall time through the teleoperation chain (``TeleopSink``, ψ = 0) into a running
:class:`~exohil.harness.robot_mujoco.MujocoNao`. Arm-direction errors (degrees, every
command): the commanded upper-arm axis against the human direction (the mapping alone: zero
where reachable), and the simulated arm's axis against the human direction (mapping plus
servo lag).

Run from the repository root: ``python -m benchmarks.bench_robot [--seconds 30]
[--start 25] [--gif out/arm.gif] [--json FILE]``, the replay within the fixture's
0–246 s; figures are reported through
:mod:`benchmarks.report` (no goal is documented, so none is judged).
"""

from __future__ import annotations

import math
import time

import numpy as np

from benchmarks.report import (
    gif_file,
    parser,
    positive_float,
    refuse_overwrite,
    report,
    run_main,
)
from exohil.formats.measurement import Measurement
from exohil.formats.recording_reader import read_recording
from exohil.harness.paths import FIXTURES_DIR
from exohil.harness.robot_mujoco import MujocoNao
from exohil.harness.robot_render import (
    human_upper_arm_direction,
    sample_robot,
    write_arm_animation,
)
from exohil.harness.robot_stats import LogHistogram
from exohil.harness.teleop import SHOULDER_ANGLES, TeleopSink
from exohil.realtime import sleep_until

RATE_HZ = 250.0
FIXTURE = FIXTURES_DIR / "paper_protocol.mcap"


def commanded_axis(joints: np.ndarray) -> np.ndarray:
    """Right arm's upper-arm X axis for (pitch, roll, yaw): R_y(pitch) R_z(roll) e_x."""
    pitch, roll = joints[0], joints[1]
    return np.array([math.cos(pitch) * math.cos(roll), math.sin(roll),
                     -math.sin(pitch) * math.cos(roll)])


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.atan2(float(np.linalg.norm(np.cross(a, b))), float(a @ b)))


def _histogram(name: str, values: dict, unit: str, note: str = "") -> list[Measurement]:
    """p50/p99/max of a robot histogram summary (``{"p50", "p99", "max"}``) as measurements."""
    return [Measurement.judge(f"{name}.{stat}", math.nan if values.get(stat) is None
                              else float(values[stat]), unit, note=note)
            for stat in ("p50", "p99", "max")]


def main() -> None:
    ap = parser(__doc__)
    ap.add_argument("--seconds", type=positive_float, default=30.0, help="replay length, s")
    ap.add_argument("--start", type=float, default=25.0,
                    help="offset into the fixture, s (25: abduction, then the rest)")
    ap.add_argument("--gif", type=gif_file, default=None, metavar="FILE.gif",
                    help="also write an animation (5 frames/s)")
    args = ap.parse_args()
    refuse_overwrite(ap, "--json", args.json, [FIXTURE])
    refuse_overwrite(ap, "--gif", args.gif, [FIXTURE])
    stream = read_recording(FIXTURE).mocap["shoulder"]
    first, last = float(stream.t[0]), float(stream.t[-1])
    if not (math.isfinite(args.start) and first <= args.start
            and args.start + args.seconds <= last):
        ap.error(f"--start {args.start:g} --seconds {args.seconds:g}: the replay must lie "
                 f"within the fixture's {first:g}..{last:g} s")
    t = np.arange(args.start, args.start + args.seconds, 1.0 / RATE_HZ)
    theta = np.interp(t, stream.t, stream.column("elv_angle"))
    phi = np.interp(t, stream.t, stream.column("shoulder_elv"))
    mapping_deg, arm_deg = LogHistogram(1e-9, 360.0), LogHistogram(1e-9, 360.0)
    samples = []
    with MujocoNao() as nao:
        sink = TeleopSink([nao], SHOULDER_ANGLES)
        start = time.perf_counter()
        for k in range(len(t)):
            sleep_until(start + k / RATE_HZ)
            command = sink.command_for(float(theta[k]), float(phi[k]))
            nao.command(float(t[k]), command.joints, command.clamped)
            human = human_upper_arm_direction(theta[k], phi[k])
            mapping_deg.add(angle_deg(commanded_axis(command.joints), human))
            arm_deg.add(angle_deg(nao.upper_arm_axis("axis"), human))
            if args.gif and k % int(RATE_HZ / 5) == 0:
                samples.append(sample_robot(nao, float(t[k]), theta[k], phi[k]))
        summary = nao.summary()
    print(f"replayed {len(t)} commands at {RATE_HZ:.0f} Hz, fixture t = {args.start:.1f}.."
          f"{args.start + args.seconds:.1f} s")
    measurements = [
        Measurement.judge("physics.rate", summary["physics_rate_hz"] or math.nan, "Hz",
                          note=f"target {summary['target_rate_hz']} Hz; "
                               f"{summary['late_steps']} late, {summary['skipped_steps']} "
                               "skipped steps"),
        Measurement.judge("commands", summary["commands"], "count"),
        *_histogram("command_to_stepped", summary["command_delay_ms"], "ms"),
        *_histogram("tracking_error", summary["tracking_error_deg"], "deg",
                    "largest |reached - commanded| joint"),
        *_histogram("axis.commanded_vs_human", mapping_deg.summary(), "deg", "the mapping"),
        *_histogram("axis.simulated_vs_human", arm_deg.summary(), "deg", "mapping + servo"),
    ]
    report("bench_robot", measurements, args.json)
    if args.gif:
        print(f"wrote {write_arm_animation(samples, args.gif, fps=5.0)}")


if __name__ == "__main__":
    run_main(main)
