"""What one conformance run measures, shared by its checks.

:class:`ConformanceRun` holds the target, the model, the profile and (optionally) the
reference and the baseline, and computes each expensive piece once, on first use:

* the *replay*: every sensor frame of the reference recording pushed through the same
  streaming engine the pipeline uses, as fast as it goes (the accuracy check);
* the *real-time session*: ``realtime_seconds`` of the device over its serial link at its
  own rate, through the whole pipeline with teleoperation (latency, link, teleop checks).

Each ``*_measurements`` method returns the measurements of one check with the profile's
limits; the pytest check (``test_checks.py``) records and judges them.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import cached_property
from pathlib import Path

import numpy as np

from exohil.conformance.conversions import run_properties
from exohil.conformance.profile import Profile
from exohil.estimator.coverage import CoverageTally, stream_coverage
from exohil.estimator.evaluation import accuracy_measurements
from exohil.estimator.rates import same_rate
from exohil.formats.alignment import angles_at_sensor_times
from exohil.formats.measurement import Limit, Measurement, distribution
from exohil.formats.recording import Recording
from exohil.formats.recording_metadata import shared_frames, source_entry
from exohil.harness.bench import (
    BenchConfig,
    Device,
    EmulatorDevice,
    SerialDevice,
    parse_target,
)
from exohil.harness.machine import HostLoad
from exohil.harness.pipeline import Status
from exohil.harness.session import (
    LoadedModel,
    SessionError,
    SessionResult,
    coverage_measurement,
    latency_measurements,
    link_measurements,
    load_model,
    read_reference,
    reference_path,
    run_session,
    session_accuracy,
    sha256_file,
    teleop_measurements,
)

#: The share of the profile's ``realtime_seconds`` a real-time segment must cover.
SEGMENT_SHARE = 0.9
#: The share of a device's reference (its sensor frames' times) that the segment streamed to
#: its end must cover for accuracy to be judged (``accuracy.reference_coverage``, %).
REFERENCE_SHARE = 0.9


class CheckBlocked(Exception):
    """A check cannot be measured (the message says why); it is reported as skipped."""


@dataclass
class Replay:
    """The reference recording replayed through the model: estimates and truth, degrees."""

    estimates: np.ndarray
    truth: np.ndarray
    seconds: float


class ConformanceRun:
    """One target × model × profile (see module doc)."""

    def __init__(self, target: str | Device, model: Path, profile: Profile, *,
                 reference: Path | None = None, baseline: Path | None = None,
                 backend: str = "auto", say: Callable[[str], None] = lambda line: None,
                 sensor_names: tuple[str, ...] | None = None,
                 rate_hz: float | None = None) -> None:
        device = parse_target(target) if isinstance(target, str) else target
        if isinstance(device, EmulatorDevice) and device.faults is None:
            device = EmulatorDevice(device.recording, profile.setting("faults") or None,
                                    profile.setting("seed"))
        if isinstance(device, SerialDevice) and reference is not None:
            device = SerialDevice(device.url, reference)
        self.target = target if isinstance(target, str) else device.describe()
        self.device = device
        self.profile = profile
        self.model_path = Path(model)
        self.baseline_path = None if baseline is None else Path(baseline)
        self.backend = backend
        #: what a bench file states of its device ([sensors] names, rate_hz), if anything
        self.bench_sensor_names, self.bench_rate_hz = sensor_names, rate_hz
        self.config = BenchConfig(device=device, model=self.model_path, backend=backend,
                                  sensor_names=sensor_names, rate_hz=rate_hz)
        self.say = say  #: progress lines for long steps
        self.started = time.time()

    # ---- shared pieces ---------------------------------------------------------------
    @cached_property
    def model(self) -> LoadedModel:
        return load_model(self.model_path, self.backend)

    @cached_property
    def reference_file(self) -> Path | None:
        return reference_path(self.config)

    @cached_property
    def reference(self) -> Recording | None:
        path = self.reference_file
        return None if path is None else read_reference(path)

    def compatible_reason(self) -> str | None:
        """Why the model cannot run on this target's data, or None."""
        bench = self._bench_mismatch()
        if bench:
            return "; ".join(m.note for m in bench)
        rec, est = self.reference, self.model.estimator
        if rec is None:
            return None
        if tuple(rec.sensor_names) != est.sensor_names:
            return (f"the model expects {len(est.sensor_names)} sensors "
                    f"{list(est.sensor_names)}; the device's recording has "
                    f"{len(rec.sensor_names)} {list(rec.sensor_names)}")
        stream = rec.mocap.get(est.target.joint)
        missing = [a for a in est.target.angles if stream is None or a not in stream.names]
        if missing:
            return f"the reference has no {est.target.joint} angle(s) {missing}"
        return None

    def _require_compatible(self) -> None:
        reason = self.compatible_reason()
        if reason is not None:
            raise CheckBlocked(f"incompatible model and device ({reason}); see compatibility")

    @cached_property
    def replay(self) -> Replay:
        self._require_compatible()
        rec = self.reference
        if rec is None:
            raise CheckBlocked("no reference recording (give --reference for a device)")
        self.say(f"replaying {len(rec.sensors)} frames of {self.reference_file} through "
                 f"{self.model_path.name} ...")
        replay = self._replay(self.model, rec)
        self.say(f"replayed in {replay.seconds:.1f} s")
        return replay

    @staticmethod
    def _replay(model: LoadedModel, rec: Recording) -> Replay:
        est = model.estimator
        engine = model.engine()
        start = time.perf_counter()
        values = rec.sensors.values
        out = np.empty((values.shape[0], len(est.target.angles)))
        for i in range(values.shape[0]):
            out[i] = engine.push(values[i])
        seconds = time.perf_counter() - start
        truth = angles_at_sensor_times(rec, est.target.joint, est.target.angles)
        return Replay(out, truth, seconds)

    @property
    def to_reference(self) -> bool:
        """Whether the real-time segment is a serial device streamed to its reference's end
        (one segment: the device's replay of the reference cannot be repeated)."""
        return isinstance(self.device, SerialDevice) and self.reference_file is not None

    @cached_property
    def _session_outcome(self) -> SessionResult | CheckBlocked:
        try:
            return self._segment()
        except CheckBlocked as err:
            return err

    @property
    def session(self) -> SessionResult:
        """The real-time segment: ``realtime_seconds`` of the emulator, or of a serial device
        without reference; a serial device with a reference streams until its clock passes the
        reference's end (:attr:`to_reference`). Run once: a segment that could not run is
        reported by every check that asks for it, not run again for each."""
        outcome = self._session_outcome
        if isinstance(outcome, CheckBlocked):
            raise CheckBlocked(str(outcome))
        return outcome

    def segment_result(self) -> SessionResult | None:
        """The real-time segment if a check ran it (None if none did, or it could not run)."""
        outcome = vars(self).get("_session_outcome")
        return outcome if isinstance(outcome, SessionResult) else None

    def _segment(self, attempt: str = "") -> SessionResult:
        """Run one real-time segment (see :attr:`session`); ``attempt`` labels a repeat."""
        self._require_compatible()
        seconds = None if self.to_reference else self.profile.setting("realtime_seconds")
        span = "to the end of the reference" if seconds is None else f"{seconds:g} s"
        self.say(f"real-time segment{attempt}: {self.device.describe()}, {span} ...")

        def progress(status: Status) -> None:
            link = status.link
            self.say(f"  {status.frames} frames, dropped {link.dropped}, crc errors "
                     f"{link.crc_errors}")

        try:
            result = run_session(self.config, seconds, progress=progress,
                                 reference=self.reference)
        except SessionError as err:
            raise CheckBlocked(f"the real-time segment could not run: {err}") from None
        self.say(f"segment done; the host meanwhile: {result.host_load.describe()}")
        return result

    def _kept_segment(self, result: SessionResult | None = None) -> SessionResult:
        """The real-time segment (``result``, default :attr:`session`); SessionError (the
        checks fail) where the device was lost during it: its figures would pass for a
        whole run's."""
        result = self.session if result is None else result
        if result.device_lost:
            run = result.run
            raise SessionError(f"the device was lost during the real-time segment, after "
                               f"{_span_s(result):.3g} s of device time ({run.frames} frames):"
                               f" {result.device_lost}")
        return result

    def _whole_segment(self, result: SessionResult | None = None) -> SessionResult:
        """The real-time segment (``result``, default :attr:`session`), failed where the
        device was lost (:meth:`_kept_segment`) and refused where it covered under
        :data:`SEGMENT_SHARE` of the profile's ``realtime_seconds`` of device time, for a
        device streamed to its reference's end too (its segment is the reference's span):
        latency, link and teleop figures of a few frames measure nothing."""
        result = self._kept_segment(result)
        span = _span_s(result)
        wanted = self.profile.setting("realtime_seconds")
        if span >= SEGMENT_SHARE * wanted:
            return result
        if self.to_reference:
            ref = self.reference
            held = (float(ref.sensors.t[-1] - ref.sensors.t[0])
                    if ref is not None and len(ref.sensors) else 0.0)
            why = (f"the segment of a device with a reference is the reference's span "
                   f"({held:.3g} s)")
            why += (": give a reference of at least "
                    f"{SEGMENT_SHARE * wanted:.3g} s, or a profile with a shorter "
                    "realtime_seconds" if held < SEGMENT_SHARE * wanted else
                    ", and the device streamed only part of it (already streaming when the "
                    "run opened it, or its clock not on the reference's): see "
                    "accuracy.reference_coverage")
        else:
            why = ("the recording ends before that (it is also the reference, so it is not "
                   "looped), or the device stopped")
        raise CheckBlocked(f"the real-time segment covered {span:.3g} s of device time "
                           f"({result.run.frames} frames) where {wanted:g} s are asked for: "
                           f"{why}")

    def _reference_coverage(self, result: SessionResult,
                            limits: dict[str, Limit]) -> Measurement:
        """``accuracy.reference_coverage``: the share of the reference's sensor frames whose
        times lie within the segment's device time, %; at least :data:`REFERENCE_SHARE`
        unless the profile states its own limit. A device already streaming when the run
        began, or one whose clock does not start where the reference does, scores only part
        of the reference, and its figures would pass for the whole's."""
        name = "accuracy.reference_coverage"
        limit = limits.get(name, Limit(low=100 * REFERENCE_SHARE, unit="%", inclusive=True))
        ref, run = self.reference, result.run
        t = np.empty(0) if ref is None else ref.sensors.t
        if not t.size:
            return Measurement.skipped(name, "%", "the reference holds no sensor frame", limit)
        half = 0.5 / (ref.sensor_rate_hz if ref is not None else 1.0)
        lo, hi = run.first_device_time_s - half, run.last_device_time_s + half
        covered = int(np.count_nonzero((t >= lo) & (t <= hi)))
        scored = result.scoring.accuracy.scored if result.scoring is not None else 0
        note = (f"the segment spans device time {run.first_device_time_s:.3f}..."
                f"{run.last_device_time_s:.3f} s: {covered} of the reference's {t.size} frames "
                f"({float(t[0]):.3f}...{float(t[-1]):.3f} s); {run.frames} frames received, "
                f"{scored} scored")
        return Measurement.judge(name, 100.0 * covered / t.size, "%", limit, note)

    # ---- checks ----------------------------------------------------------------------
    def _bench_mismatch(self) -> list[Measurement]:
        """``compatibility.sensor_mismatch`` and ``rate_mismatch`` of what the bench file
        states of its device against the model (none where it states nothing): a bench that
        names other sensors or another rate is not the model's, whatever the stream shows."""
        limits = self.profile.limits("compatibility")
        est, out = self.model.estimator, []
        names = self.bench_sensor_names
        if names is not None and tuple(names) != est.sensor_names:
            out.append(Measurement.judge("compatibility.sensor_mismatch", 1, "count",
                                         limits.get("compatibility.sensor_mismatch"),
                                         f"model {list(est.sensor_names)} vs the bench's "
                                         f"[sensors] names {list(names)}"))
        rate = self.bench_rate_hz
        if rate is not None and not same_rate(rate, est.sensor_rate_hz):
            out.append(Measurement.judge("compatibility.rate_mismatch", 1, "count",
                                         limits.get("compatibility.rate_mismatch"),
                                         f"the bench's [sensors] rate_hz {rate:g} Hz, the "
                                         f"model's {est.sensor_rate_hz:g} Hz"))
        return out

    def compatibility_measurements(self) -> list[Measurement]:
        bench = self._bench_mismatch()
        if bench:  # the device is not the model's: the session would refuse to run it
            return bench
        limits = self.profile.limits("compatibility")
        rec, est = self.reference, self.model.estimator
        if rec is None:
            session = self.session
            bad = int(session.run.frames == 0 and session.run.link.decode_errors > 0)
            return [Measurement.judge("compatibility.sensor_mismatch", bad, "count",
                                      limits.get("compatibility.sensor_mismatch"),
                                      "frames of the model's sensor count arrive"),
                    self._rate(self._device_rate_hz(session), "the device streams", limits),
                    self._coverage(session.coverage, limits)]
        stream = rec.mocap.get(est.target.joint)
        missing = [a for a in est.target.angles if stream is None or a not in stream.names]
        sensors_ok = tuple(rec.sensor_names) == est.sensor_names
        out = [
            Measurement.judge("compatibility.sensor_mismatch", 0 if sensors_ok else 1, "count",
                              limits.get("compatibility.sensor_mismatch"),
                              f"model {list(est.sensor_names)} vs device "
                              f"{list(rec.sensor_names)}"),
            Measurement.judge("compatibility.angle_mismatch", len(missing), "count",
                              limits.get("compatibility.angle_mismatch"),
                              f"estimated angles missing from the reference: {missing}"
                              if missing else "every estimated angle has ground truth"),
        ]
        if isinstance(self.device, EmulatorDevice) or not sensors_ok or missing:
            # the emulator streams the reference itself, at its rate
            return out + [
                self._rate(rec.sensor_rate_hz, "the reference's sensors run", limits),
                self._coverage(stream_coverage(est, rec.sensors.values) if sensors_ok
                               else None, limits)]
        # a device: what it streams, not what the reference holds, is what the model gets
        session = self.session
        rate = self._rate(self._device_rate_hz(session), "the device streams", limits)
        reference = f"the reference's sensors at {rec.sensor_rate_hz:.5g} Hz"
        if not same_rate(rec.sensor_rate_hz, est.sensor_rate_hz):
            rate = Measurement.judge(rate.name, 1, "count", rate.limit,
                                     f"{rate.note}; {reference}, not the model's")
        else:
            rate = replace(rate, note=f"{rate.note}; {reference}")
        return out + [rate, self._coverage(session.coverage, limits)]

    @staticmethod
    def _device_rate_hz(session: SessionResult) -> float:
        """The device's own frame rate over the session (``PipelineRun.device_rate_hz``);
        NaN under a second of it."""
        rate = session.run.device_rate_hz
        return math.nan if rate is None else rate

    def _rate(self, rate_hz: float, what: str, limits: dict[str, Limit]) -> Measurement:
        """``compatibility.rate_mismatch``: 1 when the device's frame rate is not the
        model's (its window would span another time); skipped where it is not known."""
        name, model_hz = "compatibility.rate_mismatch", self.model.estimator.sensor_rate_hz
        if not math.isfinite(rate_hz):
            return Measurement.skipped(name, "count", "no frame rate measured", limits.get(name))
        return Measurement.judge(name, 0 if same_rate(rate_hz, model_hz) else 1, "count",
                                 limits.get(name), f"{what} at {rate_hz:.5g} Hz, the model's "
                                 f"at {model_hz:g} Hz")

    @staticmethod
    def _coverage(tally: CoverageTally | None, limits: dict[str, Limit]) -> Measurement:
        """``compatibility.outside_training`` of ``tally`` (skipped without one: sensors
        that do not match)."""
        name = "compatibility.outside_training"
        if tally is None:
            return Measurement.skipped(name, "%", "the sensors do not match", limits.get(name))
        return coverage_measurement(tally, limits)

    def heldout_measurements(self) -> list[Measurement]:
        limits = self.profile.limits("heldout")
        path = self.reference_file
        if path is None:
            raise CheckBlocked("no reference recording to compare with the training data")
        # a part cut from a training recording (exohil record cut) is training data too, and
        # so is a recording a training recording was cut from, unless their times never meet
        reference = self.reference  # a file that is no recording fails here, not passes
        scored = ({"file": path.name, "sha256": self.reference_sha256} if reference is None
                  else source_entry(path, reference, self.reference_sha256))
        sources = self.model.estimator.info.get("sources", [])
        judged = [shared_frames(scored, s) for s in sources]
        trained = [why for overlap, why in judged if overlap]
        apart = [why for overlap, why in judged if not overlap and why]
        note = (f"{'; '.join(trained)}: score it on a recording the model never saw"
                if trained else
                f"{path.name} is not among the model's {len(sources)} training recording(s)"
                + "".join(f"; {why}" for why in apart))
        unknown = [s.get("file", "?") for s in sources if "cut_from" not in s]
        if unknown and not trained:  # a checkpoint written before exohil recorded lineage
            note += (f"; the checkpoint does not record what {', '.join(unknown)} was cut "
                     "from (written before exohil did), so a part of this one would go unseen")
        if not sources:
            note = "the checkpoint records no training recordings; cannot prove held-out"
        return [Measurement.judge("heldout.overlap", len(trained) if sources else 1, "count",
                                  limits.get("heldout.overlap"), note)]

    def accuracy_measurements(self) -> list[Measurement]:
        limits = self.profile.limits("accuracy")
        est = self.model.estimator
        if self.profile.setting("replay") == "full" and isinstance(self.device, EmulatorDevice):
            replay = self.replay
            return accuracy_measurements(replay.estimates, replay.truth, est.target.angles,
                                         limits)
        if self.reference is None:
            raise CheckBlocked("no reference recording (give --reference for a device)")
        if not self.to_reference:
            return session_accuracy(self.session, limits)
        result = self._kept_segment()
        return [*session_accuracy(result, limits), self._reference_coverage(result, limits)]

    def latency_measurements(self) -> list[Measurement]:
        """Latency of the real-time segment, and how busy the host was during it.

        A busy host only adds time. With ``latency_attempts`` > 1, a segment whose latency
        fails a limit is followed by a fresh one, up to that many in all, and the check is
        judged on the last: it passes only if one whole segment met every limit.
        ``latency.attempts`` counts the segments; its note gives each one's figures. A
        device streamed to its reference's end is judged on its one segment: it cannot
        replay the reference again."""
        limits = self.profile.limits("latency")
        attempts = self.profile.setting("latency_attempts")
        once = ""
        if self.to_reference and attempts > 1:
            attempts = 1
            once = ("; judged on the one segment: a device streamed to its reference's end "
                    "cannot replay it again (latency_attempts applies to the emulator and to "
                    "a device without a reference)")
        result = self._whole_segment()
        tried: list[str] = []
        while True:
            measured = latency_measurements(result.run, limits)
            measured += _host_measurements(result.host_load, limits)
            failed = next((m for m in measured if m.failed), None)
            tried.append(_attempt_summary(measured, failed is not None, result.host_load))
            if failed is None or len(tried) >= attempts:
                break
            self.say(f"latency: {failed.describe()}; {result.host_load.describe()} during the "
                     "segment, and a busy host only adds time: measuring a fresh segment")
            result = self._whole_segment(
                self._segment(f" (latency attempt {len(tried) + 1} of {attempts})"))
        note = "; ".join(f"{i}: {line}" for i, line in enumerate(tried, 1)) + once
        return measured + [Measurement.judge("latency.attempts", len(tried), "count",
                                             limits.get("latency.attempts"), note)]

    def link_measurements(self) -> list[Measurement]:
        return link_measurements(self._whole_segment(), self.profile.limits("link"))

    def teleop_measurements(self) -> list[Measurement]:
        return teleop_measurements(self._whole_segment(), self.profile.limits("teleop"))

    def conversions_measurements(self) -> list[Measurement]:
        """How many conversion properties failed, how many examples ran, the largest error."""
        limits = self.profile.limits("conversions")
        results = run_properties(self.profile.setting("conversion_examples"),
                                 self.profile.setting("seed"))
        failures = [r for r in results if r.failure]
        out = [
            Measurement.judge("conversions.failures", len(failures), "count",
                              limits.get("conversions.failures"),
                              "; ".join(f"{r.name}: {r.failure}" for r in failures)
                              or f"{len(results)} properties held"),
            Measurement.judge("conversions.examples", sum(r.examples for r in results), "count",
                              limits.get("conversions.examples"),
                              f"seed {self.profile.setting('seed')}"),
            Measurement.judge("conversions.max_error", max(r.max_error_deg for r in results),
                              "deg", limits.get("conversions.max_error"),
                              "largest round-trip or oracle error"),
        ]
        return out

    def regression_measurements(self) -> list[Measurement]:
        """Accuracy against the baseline's, and the estimator's p99 against the baseline
        model's. The baseline is a checkpoint (both models replayed and timed here) or the
        ``conformance.json`` of an earlier run (its accuracy figures, measured on the same
        reference recording: :func:`figures_baseline`; a run elsewhere has no model to
        time beside this one, so latency is then not compared)."""
        if self.baseline_path is None:
            raise CheckBlocked("no --baseline given")
        limits = dict(self.profile.limits("regression"))
        margin = self.profile.setting("regression_accuracy_margin_deg")
        factor = self.profile.setting("regression_latency_factor")
        rec = self.reference
        if rec is None:
            raise CheckBlocked("no reference recording to compare accuracy on")
        mine = accuracy_measurements(self.replay.estimates, self.replay.truth,
                                     self.model.estimator.target.angles)
        if self.baseline_path.suffix.lower() == ".json":  # an earlier run's figures
            scored = next((m.value for m in mine if m.name == "accuracy.frames_scored"), None)
            base_values, whose = figures_baseline(self.baseline_path, self.reference_sha256,
                                                  scored)
            baseline = None
        else:
            baseline = load_model(self.baseline_path, self.backend)
            base_replay = self._replay(baseline, rec)
            base_values = {m.name: m.value for m in accuracy_measurements(
                base_replay.estimates, base_replay.truth, baseline.estimator.target.angles)}
            whose = "baseline"
        out = []
        for m in mine:
            if m.unit != "deg" or m.name not in base_values:
                continue
            name = "regression." + m.name
            limit = limits.get(name, Limit(high=margin, unit="deg", inclusive=True))
            out.append(Measurement.judge(name, m.value - base_values[m.name], "deg", limit,
                                         f"{m.value:.3f} vs {whose} {base_values[m.name]:.3f}"))
        if not out:
            raise SessionError(f"{self.baseline_path}: no accuracy figure to compare with "
                               f"this model's ({', '.join(m.name for m in mine)})")
        limit = limits.get("regression.latency_p99_ratio", Limit(high=factor, unit="x",
                                                                 inclusive=True))
        if baseline is None:
            out.append(Measurement.skipped(
                "regression.latency_p99_ratio", "x", "the baseline is figures of an earlier "
                "run, with no model to time beside this one (give a checkpoint to compare "
                "latency)", limit))
            return out
        mine_p99, base_p99 = _paced_p99_ms(self.model, baseline, rec.sensors.values)
        out.append(Measurement.judge("regression.latency_p99_ratio", mine_p99 / base_p99, "x",
                                     limit, f"estimator p99 {mine_p99:.3f} ms vs baseline "
                                            f"{base_p99:.3f} ms, interleaved on one machine, each "
                                            "frame the least of its passes"))
        return out

    @cached_property
    def reference_sha256(self) -> str | None:
        """The reference recording's sha256 (None without one)."""
        path = self.reference_file
        return None if path is None else sha256_file(path)

    @cached_property
    def profile_sha256(self) -> str | None:
        """The profile file's sha256, for the reports (None for a profile made in code)."""
        return None if self.profile.path is None else sha256_file(self.profile.path)


