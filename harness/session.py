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

Memory is bounded whatever the session's length: the pipeline keeps per-frame rows only for
the first and last frames of the run (``PipelineRun``) and folds every frame, as the run goes,
into fixed-size totals: its latency histograms, and the observers built here, which score the
estimates against the reference (:class:`TruthTally`) and check the frames against what the
emulator sent (:class:`LinkTally`). Only two things grow, and only with what the emulator
injected or the reference holds: the sequence gaps kept for the link reconciliation, and the
frames with ground truth whose robot commands are scored at the end (at most
:data:`TELEOP_MAX_FRAMES`).
"""

from __future__ import annotations

import math
import threading
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from exohil.emulators.faults import LOSING_KINDS
from exohil.estimator.checkpoint import CheckpointError, ensure_fits, load_checkpoint
from exohil.estimator.coverage import CoverageTally
from exohil.estimator.evaluation import AccuracyTally, arm_direction_error_deg
from exohil.estimator.inference import StreamingEstimator, default_backend
from exohil.estimator.trained import TrainedEstimator
from exohil.formats.alignment import angles_at
from exohil.formats.atomic import same_file
from exohil.formats.digest import sha256_file
from exohil.formats.errors import InputError, RecordingError
from exohil.formats.measurement import DISTRIBUTION_STATS, Limit, Measurement, distribution
from exohil.formats.recording import AngleStream, Recording, Segment, SensorStream
from exohil.formats.recording_metadata import DEFAULT_SENSOR_RATE_HZ
from exohil.formats.wire import SEQ_MODULUS, TIME_MODULUS_US, WIRE_UNITS, off_the_wire
from exohil.harness.bench import (
    BenchConfig,
    BenchError,
    EmulatorDevice,
    SerialDevice,
    device_rate_hz,
    open_device,
)
from exohil.harness.frame_source import Frame, LinkStats
from exohil.harness.machine import HostLoad, HostLoadMeter
from exohil.harness.pipeline import (
    FrameRows,
    Pipeline,
    PipelineRun,
    RowsObserver,
    Sample,
    Sink,
    Status,
)
from exohil.harness.recorder import RecorderSink, partial_path
from exohil.harness.robot_stats import LogHistogram
from exohil.harness.robot_trace import RobotTrace, RobotTraceSink
from exohil.harness.teleop import HYSTERESIS_DEG, SHOULDER_ANGLES, SimulatedNao, TeleopSink
from exohil.kinematics import NAO_JOINTS, humerus_to_nao, ms_to_quat
from exohil.kinematics.robot import Side

Limits = Mapping[str, Limit]
Progress = Callable[[Status], None]

#: Interval measurements: name → (from stage, to stage).
LATENCY_INTERVALS = {
    "latency.device_to_host": ("device_write", "host_receive"),
    "latency.decode": ("host_receive", "decoded"),
    "latency.queue_and_estimate": ("decoded", "estimated"),
    "latency.command": ("estimated", "commanded"),
}


#: Frames with ground truth whose robot commands are kept to be scored at the end of a session
#: (``teleop.rmse.*``): 2**20, 70 min at 250 Hz, 48 MiB. Mapping a true pose to its command
#: takes ~0.3 ms, too long for the pipeline's thread, so it is done after the run.
TELEOP_MAX_FRAMES = 1 << 20


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


def on_host_clock(reference: Recording) -> Recording:
    """``reference`` on the clock the host unwraps the device's time to: the wire carries
    32-bit µs (docs/wire-protocol.md), so an emulator replaying a recording whose first frame
    lies 2³² µs (71.6 min) or more after 0 (another tool's Unix time, 1.7e9 s; a part cut late
    from a long session) sends it modulo 2³² µs, and the host's device times start there. Its
    times are moved back by those whole wraps; a reference that starts before the first wrap
    is returned as it is."""
    if not len(reference.sensors):
        return reference
    wraps = round(float(reference.sensors.t[0]) * 1e6) // TIME_MODULUS_US
    if wraps <= 0:
        return reference
    shift = wraps * TIME_MODULUS_US / 1e6
    sensors = SensorStream(reference.sensors.seq, reference.sensors.t - shift,
                           reference.sensors.values)
    mocap = {joint: AngleStream(stream.t - shift, stream.names, stream.angles)
             for joint, stream in reference.mocap.items()}
    segments = [Segment(seg.name, seg.t0 - shift, seg.t1 - shift) for seg in reference.segments]
    return replace(reference, sensors=sensors, mocap=mocap, segments=segments)


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
        from exohil.harness.robot_udp import UdpJointTarget, parse_udp_address

        try:
            host, port = parse_udp_address(name)
        except ValueError as err:
            raise BenchError(str(err)) from None
        try:
            return UdpJointTarget(host, port)
        except ValueError as err:
            raise BenchError(f"robot {name!r}: {err}") from None
    raise BenchError(f"unknown robot {name!r}; available: simulated, mujoco, udp:HOST:PORT")


class TruthTally:
    """Scores every frame against the reference as the run goes (a pipeline observer).

    Accuracy is summed block by block (:class:`~exohil.estimator.evaluation.AccuracyTally`).
    With teleoperation, the robot command and the true (θ, φ) of the frames with ground truth
    are kept (at most :data:`TELEOP_MAX_FRAMES`, the first ones) and compared at the end with
    the commands the kinematics give for the true angles (:func:`nao_commands_for`,
    :meth:`teleop_errors_deg`); the true angles are also fed through a fresh
    :class:`TeleopSink`, the way the run feeds its estimates, to check the sink's wiring
    against those commands (:meth:`teleop_mapping_error_deg`).
    """

    def __init__(self, reference: Recording, est: TrainedEstimator, teleop: bool) -> None:
        self.reference, self.est = reference, est
        self.accuracy = AccuracyTally(est.target.angles)
        self.teleop = teleop
        angles = est.target.angles
        self._shoulder = [angles.index(a) for a in SHOULDER_ANGLES] if teleop else []
        self._commands: list[np.ndarray] = []
        self._truth: list[np.ndarray] = []
        self._times: list[np.ndarray] = []
        self.teleop_frames = 0  #: frames with ground truth and a command
        self.teleop_kept = 0  #: of those, the ones kept to score (the first ones)
        self._errors: np.ndarray | None = None
        self._reference: np.ndarray | None = None

    def __call__(self, rows: FrameRows) -> None:
        truth = truth_at(self.reference, self.est, rows.device_time_s)
        self.accuracy.add(rows.estimates, truth)
        if not self.teleop:
            return
        ok = np.all(np.isfinite(truth), axis=1) & np.all(np.isfinite(rows.commands), axis=1)
        count = int(ok.sum())
        self.teleop_frames += count
        take = np.flatnonzero(ok)[:max(0, TELEOP_MAX_FRAMES - self.teleop_kept)]
        if take.size:
            self._commands.append(rows.commands[take].copy())
            self._truth.append(truth[take][:, self._shoulder])
            self._times.append(np.asarray(rows.device_time_s)[take].copy())
            self.teleop_kept += int(take.size)

    def _kept_truth(self) -> np.ndarray:
        """(K, 2) true (θ, φ) of the kept frames, deg."""
        return np.concatenate(self._truth) if self._truth else np.empty((0, 2))

    def _reference_commands(self) -> np.ndarray:
        """(K, 3) NAO commands for the true angles of the kept frames, rad (computed once)."""
        if self._reference is None:
            self._reference = nao_commands_for(self._kept_truth())
        return self._reference

    def teleop_errors_deg(self) -> np.ndarray:
        """(K, 3) robot command minus the command the kinematics give for the true angles
        (:func:`nao_commands_for`), deg, of the kept frames (computed once)."""
        if self._errors is None:
            commands = (np.concatenate(self._commands) if self._commands
                        else np.empty((0, 3)))
            self._errors = np.rad2deg(commands - self._reference_commands())
        return self._errors

    def teleop_mapping_error_deg(self) -> float:
        """Largest |joint difference|, deg, over the kept frames, between what a fresh
        :class:`TeleopSink` built as the run builds its own commands for the true angles
        (fed as the run feeds it: a :class:`Sample` of every estimator output, in the
        estimator's order, through ``accept`` to a robot target) and
        :func:`nao_commands_for` of the same angles; NaN without kept frames."""
        truth = self._kept_truth()
        if not truth.shape[0]:
            return float("nan")
        robot = _CommandLog()
        sink = TeleopSink([robot], self.est.target.angles)
        angles = np.full(len(self.est.target.angles), np.nan)
        for i, (pose, t) in enumerate(zip(truth, np.concatenate(self._times), strict=True)):
            angles[self._shoulder] = pose
            sink.accept(Sample(Frame(i, float(t), np.empty(0), 0), angles.copy()))
        sent = np.array(robot.joints).reshape(-1, 3)
        if sent.shape != truth.shape[:1] + (3,):
            return float("inf")  # a command not sent, or sent twice, to the robot
        return float(np.max(np.abs(np.rad2deg(sent - self._reference_commands()))))


class _CommandLog:
    """A robot target that keeps every joint command it receives (rad, NAO_JOINTS order)."""

    def __init__(self) -> None:
        self.joints: list[np.ndarray] = []

    def command(self, t: float, joints: np.ndarray, clamped: np.ndarray) -> None:
        self.joints.append(np.array(joints, dtype=float))


def nao_commands_for(truth_deg: np.ndarray, side: Side = "right") -> np.ndarray:
    """(K, 3) NAO (ShoulderPitch, ShoulderRoll, ElbowYaw) commands, rad, for K MoBL-ARMS
    (θ, φ) poses in deg, taken as a stream, straight from the kinematics: ψ = 0 (the suit does
    not measure it; :class:`TeleopSink` holds it at 0), ideal axes, the coupled convention,
    and each pose's hint the previous pose's command with the sink's hysteresis
    (docs/conventions.md). The reference the teleop check scores the sink against. A pose's
    hint matters only where some joint is clamped (a tie, a choice between two limits), so all
    poses are solved at once without hints and those alone again, one by one in order."""
    truth = np.asarray(truth_deg, dtype=float).reshape(-1, 2)
    if not truth.shape[0]:
        return np.empty((0, 3))
    q = ms_to_quat(np.deg2rad(truth[:, 0]), np.deg2rad(truth[:, 1]), 0.0)
    first = humerus_to_nao(q, side=side)  # no hint: the first pose's command, and every pose
    angles = first.angles.copy()          # where nothing is clamped
    sticky = np.deg2rad(HYSTERESIS_DEG)
    for k in np.flatnonzero(first.any_clamped):
        if k:
            angles[k] = humerus_to_nao(q[k], side=side, hint=angles[k - 1],
                                       hysteresis=sticky).angles
    return angles


class LinkTally:
    """The frames the host processed against those the emulator sent (a pipeline observer):
    counts frames whose values differ from what it sent for that sequence number, and keeps
    the gaps in the sequence numbers, to reconcile with its fault log at the end
    (:meth:`lost_on_host`). A frame older than one already processed (never on a serial link)
    fills no gap; it is counted in ``late``."""

    def __init__(self, wire_values_mm: np.ndarray, seq0: int) -> None:
        self.wire, self.seq0 = wire_values_mm, seq0
        self.bad = 0  #: frames whose values differ from what the device sent
        self.late = 0  #: frames whose seq is not above every one before
        self._high: int | None = None  # the highest seq so far
        self._gaps: list[np.ndarray] = []  # (G, 2): first and last missing seq

    def __call__(self, rows: FrameRows) -> None:
        seq = rows.seq
        wire = self.wire[(seq - self.seq0) % self.wire.shape[0]]
        self.bad += int(np.count_nonzero(np.any(np.abs(rows.values - wire) > 1e-9, axis=1)))
        before = np.maximum.accumulate(np.concatenate((
            [seq[0] - 1 if self._high is None else self._high], seq[:-1])))
        self.late += int(np.count_nonzero(seq <= before))
        gap = seq > before + 1
        if gap.any():
            self._gaps.append(np.column_stack((before[gap] + 1, seq[gap] - 1)))
        self._high = int(max(before[-1], seq[-1]))

    def release(self) -> None:
        """Let go of the device's values (as long as the run) once the run is over."""
        self.wire = np.empty((1, self.wire.shape[1]))

    def lost_on_host(self, logged_lost: np.ndarray) -> int:
        """Sequence numbers missing between the processed frames and not among
        ``logged_lost`` (sorted unique seqs the device logged as lost)."""
        if not self._gaps:
            return 0
        gaps = np.concatenate(self._gaps)
        logged = (np.searchsorted(logged_lost, gaps[:, 1], side="right")
                  - np.searchsorted(logged_lost, gaps[:, 0], side="left"))
        return int(np.sum(gaps[:, 1] - gaps[:, 0] + 1 - logged))


def unseen_wraps(seq0: int) -> int:
    """The counts of a device's numbering that the host cannot see, for a device whose first
    frame is numbered ``seq0``: the wire carries seq mod 65536 and the host counts on from
    the first value it receives, so host seq = device seq − this."""
    return seq0 - seq0 % SEQ_MODULUS


def _nothing_decoded_hint(crc_errors: int, decode_errors: int, sensors: int,
                          bytes_read: int = 0) -> str:
    """Why no frame was decoded, from what the link rejected (" (…)", or "" if nothing):
    packets of another shape alone suggest another sensor count; failed CRCs, a link that
    corrupts what it carries; bytes with no packet in them at all (no 0x00 delimiter, e.g.
    text), a device that does not speak the wire protocol."""
    seen = [f"{n} packets {what}" for n, what in ((crc_errors, "failed their CRC"),
                                                  (decode_errors, "had another shape")) if n]
    if not seen:
        if not bytes_read:
            return ""
        return (f" ({bytes_read} bytes arrived and none was a wire-protocol v1 frame: is the "
                "device running another sketch (e.g. printing text) or another protocol, or is "
                "this the wrong port? flash firmware/exohil_due, see docs/wire-protocol.md)")
    guess = (f"does the device send {sensors} sensors?" if not crc_errors else
             "a link that corrupts what it carries?")
    return f" ({', '.join(seen)}: {guess})"


@dataclass
class SessionResult:
    """Everything one session produced (see :func:`run_session`).

    ``truth`` holds the true angles at the device times of the run's kept rows (``run``'s
    per-frame attributes); ``scoring`` and ``link_tally`` were folded over every frame."""

    config: BenchConfig
    model: LoadedModel
    run: PipelineRun
    truth: np.ndarray | None
    fault_log: list[Any] | None
    emulator_seq0: int | None
    clipped_values: int
    #: how busy the host's CPUs were while the session streamed
    host_load: HostLoad
    robots: list[Any] = field(default_factory=list)
    robot_trace: RobotTrace | None = None
    #: why the device stopped before the run's end (a device that never came back), or None
    device_lost: str | None = None
    #: accuracy and teleoperation against the reference (None without one)
    scoring: TruthTally | None = None
    #: the host's frames against the emulator's (None for another device)
    link_tally: LinkTally | None = None
    #: the received readings against those the model was trained on (every frame)
    coverage: CoverageTally | None = None
    #: the device's nominal frame rate (:func:`~exohil.harness.bench.device_rate_hz`), Hz
    sensor_rate_hz: float = DEFAULT_SENSOR_RATE_HZ
    #: why the run streamed less than it was asked to: stopped on request (``stop``, e.g.
    #: Ctrl-C), or an emulator's recording that ended before the seconds asked for; or None
    ended_early: str | None = None

    @property
    def fault_counts(self) -> dict[str, int] | None:
        if self.fault_log is None:
            return None
        return dict(Counter(record.kind for record in self.fault_log))


def run_session(config: BenchConfig, seconds: float | None, *,
                progress: Progress | None = None,
                stop: threading.Event | None = None, extra_sinks: Sequence[Sink] = (),
                realtime: bool = False, keep_frames: tuple[int, int] | None = None,
                reference: Recording | None = None) -> SessionResult:
    """Stream ``seconds`` of the bench's device through its model into its sinks.

    An emulator streams exactly ``seconds`` of device time and the run ends once every frame
    it sent has been processed, so its fault log and the host's counters cover the same
    frames; a serial device is read for ``seconds`` of wall time. ``seconds=None`` runs until
    ``stop`` is set (or, for the emulator, to the end of its recording; for a serial device with
    a reference, until the device's clock passes the reference's end: an outage shorter than
    ``DEVICE_TIMEOUT_S`` is ridden out, and a device that stops before that end is
    ``device_lost``). Setting ``stop`` ends any run early, and the result covers what was
    processed; its ``ended_early`` says so. ``keep_frames`` = (first, last)
    sets how many per-frame rows the run keeps (default: the pipeline's); every figure covers
    every frame regardless. ``reference``: the bench's reference recording when the caller
    has already read it (else it is read here).
    """
    if seconds is not None and not 0 < seconds < math.inf:
        raise SessionError(f"seconds must be a finite number > 0 (or None: until stopped), "
                           f"got {seconds!r}")
    if config.device is None:
        raise SessionError("no device: give a target (emulator:RECORDING or a serial URL)")
    if config.model is None:
        raise SessionError("no model: give a checkpoint")
    model = load_model(config.model, config.backend)
    est = model.estimator
    if config.sensor_names is not None and tuple(config.sensor_names) != est.sensor_names:
        raise SessionError(f"the bench's sensors {list(config.sensor_names)} are not the "
                           f"model's {list(est.sensor_names)}")
    units = est.info.get("sensor_units")
    why = None if units is None else off_the_wire(units)  # a device's frames come over it
    if why is not None:
        raise SessionError(f"{config.model}: the model's {why}, and a device streams over it "
                           f"(train a model on recordings in {WIRE_UNITS})")
    ref_path = reference_path(config)
    if ref_path is None:
        reference = None
    elif reference is None:
        reference = read_reference(ref_path)
    why = None if reference is None else off_the_wire(reference.sensor_units)
    if why is not None and isinstance(config.device, EmulatorDevice):
        raise SessionError(f"{ref_path}: {why}, and the emulator streams the recording over it")
    if reference is not None:
        try:
            ensure_fits(est, reference, str(ref_path))
        except CheckpointError as err:
            raise SessionError(str(err)) from None
    inputs = [p for p in (config.model, ref_path) if p is not None]
    if config.record is not None and same_file(config.record, inputs) is not None:
        raise SessionError(f"refusing to record onto an input: {config.record}")
    if config.record is not None and partial_path(config.record).exists():
        left = partial_path(config.record)
        raise SessionError(f"{left} is what a run that was stopped short recorded; recover it "
                           f"(exohil record recover {left} --out FILE) or remove it first")
    # the reference as the host's device times see it; the emulator replays it as it is
    truth_ref = None if reference is None else on_host_clock(reference)
    if progress is not None and truth_ref is not None:
        progress = _with_running_error(progress, truth_ref, est)
    rate_hz = device_rate_hz(config, reference)
    robots: list[Any] = []
    sinks: list[Sink] = []
    tracer = None
    scoring = None
    link_tally = None
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
            sinks.append(RecorderSink(config.record, est.sensor_names, metadata={
                "generator": "exohil", "source": config.device.describe(),
                "model_sha256": model.sha256}, sensor_rate_hz=rate_hz))
        coverage = CoverageTally(est)
        observers: list[RowsObserver] = [lambda rows: coverage.add(rows.values)]
        if truth_ref is not None:
            scoring = TruthTally(truth_ref, est, teleop=bool(robots))
            observers.append(scoring)
        meter = HostLoadMeter()
        with open_device(config.device, len(est.sensor_names), realtime=realtime,
                         duration_s=seconds, recording=reference) as opened:
            for sink in sinks:
                if isinstance(sink, RecorderSink):
                    sink.link_stats = opened.source.stats
            if opened.emulator is not None:
                seq0 = opened.emulator.seq0
                link_tally = LinkTally(opened.emulator.wire_values_mm,
                                       seq0 - unseen_wraps(seq0))
                observers.append(link_tally)
            keep = {} if keep_frames is None else {"keep_first": keep_frames[0],
                                                   "keep_last": keep_frames[1]}
            pipeline = Pipeline(opened.source, model.engine(), sinks, opened.device_clock,
                                observers=observers, **keep)
            short = None
            if opened.emulator is not None:
                # until every frame the emulator sent is processed, outages included
                limit = None if seconds is None else seconds + 30.0
                emulator = opened.emulator
                run = pipeline.run(duration_s=limit, stop=stop, progress=progress,
                                   source_done=lambda: emulator.finished)
                stopped = stop is not None and stop.is_set()
                # a looped replay without seconds streams until stopped: that is its end
                looped = isinstance(config.device, EmulatorDevice) and config.device.loop
                early = stopped and (seconds is not None or not looped)
            else:
                end, wall = None, seconds
                if seconds is None and truth_ref is not None and len(truth_ref.sensors):
                    t = truth_ref.sensors.t
                    end = float(t[-1]) - 1.5 / truth_ref.sensor_rate_hz  # its last frame
                    wall = float(t[-1] - t[0]) + 60.0  # a device that never gets there
                # no idle timeout: an outage shorter than DEVICE_TIMEOUT_S is ridden out (the
                # reader reconnects), a longer one ends the reader, and so the run
                source = opened.source
                run = pipeline.run(duration_s=wall, stop=stop, progress=progress,
                                   until_device_time_s=end,
                                   source_done=lambda: not source.alive)
                stopped = stop is not None and stop.is_set()
                short = _short_of_reference(run, end, stopped=stopped)
                # without seconds or a reference the run lasts until stopped: no early end
                early = stopped and (seconds is not None or end is not None)
            device_lost = short
            if opened.source.device_timed_out:
                device_lost = "; ".join(why for why in (
                    opened.source.last_error or "the device stopped sending", short) if why)
            last_error = opened.source.last_error
            emulator = opened.emulator
            fault_log = None if emulator is None else emulator.fault_log
            seq0 = None if emulator is None else emulator.seq0
            clipped = 0 if emulator is None else emulator.clipped_values
        host_load = meter.stop()
    except (ValueError, RecordingError) as err:
        raise SessionError(str(err)) from None
    finally:
        for sink in sinks:
            sink.close()
        if link_tally is not None:
            link_tally.release()
    if run.frames == 0:
        hint = _nothing_decoded_hint(run.link.crc_errors, run.link.decode_errors,
                                     len(est.sensor_names), run.link.bytes_read)
        problem = (config.device.path_problem() if isinstance(config.device, SerialDevice)
                   else None) or device_lost or last_error
        why = f": {problem}" if problem else ""
        raise SessionError(f"no frame arrived from the {config.device.describe()}{hint}{why}")
    truth = None if truth_ref is None else truth_at(truth_ref, est, run.device_time_s)
    trace = None if tracer is None else tracer.trace()
    if trace is not None and truth_ref is not None:
        angles = truth_at(truth_ref, est, trace.device_time_s)
        shoulder = [est.target.angles.index(a) for a in SHOULDER_ANGLES]
        trace = replace(trace, truth_deg=angles[:, shoulder])
    ended_early = "; ".join(why for why in (_stopped_early(run, early),
                                            _recording_ended(config, reference, seconds)) if why)
    return SessionResult(config, model, run, truth, fault_log, seq0, clipped, host_load, robots,
                         trace, device_lost, scoring, link_tally, coverage, rate_hz,
                         ended_early or None)


def _stopped_early(run: PipelineRun, early: bool) -> str | None:
    """What a run stopped on request (``stop`` set while it streamed) before the end it was
    given (seconds, a reference's end, an emulator's recording) covers, or None."""
    if not early:
        return None
    return (f"stopped on request (Ctrl-C or SIGTERM) at device time "
            f"{run.last_device_time_s:.3f} s, after {run.frames} frames: every figure covers "
            "only those")


def _short_of_reference(run: PipelineRun, end: float | None, stopped: bool) -> str | None:
    """Why a serial device streamed to a reference's end (device time ``end``, s) stopped
    short of it (silent for the device timeout, or past the run's wall-time bound), or None
    (reached, no such end, stopped on request, or nothing arrived: an error of its own)."""
    if end is None or stopped or run.frames == 0 or run.last_device_time_s >= end:
        return None
    return (f"its last frame came at device time {run.last_device_time_s:.3f} s, before the "
            f"reference's end ({end:.3f} s)")


def _recording_ended(config: BenchConfig, recording: Recording | None,
                     seconds: float | None) -> str | None:
    """Why an emulator replaying ``recording`` once streamed less than ``seconds``, or None."""
    device = config.device
    if not isinstance(device, EmulatorDevice) or device.loop or seconds is None \
            or recording is None:
        return None
    held_s = len(recording.sensors) / recording.sensor_rate_hz
    if held_s + 1.0 / recording.sensor_rate_hz >= seconds:
        return None
    return (f"the recording holds {held_s:.1f} s of frames, so the run streamed those, not the "
            f"{seconds:g} s asked for (loop = true under a bench file's [device] replays it)")


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


def latency_histograms(run: PipelineRun) -> dict[str, tuple[LogHistogram, str]]:
    """Every frame's time (ms) of each latency measurement, as a histogram, by name, with what
    it spans: the stage intervals, the estimator's compute, and end to end from the device's
    write (when known, else host receive) to the robot command (else the sinks done)."""
    out = {name: (run.interval_histogram(a, b), f"{a} → {b}")
           for name, (a, b) in LATENCY_INTERVALS.items()}
    out["latency.estimator"] = (run.compute_ms, "estimator compute per frame")
    start_stage = "device_write" if run.stamped["device_write"] else "host_receive"
    end_stage = "commanded" if run.stamped["commanded"] else "done"
    out["latency.end_to_end"] = (run.interval_histogram(start_stage, end_stage),
                                 f"{start_stage} → {end_stage}")
    return out


def histogram_distribution(name: str, hist: LogHistogram, unit: str,
                           limits: Mapping[str, Limit] | None = None,
                           note: str = "") -> list[Measurement]:
    """p50, p99 and max of ``hist`` as measurements ``name.p50`` etc. (as
    ``measurement.distribution`` gives them for samples); the quantiles are exact to one bin
    (1.2 %), the maximum exact. Skipped when empty."""
    limits = limits or {}
    if hist.count == 0:
        return [Measurement.skipped(f"{name}.{stat}", unit, "no samples", limits.get(stat))
                for stat in DISTRIBUTION_STATS]
    values = {"p50": hist.quantile(0.5), "p99": hist.quantile(0.99), "max": hist.max}
    counted = f"{hist.count} samples" + (f"; {note}" if note else "")
    return [Measurement.judge(f"{name}.{stat}", float(values[stat] or 0.0), unit,
                              limits.get(stat), counted) for stat in DISTRIBUTION_STATS]


def latency_measurements(run: PipelineRun, limits: Limits | None = None) -> list[Measurement]:
    """p50/p99/max, ms, of each of :func:`latency_histograms` (every frame of the run).
    ``limits`` maps e.g. ``latency.end_to_end.max`` to its limit."""
    limits = limits or {}
    out: list[Measurement] = []
    for name, (hist, note) in latency_histograms(run).items():
        out += histogram_distribution(name, hist, "ms", _stat_limits(limits, name), note)
    return [_with_largest_part(m, out) for m in out]


def _with_largest_part(m: Measurement, every: list[Measurement]) -> Measurement:
    """An end-to-end figure that failed its limit, with the stage of the chain (the
    intervals of :data:`LATENCY_INTERVALS`) whose same statistic is largest named in its
    note, so a failed gate says where the time went; any other measurement as it is."""
    head, _, stat = m.name.rpartition(".")
    if not m.failed or head != "latency.end_to_end":
        return m
    parts = {p.name: p.value for p in every
             if p.name.rpartition(".")[0] in LATENCY_INTERVALS and p.name.endswith("." + stat)
             and math.isfinite(p.value)}
    if not parts:
        return m
    largest = max(parts, key=lambda name: parts[name])
    return replace(m, note=f"{m.note}; largest part: {largest} = {parts[largest]:.3g} ms")


def coverage_measurement(tally: CoverageTally, limits: Limits | None = None) -> Measurement:
    """``compatibility.outside_training``: the share of frames with a reading outside the
    model's training data (:mod:`exohil.estimator.coverage`), %; skipped without a frame."""
    name = "compatibility.outside_training"
    limit = (limits or {}).get(name)
    if tally.outside_percent is None:
        return Measurement.skipped(name, "%", "no frame with finite readings", limit)
    return Measurement.judge(name, tally.outside_percent, "%", limit, tally.note())


def session_coverage(result: SessionResult) -> list[Measurement]:
    """The received readings against the model's training data (none for a result made
    without a tally)."""
    return [] if result.coverage is None else [coverage_measurement(result.coverage)]


def link_measurements(result: SessionResult, limits: Limits | None = None) -> list[Measurement]:
    """Host link counters and, for the emulator, their reconciliation with its fault log:

    * ``link.lost_on_host``: frames the device handed over that never reached the pipeline
      (buffer overflow, or a gap the device did not log), must be 0;
    * ``link.bad_frames_delivered``: frames whose values differ from what the device sent for
      that sequence number (a CRC that let corruption through), must be 0;
    * ``link.dropped_unexplained``: host-counted drops minus the device's logged losses
      within the received span, must be 0.

    Another device keeps no fault log, so nothing it loses is explained: those three are
    skipped and what the host can see is judged instead (:func:`device_link_measurements`).
    """
    limits = limits or {}
    run = result.run
    link = run.link

    def m(name: str, value: float, unit: str = "count", note: str = "") -> Measurement:
        return Measurement.judge(name, value, unit, limits.get(name), note)

    span = run.last_device_time_s - run.first_device_time_s if run.frames > 1 else 0.0
    rate = (run.frames - 1) / span if span > 0 else float("nan")
    out = [m("link.frames", run.frames),
           m("link.rate", rate, "Hz", note="frames received per second of device time"),
           m("link.dropped", link.dropped, note="sequence gaps seen by the host"),
           m("link.crc_errors", link.crc_errors), m("link.decode_errors", link.decode_errors),
           m("link.overflow", link.overflow, note="frames the host buffer discarded")]
    tally = result.link_tally
    if (result.fault_log is None or tally is None or run.first_seq is None
            or run.last_seq is None):
        why = ("no device fault log (not the in-process emulator) to reconcile with; "
               "link.lost, link.rejected, link.sequence_resets and link.disconnects judge "
               "what the host saw")
        for name in ("link.lost_on_host", "link.bad_frames_delivered",
                     "link.dropped_unexplained"):
            out.append(Measurement.skipped(name, "count", why, limits.get(name)))
        return out + device_link_measurements(link, limits)
    first, last = run.first_seq, run.last_seq
    hidden = unseen_wraps(result.emulator_seq0 or 0)  # the device logs in its numbering
    lost = {r.seq - hidden for r in result.fault_log
            if r.kind in LOSING_KINDS and first <= r.seq - hidden <= last}
    expected = last - first + 1 - len(lost)
    late = f"; {tally.late} frames arrived out of order" if tally.late else ""
    out += [
        m("link.lost_on_host", tally.lost_on_host(np.array(sorted(lost), dtype=np.int64)),
          note=f"{expected} frames the device delivered in seq {first}..{last}{late}"),
        m("link.bad_frames_delivered", tally.bad,
          note="values differ from what the device sent"),
        m("link.dropped_unexplained", link.dropped - len(lost),
          note=f"host {link.dropped} vs device log {len(lost)} in the received span"),
    ]
    return out


def device_link_measurements(link: LinkStats, limits: Limits | None = None) -> list[Measurement]:
    """What the host sees of a device's link, where no fault log explains any of it (a real
    device): every frame lost, rejected, every reboot and disconnect is the device's or the
    link's fault.

    * ``link.lost``: frames missing from the device's stream: sequence gaps (``dropped``,
      disconnects included) plus the frames missed across sequence resets, by host time at
      the device's period (``dropped_in_resets``: a reboot restarts the numbering, so
      sequence numbers alone cannot see them);
    * ``link.rejected``: packets the host could not use: failed CRC, wrong shape,
      valid-CRC frames whose header did not fit the stream (``implausible``) or repeated
      one already taken (``duplicates``: also what a reboot within 1024 frames of the
      first looks like, its new numbering repeating the first frames');
    * ``link.sequence_resets``: times the device's numbering restarted (a reboot);
    * ``link.disconnects``: times the port was lost (e.g. USB re-enumeration).
    """
    limits = limits or {}

    def m(name: str, value: float, note: str) -> Measurement:
        return Measurement.judge(name, value, "count", limits.get(name), note)

    return [
        m("link.lost", link.dropped + link.dropped_in_resets,
          f"{link.dropped} by sequence gaps ({link.dropped_in_disconnects} across "
          f"disconnects), {link.dropped_in_resets} across {link.sequence_resets} sequence "
          "reset(s) by host time"),
        m("link.rejected", link.crc_errors + link.decode_errors + link.implausible
          + link.duplicates,
          f"{link.crc_errors} failed CRC, {link.decode_errors} of another shape, "
          f"{link.implausible} implausible headers, {link.duplicates} duplicates"),
        m("link.sequence_resets", link.sequence_resets,
          "the device's numbering restarted (a reboot)"),
        m("link.disconnects", link.disconnects,
          f"the port was lost; {link.reconnects} reconnect(s), {link.wrong_device} refused "
          "as another device"),
    ]


def teleop_measurements(result: SessionResult,
                        limits: Limits | None = None) -> list[Measurement]:
    """Robot commands from the estimates against the commands the kinematics give for the
    true angles (:func:`nao_commands_for`): RMSE per joint (deg, over the frames with ground
    truth, at most :data:`TELEOP_MAX_FRAMES`) and the share of clamped commands (every frame);
    and ``teleop.mapping_error`` (deg), the largest difference between the teleoperation
    sink's commands for the true angles and those of :func:`nao_commands_for`, which catches
    a wiring error in the sink that the RMSE (estimate errors and all) cannot tell apart."""
    limits = limits or {}
    run, scoring = result.run, result.scoring
    names = [f"teleop.rmse.{j}" for j in NAO_JOINTS]
    if scoring is None or not result.robots or run.commanded == 0:
        why = "no reference" if scoring is None else "no teleoperation (not a shoulder model)"
        return [Measurement.skipped(n, "deg", why, limits.get(n))
                for n in [*names, "teleop.mapping_error"]]
    err = scoring.teleop_errors_deg()
    note = f"{scoring.teleop_kept} frames"
    if scoring.teleop_kept < scoring.teleop_frames:
        note += f" (the first of {scoring.teleop_frames} with ground truth)"
    out = [Measurement.judge(n, float(np.sqrt(np.mean(err[:, j] ** 2))), "deg", limits.get(n),
                             note) if err.shape[0] else
           Measurement.skipped(n, "deg", "no frame with both a command and the truth",
                               limits.get(n)) for j, n in enumerate(names)]
    mapping, limit = scoring.teleop_mapping_error_deg(), limits.get("teleop.mapping_error")
    out.append(Measurement.skipped("teleop.mapping_error", "deg",
                                   "no frame with both a command and the truth", limit)
               if math.isnan(mapping) else Measurement.judge(
        "teleop.mapping_error", mapping, "deg", limit,
        f"the sink's commands for the true angles of {scoring.teleop_kept} frames against the "
        "kinematics' (humerus_to_nao), largest |difference|"))
    share = run.clamped_commands / run.frames if run.frames else float("nan")
    out.append(Measurement.judge("teleop.clamped_share", share, "ratio",
                                 limits.get("teleop.clamped_share"),
                                 "commands with a joint at its limit"))
    return out


def session_accuracy(result: SessionResult, limits: Limits | None = None) -> list[Measurement]:
    """Accuracy of the streamed estimates against the reference, every frame (skipped without
    one)."""
    est = result.model.estimator
    if result.scoring is None:
        names = [f"accuracy.rmse.{a}" for a in est.target.angles]
        if _is_shoulder(est):
            names.append("accuracy.direction_rmse")
        return [Measurement.skipped(n, "deg", "no reference recording", (limits or {}).get(n))
                for n in names]
    return result.scoring.accuracy.measurements(limits)


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
