"""One bench session: open the device, stream through the model into the sinks, measure.

``exohil demo``, ``exohil run`` and the conformance suite's real-time checks all run a
:func:`run_session` on a :class:`~exohil.harness.bench.BenchConfig` and report the
:class:`~exohil.formats.measurement.Measurement` lists built here, so the three can never
define a figure differently:

* :func:`latency_measurements`: per-stage times of every frame (ms), see ``pipeline.STAGES``;
* :func:`link_measurements`: host counters, and for the emulator an exact reconciliation with
  its fault log;
* :func:`accuracy_measurements` (from the estimator layer): against the reference's motion
  capture, aligned by device time;
* :func:`teleop_measurements`: robot commands against those computed from the true angles;
* :func:`robot_measurements`: what a simulated robot did: command → stepped delay
  (``latency.robot_step``), joint tracking and its upper-arm axis against the true humerus.
"""

from __future__ import annotations

import threading
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from exohil.emulators.faults import LOSING_KINDS
from exohil.estimator.checkpoint import CheckpointError, ensure_fits, load_checkpoint
from exohil.estimator.evaluation import accuracy_measurements, arm_direction_error_deg
from exohil.estimator.inference import StreamingEstimator, default_backend
from exohil.estimator.trained import TrainedEstimator
from exohil.formats.alignment import angles_at
from exohil.formats.atomic import same_file
from exohil.formats.digest import sha256_file
from exohil.formats.errors import InputError, RecordingError
from exohil.formats.measurement import DISTRIBUTION_STATS, Limit, Measurement, distribution
from exohil.formats.recording import Recording
from exohil.harness.bench import BenchConfig, BenchError, EmulatorDevice, SerialDevice, open_device
from exohil.harness.pipeline import STAGES, Pipeline, PipelineRun, Sink, Status
from exohil.harness.robot_trace import RobotTrace, RobotTraceSink
from exohil.harness.teleop import SHOULDER_ANGLES, SimulatedNao, TeleopSink
from exohil.kinematics import NAO_JOINTS

Limits = Mapping[str, Limit]
Progress = Callable[[Status], None]

#: Interval measurements: name → (from stage, to stage).
LATENCY_INTERVALS = {
    "latency.device_to_host": ("device_write", "host_receive"),
    "latency.decode": ("host_receive", "decoded"),
    "latency.queue_and_estimate": ("decoded", "estimated"),
    "latency.command": ("estimated", "commanded"),
}


class SessionError(InputError):
    """A session that cannot start or produced nothing; the message says why (one line)."""


@dataclass
class LoadedModel:
    """A checkpoint and its streaming engine."""

    path: Path
    estimator: TrainedEstimator
    backend: str
    sha256: str

    def engine(self) -> StreamingEstimator:
        """A fresh streaming engine (empty window)."""
        return StreamingEstimator(self.estimator, backend=self.backend)


def load_model(path: Path, backend: str = "auto") -> LoadedModel:
    """Load a checkpoint and check that ``backend`` can run it; SessionError if not."""
    try:
        est = load_checkpoint(path)
        chosen = default_backend(est) if backend == "auto" else backend
        StreamingEstimator(est, backend=chosen)
    except (CheckpointError, ValueError, OSError) as err:
        raise SessionError(str(err)) from None
    return LoadedModel(Path(path), est, chosen, sha256_file(path))


def read_reference(path: Path) -> Recording:
    """A recording holding ground truth; SessionError if it cannot be read."""
    from exohil.formats.recording_reader import read_recording

    try:
        return read_recording(path)
    except RecordingError as err:
        raise SessionError(str(err)) from None


def reference_path(config: BenchConfig) -> Path | None:
    """The recording that holds the ground truth of ``config``'s device, if any."""
    device = config.device
    if isinstance(device, EmulatorDevice):
        return device.recording
    if isinstance(device, SerialDevice):
        return device.reference
    return None


def truth_at(reference: Recording, est: TrainedEstimator, device_time_s: np.ndarray) -> np.ndarray:
    """(N, A) true angles (deg) at the frames' device times, in the estimator's order; NaN
    outside the reference's motion capture."""
    return angles_at(reference, device_time_s, est.target.joint, est.target.angles)


