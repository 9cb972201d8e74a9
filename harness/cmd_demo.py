"""``exohil demo``: the whole hardware-in-the-loop chain on the bundled held-out fixture.

Software Arduino on a pty (wire protocol v1, paced at 250 Hz, realistic faults unless
``--no-faults``) → acquisition thread (pyserial, COBS, CRC) → streaming ENNet (reference
model) → MoBL-ARMS → ISB → quaternion → NAO joints → NAO's arms simulated in MuJoCo. It
prints a live status line while it runs and, at the end, the link statistics reconciled with
the emulator's fault log, per-stage latency (p50/p99/max), the accuracy against the fixture's
motion capture and the teleoperation and robot errors, then writes the report folder
(``--out``, :mod:`exohil.harness.demo_report`). The fixture is one the reference models never
saw in training.
"""

from __future__ import annotations

from pathlib import Path

import click

from exohil.harness.cli_types import (
    MAX_DURATION_S,
    FaultSpec,
    Finite,
    InputFile,
    OutputDir,
    OutputFile,
    Robot,
    Seed,
)
from exohil.harness.paths import FIXTURES_DIR, MODELS_DIR

DEFAULT_RECORDING = FIXTURES_DIR / "paper_protocol_heldout.mcap"
DEFAULT_MODEL = MODELS_DIR / "ennet.npz"
#: Realistic link faults: rare drops and corrupted frames, a short USB stall every 5 s.
DEFAULT_FAULTS = "drop:rate=0.002;corrupt:rate=0.001;stall:every_s=5,duration_ms=20"
#: The report folder.
DEFAULT_OUT = Path("demo-report")
#: The robot the demo drives unless told otherwise: NAO's arms in MuJoCo.
DEFAULT_ROBOTS = ("mujoco",)


@click.command("demo")
@click.option("--bench", "bench_file", type=InputFile(), default=None,
              help="Bench configuration (TOML, docs/architecture.md); the options below "
                   "override it.")
@click.option("--recording", type=InputFile(), default=None,
              help=f"Recording the emulator replays [default: {DEFAULT_RECORDING.name}, "
                   "held out from the reference models' training].")
@click.option("--model", type=InputFile(), default=None,
              help=f"Estimator checkpoint [default: {DEFAULT_MODEL}].")
@click.option("--seconds", type=Finite(1.0, MAX_DURATION_S), default=15.0,
              show_default=True, help="Device time to stream (the device runs in real time).")
@click.option("--faults", type=FaultSpec(), default=None,
              help=f"Emulator fault spec (docs/emulator.md) [default: {DEFAULT_FAULTS!r}].")
@click.option("--no-faults", is_flag=True, help="Stream without injected faults.")
@click.option("--seed", type=Seed(), default=None, help="Seed for faults [0].")
@click.option("--backend", type=click.Choice(["auto", "numpy", "torch", "torchscript",
                                              "onnxruntime"]),
              default=None, help="Streaming inference backend [auto: onnxruntime when "
                                 "installed, else numpy (torch for a CNN)].")
@click.option("--record", "record_path", type=OutputFile(), default=None,
              help="Also write the frames the host received to this recording (MCAP).")
@click.option("--json", "json_out", type=OutputFile(), default=None,
              help="Also write the summary (summary.json layout) here.")
@click.option("--out", "out_dir", type=OutputDir(), default=DEFAULT_OUT, show_default=True,
              help="Report folder: summary.json, summary.md, angles/latency/hysteresis PNGs, "
                   "arm.gif and arm_NNNNN.png, run.mcap; an earlier report's files there are "
                   "removed first, so the two never mix.")
@click.option("--sink", "sinks", type=Robot(), multiple=True,
              help="Robot the commands go to (repeatable): mujoco (NAO's arms in MuJoCo), "
                   "simulated, udp:HOST:PORT or none [default: the bench's robots with "
                   "--bench, else mujoco].")
def demo(bench_file: Path | None, recording: Path | None, model: Path | None, seconds: float,
         faults: str | None, no_faults: bool, seed: int | None, backend: str | None,
         record_path: Path | None, json_out: Path | None, out_dir: Path,
         sinks: tuple[str, ...]) -> None:
    """Run the full chain (emulated device → acquisition → ENNet → NAO) and report."""
    from exohil.harness.bench import BenchConfig, BenchError, EmulatorDevice, load_bench

    if no_faults and faults:
        raise click.UsageError("--faults and --no-faults exclude each other")
    try:
        config = load_bench(bench_file) if bench_file else BenchConfig()
    except BenchError as err:
        raise click.ClickException(str(err)) from None
    device = config.device
    if device is not None and not isinstance(device, EmulatorDevice):
        raise click.ClickException("the demo runs the emulator; for a serial device use "
                                   "`exohil run`")
    base = device or EmulatorDevice(DEFAULT_RECORDING, DEFAULT_FAULTS)
    fault_spec = None if no_faults else (faults or base.faults)
    config = config.with_overrides(
        device=EmulatorDevice(recording or base.recording, fault_spec,
                              base.seed if seed is None else seed, base.loop),
        model=model or config.model or DEFAULT_MODEL, backend=backend, record=record_path,
        robots=(tuple(s for s in sinks if s != "none") if sinks
                else None if bench_file else DEFAULT_ROBOTS))
    from exohil.harness.cmd_run import run_and_report

    run_and_report(config, seconds, json_out, title="exohil demo", out_dir=out_dir)


COMMANDS = [demo]
