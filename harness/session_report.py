"""The report of a bench session (``exohil demo`` and ``exohil run``): every figure is a
:class:`~exohil.formats.measurement.Measurement` from :mod:`exohil.harness.session`; this
module lays them out as the summary JSON and the lines a person reads.

``summary.json``::

    {"rmse": {angle: deg}, "direction_rmse_deg": deg,
     "latency_ms": {stage: {"p50", "p99", "max"}},
     "frames": {"sent", "received", "dropped", "crc_errors"},
     "teleop": {"rmse_deg": {joint: deg}, "clamped_share",
                "robot_tracking_deg": {"p50", "p99", "max"}, "robot_axis_error_deg": {...},
                "robots": {name: summary}},
     "device_lost": text or null, "ended_early": text or null (a run stopped on request,
     e.g. Ctrl-C, before the end it was given: its seconds, its reference's end or its
     emulator's recording; or an emulator's recording shorter than the seconds asked for),
     "device_log": {kind: count}, "values_clipped_to_wire_range": count,
     "training_coverage": {"frames", "outside_percent", "outside_bound_sigmas",
                           "extremes_sigmas": {sensor: [low, high]}},
     "training_coverage_warning": text or null,
     "sensor_rate_warning": text or null (a device at another frame rate than the model's),
     "sensor_rate_hz": the configured frame rate, "device_rate_hz": the device's measured
     one (seq span / device-time span, harness/device_rate.py; null under 1 s of frames),
     "device_rate_warning": text or null (they differ by more than 1 %),
     "measurements": [Measurement.to_dict(), ...],
     "host_load": {"cpu_pressure", "cpu_steal"} (shares 0..1, null where the kernel does not
     say, while the session streamed: harness/machine.py ``HostLoad``),
     "model", "model_sha256", "backend", "target", "machine",
     "finished_at": local time with its UTC offset (ISO 8601)}

``teleop.robots`` holds every robot target's ``summary()`` (:func:`robot_summaries`), named by
its class (``MujocoNao``, ``UdpJointTarget``, ...); when several targets share a class (``--sink
udp:A --sink udp:B``) each is named ``Class[k]``, k from 0 in the order the sinks were given.
"""

from __future__ import annotations

import math
from datetime import datetime
from typing import Any

from exohil.estimator.rates import RATE_REMEDY, rate_mismatch
from exohil.formats.measurement import Measurement
from exohil.harness.device_rate import device_rate_warning
from exohil.harness.machine import HostLoad, machine
from exohil.harness.session import (
    SessionResult,
    latency_measurements,
    link_measurements,
    robot_measurements,
    session_accuracy,
    session_coverage,
    teleop_measurements,
)

#: The link measurements that reconcile the host's frames with an emulator's fault log.
RECONCILED = ("link.lost_on_host", "link.bad_frames_delivered", "link.dropped_unexplained")


def session_measurements(result: SessionResult) -> list[Measurement]:
    """Every measurement of a session, without limits (the demo and ``run`` report them)."""
    return (link_measurements(result) + session_coverage(result)
            + latency_measurements(result.run) + session_accuracy(result)
            + teleop_measurements(result) + robot_measurements(result))


def _value(measurements: list[Measurement], name: str) -> float | None:
    for m in measurements:
        if m.name == name:
            return None if math.isnan(m.value) else round(m.value, 4)
    return None


def robot_summaries(robots: list[Any]) -> dict[str, Any]:
    """Each robot's ``summary()`` (those that have one) by name: its class name, or
    ``Class[k]`` (k from 0, in order) when several robots share a class (module doc)."""
    reporting = [r for r in robots if hasattr(r, "summary")]
    classes = [type(r).__name__ for r in reporting]
    out: dict[str, Any] = {}
    seen: dict[str, int] = {}
    for robot, name in zip(reporting, classes, strict=True):
        if classes.count(name) > 1:
            k = seen[name] = seen.get(name, -1) + 1
            name = f"{name}[{k}]"
        out[name] = robot.summary()
    return out