def build_robots(names: Sequence[str]) -> list[Any]:
    """Robot targets by name: ``simulated`` (bookkeeping only), ``mujoco`` (NAO's arms in
    MuJoCo, started here; closed by the teleoperation sink's close), ``udp:HOST:PORT`` (one
    JSON datagram per command). BenchError (one line) for an unknown name or a bad address;
    robots already started are closed then."""
    robots: list[Any] = []
    try:
        for name in names:
            robots.append(_build_robot(name))
    except BenchError:
        for robot in robots:
            getattr(robot, "close", lambda: None)()
        raise
    return robots


def _build_robot(name: str) -> Any:
    if name == "simulated":
        return SimulatedNao()
    if name == "mujoco":
        from exohil.harness.robot_mujoco import MujocoNao

        nao = MujocoNao()
        nao.start()
        return nao
    if name.startswith("udp:"):
        from exohil.harness.robot_udp import UdpJointTarget

        host, _, port = name.removeprefix("udp:").rpartition(":")
        host = host.removeprefix("[").removesuffix("]")
        if not host or not port.isdigit() or not 1 <= int(port) <= 65535:
            raise BenchError(f"bad robot address {name!r}: expected udp:HOST:PORT with a port "
                             "1..65535, e.g. udp:127.0.0.1:9000")
        try:
            return UdpJointTarget(host, int(port))
        except ValueError as err:
            raise BenchError(f"robot {name!r}: {err}") from None
    raise BenchError(f"unknown robot {name!r}; available: simulated, mujoco, udp:HOST:PORT")


@dataclass
class SessionResult:
    """Everything one session produced (see :func:`run_session`)."""

    config: BenchConfig
    model: LoadedModel
    run: PipelineRun
    truth: np.ndarray | None
    fault_log: list[Any] | None
    emulator_seq0: int | None
    wire_values_mm: np.ndarray | None
    clipped_values: int
    robots: list[Any] = field(default_factory=list)
    robot_trace: RobotTrace | None = None
    #: why the device stopped before the run's end (a device that never came back), or None
    device_lost: str | None = None

    @property
    def fault_counts(self) -> dict[str, int] | None:
        if self.fault_log is None:
            return None
        return dict(Counter(record.kind for record in self.fault_log))


