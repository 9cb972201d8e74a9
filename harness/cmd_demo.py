"""``exohil demo``: the whole hardware-in-the-loop chain on the bundled fixture.

Software Arduino on a pty (wire protocol v1, paced at 250 Hz) → acquisition thread (pyserial,
COBS, CRC) → streaming ENNet (reference model) → MoBL-ARMS → ISB → quaternion → NAO joints on a
simulated NAO. It prints progress while it runs and, at the end, the link statistics, the
estimator and end-to-end latency (p50/p99/max) and the accuracy against the fixture's motion
capture over the streamed span.
"""

from __future__ import annotations

import json
import platform
import sys
import time
from collections import Counter
from pathlib import Path

import click
import numpy as np

from exohil.harness.cli_types import OutputFile
from exohil.harness.paths import FIXTURES_DIR, MODELS_DIR

DEFAULT_RECORDING = FIXTURES_DIR / "paper_protocol.mcap"
DEFAULT_MODEL = MODELS_DIR / "ennet.npz"
SHOULDER_ANGLES = ("elv_angle", "shoulder_elv")
#: Elevation (deg) from which the plane of elevation counts as observable (docs/results.md).
OBSERVABLE_ELEVATION_DEG = 20.0


def _progress(frames: int, link, last) -> None:
    angles = "" if last is None else f"  θ={last[0]:6.1f}° φ={last[1]:6.1f}°"
    click.echo(f"  {frames:6d} frames  dropped {link.dropped}  crc errors {link.crc_errors}"
               f"{angles}", err=True)


def _ground_truth(recording, est, seq: np.ndarray) -> np.ndarray:
    """Mocap angles (deg) of the frames the emulator sent as ``seq`` (frame k = sensor row k)."""
    from exohil.formats.alignment import angles_at_sensor_times

    truth = angles_at_sensor_times(recording, est.target.joint, est.target.angles)
    return truth[np.mod(seq, truth.shape[0])]


@click.command("demo")
@click.option("--recording", type=click.Path(path_type=Path), default=DEFAULT_RECORDING,
              show_default=True, help="Recording whose sensor frames the emulator replays.")
@click.option("--model", type=click.Path(path_type=Path), default=DEFAULT_MODEL,
              show_default=True, help="Estimator checkpoint (exohil train --out).")
@click.option("--seconds", type=click.FloatRange(min=1.0), default=15.0, show_default=True,
              help="How long to stream (wall clock; the device runs in real time).")
@click.option("--faults", default=None, help="Fault spec for the emulator, e.g. "
              "'drop:rate=0.01;corrupt:rate=0.001' (docs/emulator.md).")
@click.option("--seed", type=int, default=0, show_default=True, help="Seed for faults.")
@click.option("--backend", type=click.Choice(["auto", "numpy", "torch", "torchscript",
                                              "onnxruntime"]),
              default="auto", show_default=True,
              help="Streaming inference backend; auto = onnxruntime when installed, else numpy "
                   "(torch for a CNN).")
@click.option("--record", "record_path", type=OutputFile(), default=None,
              help="Also write the frames the host received to this recording (MCAP).")
@click.option("--json", "json_out", type=OutputFile(), default=None,
              help="Write the summary as JSON to this file.")
