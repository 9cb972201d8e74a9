"""The recording of a pipeline run (``run.mcap``): what the host received and what it did.

Recording format v1 (docs/recording-format.md) for the sensor frames the host received, plus
three JSON channels that format v1 readers skip (as notes) and MCAP tools such as Foxglove
show:

| topic | message |
|---|---|
| ``/estimate/<joint>`` | ``{"t": s, "<angle>": deg, ...}``, the estimator's output per frame |
| ``/robot/nao`` | ``{"t": s, "<Joint>": deg, ..., "clamped": bool}`` (any joint at a limit) |
| ``/timing/stages`` | ``{"t": s, "seq": n, "<stage>_us": µs after host receive, ...}`` |

Times are device times (s). The file is written to a temporary name and renamed when complete.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from exohil.formats.atomic import replacing
from exohil.formats.recording_writer import RecordingWriter
from exohil.harness.pipeline import NOT_STAMPED, STAGES, PipelineRun
from exohil.kinematics import NAO_JOINTS


def _object_schema(title: str, numbers: Sequence[str],
                   extra: Mapping[str, object] | None = None) -> dict:
    props: dict[str, object] = {name: {"type": "number"} for name in ("t", *numbers)}
    props.update(extra or {})
    return {"title": title, "type": "object", "properties": props, "required": ["t"]}


def write_run_recording(path: Path, run: PipelineRun, sensor_names: Sequence[str],
                        joint: str, angle_names: Sequence[str],
                        metadata: Mapping[str, str], sensor_rate_hz: float) -> None:
    """Write ``run``'s kept rows to ``path`` (see module doc): every frame of a run that fits
    the pipeline's window, else its first and last frames; ``sensor_rate_hz``: the device's
    nominal frame rate."""
    with replacing(path) as tmp:
        t = np.maximum(run.device_time_s, 0.0)
        with RecordingWriter(tmp, sensor_names, metadata=dict(metadata), name=path,
                             sensor_rate_hz=sensor_rate_hz) as writer:
            if run.retained:
                writer.add_sensor_frames(run.seq, t, run.values)
            estimates = writer.add_channel(f"/estimate/{joint}", f"exohil.Estimate.{joint}",
                                           _object_schema(f"{joint} estimate", angle_names))
            robot = writer.add_channel("/robot/nao", "exohil.NaoCommand", _object_schema(
                "NAO arm command, degrees", NAO_JOINTS,
                {"clamped": {"type": "boolean"}}))
            stage_names = [f"{s}_us" for s in STAGES if s != "host_receive"]
            timing = writer.add_channel("/timing/stages", "exohil.StageTimes", _object_schema(
                "per-frame stage times, µs after host receive", ["seq", *stage_names]))
            receive = run.stamps[:, STAGES.index("host_receive")]
            for i in range(run.retained):
                ti = float(t[i])
                writer.add_message(estimates, ti, {"t": ti, **{
                    a: float(v) for a, v in zip(angle_names, run.estimates[i], strict=True)
                    if np.isfinite(v)}})
                if np.all(np.isfinite(run.commands[i])):
                    writer.add_message(robot, ti, {"t": ti, **{
                        j: float(np.rad2deg(v)) for j, v in zip(NAO_JOINTS, run.commands[i],
                                                                strict=True)},
                        "clamped": bool(run.clamped[i])})
                stamps = {f"{s}_us": round((int(run.stamps[i, k]) - int(receive[i])) / 1e3, 3)
                          for k, s in enumerate(STAGES)
                          if s != "host_receive" and run.stamps[i, k] != NOT_STAMPED}
                writer.add_message(timing, ti, {"t": ti, "seq": int(run.seq[i]), **stamps})