def run_session(config: BenchConfig, seconds: float | None, *,
                progress: Progress | None = None,
                stop: threading.Event | None = None, extra_sinks: Sequence[Sink] = (),
                realtime: bool = False) -> SessionResult:
    """Stream ``seconds`` of the bench's device through its model into its sinks.

    An emulator streams exactly ``seconds`` of device time and the run ends once every frame
    it sent has been processed, so its fault log and the host's counters cover the same
    frames; a serial device is read for ``seconds`` of wall time. ``seconds=None`` runs until
    ``stop`` is set (or, for the emulator, to the end of its recording; for a serial device with
    a reference, until the device's clock passes the reference's end). Setting ``stop`` ends
    any run early, and the result covers what was processed.
    """
    if config.device is None:
        raise SessionError("no device: give a target (emulator:RECORDING or a serial URL)")
    if config.model is None:
        raise SessionError("no model: give a checkpoint")
    model = load_model(config.model, config.backend)
    est = model.estimator
    if config.sensor_names is not None and tuple(config.sensor_names) != est.sensor_names:
        raise SessionError(f"the bench's sensors {list(config.sensor_names)} are not the "
                           f"model's {list(est.sensor_names)}")
    ref_path = reference_path(config)
    reference = None if ref_path is None else read_reference(ref_path)
    if reference is not None:
        try:
            ensure_fits(est, reference, str(ref_path))
        except CheckpointError as err:
            raise SessionError(str(err)) from None
    inputs = [p for p in (config.model, ref_path) if p is not None]
    if config.record is not None and same_file(config.record, inputs) is not None:
        raise SessionError(f"refusing to record onto an input: {config.record}")
    if progress is not None and reference is not None:
        progress = _with_running_error(progress, reference, est)
    robots: list[Any] = []
    sinks: list[Sink] = []
    tracer = None
    try:  # every sink built is closed below; a bad robot name (BenchError) is a ValueError
        robots = build_robots(config.robots) if _is_shoulder(est) else []
        if robots:
            sinks.append(TeleopSink(robots, est.target.angles))
            traced = [r for r in robots if hasattr(r, "upper_arm_axis")]
            if traced:
                tracer = RobotTraceSink(traced[0])
                sinks.append(tracer)
        sinks.extend(extra_sinks)
        if config.record is not None:
            from exohil.harness.recorder import RecorderSink

            sinks.append(RecorderSink(config.record, est.sensor_names, metadata={
                "generator": "exohil", "source": config.device.describe(),
                "model_sha256": model.sha256}))
        with open_device(config.device, len(est.sensor_names), realtime=realtime,
                         duration_s=seconds, recording=reference) as opened:
            pipeline = Pipeline(opened.source, model.engine(), sinks, opened.device_clock)
            if opened.emulator is not None:
                # until every frame the emulator sent is processed, outages included
                limit = None if seconds is None else seconds + 30.0
                emulator = opened.emulator
                run = pipeline.run(duration_s=limit, stop=stop, progress=progress,
                                   source_done=lambda: emulator.finished)
            else:
                end, wall, idle = None, seconds, None
                if seconds is None and reference is not None and len(reference.sensors):
                    t = reference.sensors.t
                    end = float(t[-1]) - 1.5 / reference.sensor_rate_hz  # its last frame
                    wall = float(t[-1] - t[0]) + 60.0  # a device that never gets there
                    idle = 3.0  # or stops streaming first
                source = opened.source
                run = pipeline.run(duration_s=wall, stop=stop, progress=progress,
                                   until_device_time_s=end, idle_timeout_s=idle,
                                   source_done=lambda: not source.alive)
            device_lost = None
            if opened.source.device_timed_out:
                device_lost = opened.source.last_error or "the device stopped sending"
            emulator = opened.emulator
            fault_log = None if emulator is None else emulator.fault_log
            seq0 = None if emulator is None else emulator.seq0
            wire = None if emulator is None else emulator.wire_values_mm
            clipped = 0 if emulator is None else emulator.clipped_values
    except (ValueError, RecordingError) as err:
        raise SessionError(str(err)) from None
    finally:
        for sink in sinks:
            sink.close()
    if run.frames == 0:
        stats = run.link
        hint = (f" ({stats.decode_errors} packets of another shape: does the device send "
                f"{len(est.sensor_names)} sensors?)" if stats.decode_errors else "")
        why = f": {device_lost}" if device_lost else ""
        raise SessionError(f"no frame arrived from the {config.device.describe()}{hint}{why}")
    truth = None if reference is None else truth_at(reference, est, run.device_time_s)
    trace = None if tracer is None else tracer.trace()
    if trace is not None and reference is not None:
        angles = truth_at(reference, est, trace.device_time_s)
        shoulder = [est.target.angles.index(a) for a in SHOULDER_ANGLES]
        trace = replace(trace, truth_deg=angles[:, shoulder])
    return SessionResult(config, model, run, truth, fault_log, seq0, wire, clipped, robots,
                         trace, device_lost)


def _with_running_error(progress: Progress, reference: Recording,
                        est: TrainedEstimator) -> Progress:
    """``progress`` with ``status.error_deg`` filled in: the RMSE since the previous status of
    the arm-direction error (shoulder) or of every angle (other joints), degrees."""
    def with_error(status: Status) -> None:
        truth = truth_at(reference, est, status.recent_device_time_s)
        ok = np.all(np.isfinite(truth), axis=1)
        if ok.any():
            est_ok, true_ok = status.recent_estimates[ok], truth[ok]
            if _is_shoulder(est):
                th = est.target.angles.index("elv_angle")
                ph = est.target.angles.index("shoulder_elv")
                err = arm_direction_error_deg(est_ok[:, th], est_ok[:, ph], true_ok[:, th],
                                              true_ok[:, ph])
            else:
                err = (est_ok - true_ok).ravel()
            status.error_deg = float(np.sqrt(np.mean(err**2)))
        progress(status)

    return with_error


def _is_shoulder(est: TrainedEstimator) -> bool:
    return est.target.joint == "shoulder" and all(a in est.target.angles for a in SHOULDER_ANGLES)


def _stat_limits(limits: Limits, name: str) -> dict[str, Limit]:
    """``limits`` entries ``name.p50`` etc. keyed by statistic."""
    return {stat: limits[f"{name}.{stat}"] for stat in DISTRIBUTION_STATS
            if f"{name}.{stat}" in limits}