#: how far (a share) an earlier run's count of scored frames may be from this run's: models
#: with other windows score a few frames fewer of a reference's tens of thousands; a real-time
#: segment instead of the whole replay scores a fraction of them.
FRAMES_SCORED_TOLERANCE = 0.01


def figures_baseline(path: Path, reference_sha256: str | None,
                     frames_scored: float | None = None) -> tuple[dict[str, float], str]:
    """The accuracy figures (measurement name → degrees) of an earlier run's
    ``conformance.json`` at ``path``, and how the notes name them ("baseline <model
    sha256[:12]>"). SessionError where the file is no such report, is that of a run in
    which a check failed (a run that only left checks out, ``-k``, is taken: its checks
    that ran passed), holds no accuracy figure, was measured on another reference
    recording than ``reference_sha256``, or
    scored other frames of it than ``frames_scored`` (this run's count; within
    :data:`FRAMES_SCORED_TOLERANCE`): its profile scored a real-time segment
    (``replay`` not "full"), where the regression check scores the whole replay."""
    from exohil.conformance.report import SCHEMA

    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise SessionError(f"{path}: not a conformance report to compare with ({exc})") from None
    if not isinstance(data, dict) or data.get("schema") != SCHEMA:
        raise SessionError(f"{path}: not a conformance report (schema {SCHEMA}) to compare with")
    failed = [str(check.get("name")) for check in data.get("checks", [])
              if isinstance(check, dict) and check.get("verdict") == "fail"]
    if failed:  # its figures would lower the bar to a run that did not meet it
        raise SessionError(
            f"{path}: that run failed ({', '.join(failed)}), so its figures are no baseline; "
            "compare with a run whose checks passed (`make conform-baseline` stores one)")
    theirs = data.get("reference_sha256")
    if theirs is None or theirs != reference_sha256:
        raise SessionError(
            f"{path}: its figures were measured on another reference recording "
            f"({data.get('reference')}, sha256 {str(theirs)[:12]}) than this run's; "
            "measure the baseline on the same recording")
    accuracy = [m for check in data.get("checks", []) if check.get("name") == "accuracy"
                for m in check.get("measurements", [])]
    values = {m["name"]: float(m["value"]) for m in accuracy
              if m.get("unit") == "deg" and isinstance(m.get("value"), (int, float))}
    theirs_scored = next((m.get("value") for m in accuracy
                          if m.get("name") == "accuracy.frames_scored"), None)
    if (frames_scored is not None and isinstance(theirs_scored, (int, float))
            and abs(theirs_scored - frames_scored)
            > FRAMES_SCORED_TOLERANCE * max(frames_scored, 1.0)):
        raise SessionError(
            f"{path}: its accuracy scored {theirs_scored:.0f} frames of the reference, this "
            f"run's whole replay {frames_scored:.0f}: its profile scored another part of it "
            "(a real-time segment: replay is not \"full\"), so its figures are not comparable; "
            "measure the baseline with a profile whose replay is \"full\"")
    model = (data.get("model") or {}).get("sha256") or "?"
    return values, f"baseline figures (model {model[:12]})"