def demo(recording: Path, model: Path, seconds: float, faults: str | None, seed: int,
         backend: str, record_path: Path | None, json_out: Path | None) -> None:
    """Run the full chain (emulated device → acquisition → ENNet → NAO) and report."""
    from exohil.emulators.arduino import ArduinoEmulator
    from exohil.estimator.checkpoint import CheckpointError, ensure_fits, load_checkpoint
    from exohil.estimator.inference import StreamingEstimator, default_backend
    from exohil.formats.errors import RecordingError
    from exohil.formats.mcap_io import read_recording
    from exohil.harness.acquisition import SerialFrameSource
    from exohil.harness.pipeline import Pipeline, percentiles_us
    from exohil.harness.teleop import SimulatedNao, TeleopSink

    try:
        rec = read_recording(recording)
        est = load_checkpoint(model)
        ensure_fits(est, rec, str(recording))
    except (RecordingError, CheckpointError) as err:
        raise click.ClickException(str(err)) from None
    if backend == "auto":
        backend = default_backend(est)
    try:
        engine = StreamingEstimator(est, backend=backend)
    except ValueError as err:
        raise click.ClickException(str(err)) from None
    angle_index = [est.target.angles.index(a) for a in SHOULDER_ANGLES
                   if a in est.target.angles]
    teleop = len(angle_index) == 2 and est.target.joint == "shoulder"
    nao = SimulatedNao()
    sinks = []
    if teleop:
        sink = TeleopSink(nao)
        sinks.append(lambda frame, angles: sink.accept(frame.device_time_s,
                                                       angles[angle_index[0]],
                                                       angles[angle_index[1]]))
    recorder = None
    if record_path is not None:
        from exohil.harness.recorder import RecorderSink

        recorder = RecorderSink(record_path, rec.sensor_names, sensor_units=rec.sensor_units,
                                metadata={"generator": "exohil demo", "source": str(recording)})
        sinks.append(recorder)

    click.echo(f"exohil demo: {recording.name} → pty → acquisition → {est.kind} "
               f"({backend}) → NAO, {seconds:g} s", err=True)
    try:
        with ArduinoEmulator.from_recording(rec, faults=faults, seed=seed) as emu:
            click.echo(f"  emulated device on {emu.port}", err=True)
            with SerialFrameSource(emu.port, expected_sensors=len(rec.sensor_names)) as source:
                run = Pipeline(source, engine, sinks).run(duration_s=seconds, progress=_progress)
            fault_log = list(emu.fault_log)
            clipped = emu.clipped_values
    except ValueError as err:
        raise click.ClickException(str(err)) from None
    finally:
        if recorder is not None:
            recorder.close()
    if run.frames == 0:
        raise click.ClickException("no frame arrived from the emulated device")

    truth = _ground_truth(rec, est, run.seq)
    ok = np.all(np.isfinite(truth), axis=1)
    err = run.estimates[ok] - truth[ok]
    observable = None
    if "shoulder_elv" in est.target.angles:
        elevated = truth[ok][:, est.target.angles.index("shoulder_elv")] >= OBSERVABLE_ELEVATION_DEG
        observable = {"frames": int(elevated.sum()), "rmse_deg": _rmse(err[elevated],
                                                                          est.target.angles)}
    summary = {
        "recording": str(recording),
        "model": str(model),
        "model_kind": est.kind,
        "backend": backend,
        "wall_s": round(run.wall_s, 3),
        "frames": run.frames,
        "rate_hz": round(run.frames / run.wall_s, 2),
        "link": vars(run.link),
        "device_log": dict(Counter(record.kind for record in fault_log)),
        "values_clipped_to_wire_range": clipped,
        "estimator_compute": percentiles_us(run.compute_ns),
        "end_to_end_latency": percentiles_us(run.latency_ns),
        "rmse_deg": _rmse(err, est.target.angles),
        "rmse_where_plane_observable": observable,
        "nao": nao.summary() if teleop else None,
        "machine": f"{platform.machine()} {platform.processor() or ''} "
                   f"{platform.system()} Python {sys.version.split()[0]}".strip(),
        "finished_at": time.strftime("%Y-%m-%dT%H:%M:%S"),
    }
    if json_out is not None:
        json_out.write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    _print_summary(summary, record_path)


def _rmse(err: np.ndarray, names) -> dict[str, float | None]:
    """Per-angle RMSE (deg) of (N, A) errors; None when there is no frame."""
    if err.shape[0] == 0:
        return {name: None for name in names}
    return {name: round(float(np.sqrt(np.mean(err[:, i] ** 2))), 3)
            for i, name in enumerate(names)}


def _print_summary(s: dict, record_path: Path | None) -> None:
    link = s["link"]
    lines = [
        "",
        f"frames      {s['frames']} in {s['wall_s']} s ({s['rate_hz']} Hz)",
        f"link        dropped {link['dropped']}  crc errors {link['crc_errors']}  "
        f"resyncs {link['resyncs']}  reconnects {link['reconnects']}  overflow "
        f"{link['overflow']}",
        "device log  " + (", ".join(f"{k} {v}" for k, v in sorted(s["device_log"].items()))
                          or "nothing injected or lost")
        + "  (not_read: frames sent before the host attached)",
        "estimator   {p50_us} / {p99_us} / {max_us} µs per frame (p50/p99/max)".format(
            **s["estimator_compute"]),
        "end to end  {p50_us} / {p99_us} / {max_us} µs receive → NAO command".format(
            **s["end_to_end_latency"]),
        "accuracy    RMSE " + ", ".join(f"{k} {v}°" for k, v in s["rmse_deg"].items())
        + " over the streamed span",
    ]
    if s["rmse_where_plane_observable"]:
        obs = s["rmse_where_plane_observable"]
        per_angle = ", ".join(f"{k} {v}°" for k, v in obs["rmse_deg"].items())
        lines.append(f"            RMSE {per_angle} where φ ≥ {OBSERVABLE_ELEVATION_DEG:g}° "
                     f"({obs['frames']} frames; θ is undefined with the arm hanging)")
    if s["values_clipped_to_wire_range"]:
        lines.append(f"warning     {s['values_clipped_to_wire_range']} sensor values were outside "
                     "the wire's 0..655.35 mm and were clipped")
    if s["nao"]:
        nao = s["nao"]
        lines.append(f"NAO         {nao['commands']} commands, {nao['clamped_commands']} "
                     f"clamped; last {nao['last_joints_deg']}")
    if record_path is not None:
        lines.append(f"recorded    {record_path}")
    click.echo("\n".join(lines))


COMMANDS = [demo]