def latency_samples(run: PipelineRun) -> dict[str, tuple[np.ndarray, str]]:
    """Per-frame samples (ms) of each latency measurement, by name, with what they span: the
    stage intervals, the estimator's compute, and end to end from the device's write (when
    known, else host receive) to the robot command (else the sinks done)."""
    out = {name: (run.interval_ms(a, b), f"{a} → {b}")
           for name, (a, b) in LATENCY_INTERVALS.items()}
    out["latency.estimator"] = (run.compute_ns / 1e6, "estimator compute per frame")
    first = run.stamps[:, STAGES.index("device_write")]
    start_stage = "device_write" if np.any(first >= 0) else "host_receive"
    end_stage = "commanded" if np.any(run.stamps[:, STAGES.index("commanded")] >= 0) else "done"
    out["latency.end_to_end"] = (run.interval_ms(start_stage, end_stage),
                                 f"{start_stage} → {end_stage}")
    return out


def latency_measurements(run: PipelineRun, limits: Limits | None = None) -> list[Measurement]:
    """p50/p99/max, ms, of each of :func:`latency_samples`. ``limits`` maps e.g.
    ``latency.end_to_end.max`` to its limit."""
    limits = limits or {}
    out: list[Measurement] = []
    for name, (ms, note) in latency_samples(run).items():
        out += distribution(name, ms, "ms", _stat_limits(limits, name), note)
    return out


def link_measurements(result: SessionResult, limits: Limits | None = None) -> list[Measurement]:
    """Host link counters and, for the emulator, their reconciliation with its fault log:

    * ``link.lost_on_host``: frames the device handed over that never reached the pipeline
      (buffer overflow, or a gap the device did not log), must be 0;
    * ``link.bad_frames_delivered``: frames whose values differ from what the device sent for
      that sequence number (a CRC that let corruption through), must be 0;
    * ``link.dropped_unexplained``: host-counted drops minus the device's logged losses
      within the received span, must be 0.
    """
    limits = limits or {}
    run = result.run
    link = run.link

    def m(name: str, value: float, unit: str = "count", note: str = "") -> Measurement:
        return Measurement.judge(name, value, unit, limits.get(name), note)

    span = float(run.device_time_s[-1] - run.device_time_s[0]) if run.frames > 1 else 0.0
    rate = (run.frames - 1) / span if span > 0 else float("nan")
    out = [m("link.frames", run.frames),
           m("link.rate", rate, "Hz", note="frames received per second of device time"),
           m("link.dropped", link.dropped, note="sequence gaps seen by the host"),
           m("link.crc_errors", link.crc_errors), m("link.decode_errors", link.decode_errors),
           m("link.overflow", link.overflow, note="frames the host buffer discarded")]
    if result.fault_log is None or result.wire_values_mm is None or result.emulator_seq0 is None:
        why = "no device fault log (not the in-process emulator)"
        for name in ("link.lost_on_host", "link.bad_frames_delivered",
                     "link.dropped_unexplained"):
            out.append(Measurement.skipped(name, "count", why, limits.get(name)))
        return out
    first, last = int(run.seq[0]), int(run.seq[-1])
    lost = {r.seq for r in result.fault_log if r.kind in LOSING_KINDS and first <= r.seq <= last}
    received = set(run.seq.tolist())
    expected = set(range(first, last + 1)) - lost
    wire = result.wire_values_mm
    rows = (run.seq - result.emulator_seq0) % wire.shape[0]
    bad = int(np.count_nonzero(np.any(np.abs(run.values - wire[rows]) > 1e-9, axis=1)))
    out += [
        m("link.lost_on_host", len(expected - received),
          note=f"{len(expected)} frames the device delivered in seq {first}..{last}"),
        m("link.bad_frames_delivered", bad, note="values differ from what the device sent"),
        m("link.dropped_unexplained", link.dropped - len(lost),
          note=f"host {link.dropped} vs device log {len(lost)} in the received span"),
    ]
    return out