def _paced_p99_ms(a: LoadedModel, b: LoadedModel, values: np.ndarray, frames: int = 2000,
                  passes: int = 5, warm_up: int = 100) -> tuple[float, float]:
    """Estimator p99 (ms) of two models over the same frames, each frame's time the least of
    ``passes`` passes from fresh engines.

    A push takes some 0.03 ms, so about 1 % of pushes meet a kernel timer tick (every 4 ms at
    250 Hz) and take three times as long: a p99 of single passes sits on that cliff, and a
    model compared with itself scattered from 0.53× to 1.65× (docs/conformance.md).
    Interrupts and other processes only ever add time, and a fresh engine fed the same
    frames does the same work, so the least over passes is the model's own cost of each
    frame, whatever it depends on.
    The models are interleaved frame by frame, in alternating order, so a slow moment of the
    machine meets both and neither is always second.
    """
    ta, tb = np.full(frames, np.inf), np.full(frames, np.inf)
    clock = time.perf_counter_ns
    for k in range(passes):
        ea, eb = a.engine(), b.engine()
        for i in range(frames):
            row = values[i % values.shape[0]]
            a_first = (i + k) % 2 == 1
            first, second = (ea, eb) if a_first else (eb, ea)
            t0 = clock()
            first.push(row)
            t1 = clock()
            second.push(row)
            t2 = clock()
            da, db = (t1 - t0, t2 - t1) if a_first else (t2 - t1, t1 - t0)
            ta[i], tb[i] = min(ta[i], da / 1e6), min(tb[i], db / 1e6)
    pa = distribution("a", ta[warm_up:], "ms")[1].value
    pb = distribution("b", tb[warm_up:], "ms")[1].value
    return pa, pb