def summary(result: SessionResult, measurements: list[Measurement]) -> dict[str, Any]:
    """The summary JSON (module doc)."""
    est = result.model.estimator
    stages = list(dict.fromkeys(m.name.rsplit(".", 1)[0] for m in measurements
                                if m.name.startswith("latency.")))
    counts = result.fault_counts
    run = result.run
    device_hz = run.device_rate_hz
    sent = None
    if counts is not None:
        sent = run.frames + sum(counts.get(k, 0) for k in ("drop", "corrupt", "truncate",
                                                            "disconnect"))
    return {
        "target": result.config.device.describe() if result.config.device else None,
        "model": str(result.model.path),
        "model_sha256": result.model.sha256,
        "model_kind": est.kind,
        "backend": result.model.backend,
        "rmse": {a: _value(measurements, f"accuracy.rmse.{a}") for a in est.target.angles},
        "direction_rmse_deg": _value(measurements, "accuracy.direction_rmse"),
        "latency_ms": {s.removeprefix("latency."): {stat: _value(measurements, f"{s}.{stat}")
                                                     for stat in ("p50", "p99", "max")}
                       for s in stages},
        "frames": {"sent": sent, "received": run.frames, "dropped": run.link.dropped,
                   "crc_errors": run.link.crc_errors},
        "link": vars(run.link),
        "device_lost": result.device_lost,
        "ended_early": result.ended_early,
        "device_log": counts,
        "values_clipped_to_wire_range": result.clipped_values,
        "training_coverage": None if result.coverage is None else result.coverage.to_dict(),
        "training_coverage_warning": (None if result.coverage is None
                                      else result.coverage.warning()),
        "sensor_rate_warning": rate_mismatch(result.sensor_rate_hz, est.sensor_rate_hz,
                                             "the device's frame rate"),
        "sensor_rate_hz": result.sensor_rate_hz,
        "device_rate_hz": None if device_hz is None else round(device_hz, 3),
        "device_rate_warning": device_rate_warning(device_hz, result.sensor_rate_hz),
        "teleop": {
            "rmse_deg": {m.name.removeprefix("teleop.rmse."): _value(measurements, m.name)
                         for m in measurements if m.name.startswith("teleop.rmse.")},
            "clamped_share": _value(measurements, "teleop.clamped_share"),
            **{f"{name}_deg": {stat: _value(measurements, f"teleop.{name}.{stat}")
                               for stat in ("p50", "p99", "max")}
               for name in ("robot_tracking", "robot_axis_error")},
            "robots": robot_summaries(result.robots),
        },
        "wall_s": round(run.wall_s, 3),
        "host_load": vars(result.host_load),
        "measurements": [m.to_dict() for m in measurements],
        "machine": machine(),
        "finished_at": datetime.now().astimezone().isoformat(timespec="seconds"),
    }


def host_load_text(s: dict[str, Any]) -> str:
    """The machine's load while the session streamed, which its latencies depend on."""
    return f"{HostLoad(**s['host_load']).describe()} while streaming, on {s['machine']}"


def summary_lines(s: dict[str, Any]) -> list[str]:
    """What a person reads at the end of a run."""
    link = s["link"]
    lines = [
        "",
        f"frames      {s['frames']['received']} received in {s['wall_s']} s  "
        f"dropped {link['dropped']} (in disconnects {link['dropped_in_disconnects']})  "
        f"crc errors {link['crc_errors']}  decode errors {link['decode_errors']}",
        f"link        disconnects {link['disconnects']}  reconnects {link['reconnects']}  "
        f"wrong device {link['wrong_device']}  implausible headers {link['implausible']}  "
        f"sequence resets {link['sequence_resets']}  host overflow {link['overflow']}",
    ]
    if s.get("device_lost"):
        lines.append(f"device lost {s['device_lost']}: the run ended before its time")
    if s.get("ended_early"):
        lines.append(f"note        {s['ended_early']}")
    if s["device_log"] is not None:
        log = ", ".join(f"{k} {v}" for k, v in sorted(s["device_log"].items()))
        lines.append(f"device log  {log or 'nothing injected or lost'}")
    reconciled = {m["name"].removeprefix("link."): m["value"] for m in s["measurements"]
                  if m["name"] in RECONCILED and m["value"] is not None}
    if reconciled:
        lines.append("reconciled  with the device log: " + ", ".join(
            f"{name.replace('_', ' ')} {value:g}" for name, value in reconciled.items())
            + " (each 0 when every frame is accounted for)")
    lines.append(f"host        {host_load_text(s)}")
    for stage, stats in s["latency_ms"].items():
        if stats["p50"] is None:
            continue
        lines.append(f"{'latency':11s} {stage:22s} p50 {stats['p50']:.3f}  p99 {stats['p99']:.3f}"
                     f"  max {stats['max']:.3f} ms")
    rmse = ", ".join(f"{k} {v:.2f}°" for k, v in s["rmse"].items() if v is not None)
    direction = s["direction_rmse_deg"]
    if rmse:
        lines.append(f"accuracy    RMSE {rmse} where elevation ≥ 20° (θ is undefined with the "
                     "arm hanging)")
    elif direction is not None:
        lines.append("accuracy    RMSE per angle not measured: no frame reached 20° of elevation "
                     "(θ is undefined with the arm hanging)")
    else:
        lines.append("accuracy    not measured: no reference recording")
    if direction is not None:
        lines.append(f"            arm-direction RMSE {direction:.2f}° over all frames")
    teleop = s["teleop"]
    if teleop["rmse_deg"] and any(v is not None for v in teleop["rmse_deg"].values()):
        joints = ", ".join(f"{k} {v:.2f}°" for k, v in teleop["rmse_deg"].items())
        lines.append(f"teleop      command RMSE vs true pose: {joints}; clamped "
                     f"{100 * (teleop['clamped_share'] or 0):.1f}% of commands")
    axis = teleop["robot_axis_error_deg"]
    if axis["p50"] is not None:
        lines.append(f"robot       upper-arm axis vs true humerus p50 {axis['p50']:.1f}°  "
                     f"p99 {axis['p99']:.1f}°  max {axis['max']:.1f}°")
    if s.get("training_coverage_warning"):
        lines.append(f"warning     {s['training_coverage_warning']}")
    if s.get("device_rate_warning"):
        lines.append(f"warning     {s['device_rate_warning']}")
    if s.get("sensor_rate_warning"):
        lines.append(f"warning     {s['sensor_rate_warning']}; {RATE_REMEDY}")
    if s["values_clipped_to_wire_range"]:
        lines.append(f"warning     {s['values_clipped_to_wire_range']} sensor values were outside "
                     "the wire's 0..655.35 mm and were clipped")
    return lines