def teleop_measurements(result: SessionResult,
                        limits: Limits | None = None) -> list[Measurement]:
    """Robot commands from the estimates against the commands the same mapping gives for the
    true angles: RMSE per joint (deg) and the share of clamped commands."""
    limits = limits or {}
    run, truth, est = result.run, result.truth, result.model.estimator
    names = [f"teleop.rmse.{j}" for j in NAO_JOINTS]
    if truth is None or not result.robots or np.all(np.isnan(run.commands)):
        why = "no reference" if truth is None else "no teleoperation (not a shoulder model)"
        return [Measurement.skipped(n, "deg", why, limits.get(n)) for n in names]
    mapping = TeleopSink([], est.target.angles)
    th, ph = est.target.angles.index("elv_angle"), est.target.angles.index("shoulder_elv")
    ok = np.all(np.isfinite(truth), axis=1) & np.all(np.isfinite(run.commands), axis=1)
    reference = np.full_like(run.commands, np.nan)
    for i in np.flatnonzero(ok):
        reference[i] = mapping.command_for(truth[i, th], truth[i, ph]).joints
    if not ok.any():
        return [Measurement.skipped(n, "deg", "no frame with both a command and the truth",
                                    limits.get(n)) for n in names]
    err = np.rad2deg(run.commands[ok] - reference[ok])
    note = f"{int(ok.sum())} frames"
    out = [Measurement.judge(n, float(np.sqrt(np.mean(err[:, j] ** 2))), "deg",
                             limits.get(n), note) for j, n in enumerate(names)]
    share = float(np.mean(run.clamped)) if run.frames else float("nan")
    out.append(Measurement.judge("teleop.clamped_share", share, "ratio",
                                 limits.get("teleop.clamped_share"),
                                 "commands with a joint at its limit"))
    return out


def session_accuracy(result: SessionResult, limits: Limits | None = None) -> list[Measurement]:
    """Accuracy of the streamed estimates against the reference (skipped without one)."""
    est = result.model.estimator
    if result.truth is None:
        names = [f"accuracy.rmse.{a}" for a in est.target.angles]
        if _is_shoulder(est):
            names.append("accuracy.direction_rmse")
        return [Measurement.skipped(n, "deg", "no reference recording", (limits or {}).get(n))
                for n in names]
    return accuracy_measurements(result.run.estimates, result.truth, est.target.angles, limits)


def robot_measurements(result: SessionResult,
                       limits: Limits | None = None) -> list[Measurement]:
    """What the simulated robot (MuJoCo) did, skipped without one:

    * ``latency.robot_step``: command issued → end of the first physics step that used it, ms
      (the robot's own histogram, quantiles to 1.2 %);
    * ``teleop.robot_tracking``: per physics step the largest |reached − commanded| joint
      angle, deg (histogram);
    * ``teleop.robot_axis_error``: the robot's upper-arm axis against the true humerus at the
      sampled frames' device times, deg (needs a reference).
    """
    limits = limits or {}

    def from_histogram(name: str, stats: Mapping[str, Any] | None, unit: str,
                       note: str) -> list[Measurement]:
        if not stats or not stats.get("count"):
            why = "no simulated robot" if stats is None else "no samples"
            return [Measurement.skipped(f"{name}.{s}", unit, why, limits.get(f"{name}.{s}"))
                    for s in DISTRIBUTION_STATS]
        return [Measurement.judge(f"{name}.{s}", float(stats[s]), unit,
                                  limits.get(f"{name}.{s}"), f"{stats['count']} {note}")
                for s in DISTRIBUTION_STATS]

    robot = next((r.summary() for r in result.robots if hasattr(r, "upper_arm_axis")), None)
    out = from_histogram("latency.robot_step", None if robot is None else
                         robot["command_delay_ms"], "ms", "commands; commanded → robot stepped")
    out += from_histogram("teleop.robot_tracking", None if robot is None else
                          robot["tracking_error_deg"], "deg",
                          "physics steps; largest |reached − commanded| joint")
    trace = result.robot_trace
    name = "teleop.robot_axis_error"
    if trace is None or trace.truth_deg is None:
        why = "no simulated robot" if trace is None else "no reference"
        out += [Measurement.skipped(f"{name}.{s}", "deg", why, limits.get(f"{name}.{s}"))
                for s in DISTRIBUTION_STATS]
    else:
        out += distribution(name, trace.axis_error_deg(), "deg", _stat_limits(limits, name),
                            "robot upper-arm axis vs true humerus")
    return out