def _span_s(result: SessionResult) -> float:
    """The device time a segment's frames span, s (0 with under two frames)."""
    run = result.run
    return run.last_device_time_s - run.first_device_time_s if run.frames > 1 else 0.0


def _host_measurements(load: HostLoad, limits: dict[str, Limit]) -> list[Measurement]:
    """``latency.host.cpu_pressure`` and ``latency.host.cpu_steal`` (ratios) of ``load``."""
    out = []
    for name in ("cpu_pressure", "cpu_steal"):
        key = f"latency.host.{name}"
        value = getattr(load, name)
        if value is None:
            out.append(Measurement.skipped(key, "ratio", "the kernel does not report it",
                                           limits.get(key)))
        else:
            out.append(Measurement.judge(key, value, "ratio", limits.get(key),
                                         "while the real-time segment ran"))
    return out


def _attempt_summary(measured: list[Measurement], failed: bool, load: HostLoad) -> str:
    """One segment's end-to-end figures, its verdict and the host's load, on one line."""
    figures = ", ".join(f"{m.name.rsplit('.', 1)[1]} {m.value:.4g} {m.unit}" for m in measured
                        if m.name.startswith("latency.end_to_end."))
    verdict = "failed" if failed else "met every limit"
    return f"end to end {figures} ({verdict}); {load.describe()}"
