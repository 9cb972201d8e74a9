"""Bench configuration: targets, TOML files, and tests that select on the bench's features."""

import os
from pathlib import Path

import pytest
from click.testing import CliRunner

from exohil.harness.bench import (
    BenchConfig,
    BenchError,
    EmulatorDevice,
    SerialDevice,
    device_rate_hz,
    load_bench,
    open_device,
    parse_target,
)
from exohil.harness.cli import main
from exohil.harness.paths import FIXTURES_DIR, MODELS_DIR

HELDOUT = FIXTURES_DIR / "paper_protocol_heldout.mcap"


def test_targets_parse():
    dev = parse_target("emulator:rec.mcap?faults=drop:rate=0.01;corrupt:rate=0.001&seed=3")
    assert dev == EmulatorDevice(Path("rec.mcap"), "drop:rate=0.01;corrupt:rate=0.001", 3)
    assert parse_target("emulator:rec.mcap") == EmulatorDevice(Path("rec.mcap"))
    assert parse_target("/dev/ttyACM0") == SerialDevice("/dev/ttyACM0")
    assert parse_target("socket://127.0.0.1:7000") == SerialDevice("socket://127.0.0.1:7000")


@pytest.mark.parametrize("text, message", [
    ("emulator:", "without a recording"),
    ("emulator:r.mcap?speed=2", "unknown emulator option"),
    ("emulator:r.mcap?seed=x", "seed must be an integer"),
    ("emulator:r.mcap?seed=-1", "seed must be an integer 0..4294967295"),
    ("emulator:r.mcap?seed=4294967296", "seed must be an integer 0..4294967295"),
    ("", "empty target"),
])
def test_bad_targets_are_one_clear_error(text, message):
    with pytest.raises(BenchError, match=message):
        parse_target(text)


def test_a_bench_file_names_device_model_sensors_robots(tmp_path):
    path = tmp_path / "bench.toml"
    path.write_text('[device]\nemulator = "rec.mcap"\nfaults = "drop:rate=0.01"\nseed = 2\n'
                    '[sensors]\nnames = ["F", "SF", "SR", "R"]\nrate_hz = 250\n'
                    '[model]\ncheckpoint = "m.npz"\n[teleop]\nrobots = ["simulated"]\n'
                    '[record]\npath = "out.mcap"\n', encoding="utf-8")
    bench = load_bench(path)
    assert bench.device == EmulatorDevice(tmp_path / "rec.mcap", "drop:rate=0.01", 2)
    assert bench.model == tmp_path / "m.npz" and bench.record == tmp_path / "out.mcap"
    assert bench.sensor_names == ("F", "SF", "SR", "R") and bench.robots == ("simulated",)
    assert bench.with_overrides(model=None, backend="numpy").model == tmp_path / "m.npz"
    path.write_text('[model]\nbackend = "auto"\n', encoding="utf-8")  # as the docs show
    assert load_bench(path).backend == "auto"


@pytest.mark.parametrize("text, message", [
    ("[devise]\n", "unknown section"),
    ("[device]\nport = 'x'\n", "unknown key"),
    ("[device]\nemulator = 'a.mcap'\nurl = '/dev/x'\n", "pick one"),
    ("[device\n", "bench.toml"),
    ("[device]\nemulator = 'a.mcap'\nseed = -1\n", "seed must be an integer"),
    ("[device]\nemulator = 'a.mcap'\nseed = 'x'\n", "seed must be an integer"),
    ("[device]\nemulator = 'a.mcap'\nseed = 1.5\n", "seed must be an integer"),
    ("[device]\nemulator = 'a.mcap'\nfaults = 'drop:rate=nan'\n", "faults: drop"),
    ("[device]\nemulator = 'a.mcap'\nloop = 'yes'\n", "loop must be true or false"),
    ("[device]\nemulator = 3\n", "emulator must be a non-empty string"),
    ("[sensors]\nrate_hz = nan\n", "rate_hz must be a number"),
    ("[sensors]\nrate_hz = -250\n", "rate_hz must be a number"),
    # these were read letter by letter, or failed with a TypeError, or only at run time
    ("[teleop]\nrobots = 'mujoco'\n", r"\[teleop\] robots must be a list of names"),
    ("[sensors]\nnames = 'F,SF,SR,R'\n", r"\[sensors\] names must be a list of names"),
    ("[model]\ncheckpoint = 5\n", "checkpoint must be a non-empty string"),
    ("[device]\nurl = '/dev/x'\nreference = 5\n", "reference must be a non-empty string"),
    ("[record]\npath = 5\n", "path must be a non-empty string"),
    ("[model]\nbackend = 'tensorflow'\n", "backend 'tensorflow'; choose from auto, numpy"),
])
def test_bad_bench_files_are_one_clear_error(tmp_path, text, message):
    path = tmp_path / "bench.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(BenchError, match=message):
        load_bench(path)


def test_the_demo_reads_a_bench_file(tmp_path):
    bench = tmp_path / "bench.toml"
    bench.write_text(f'[device]\nemulator = "{HELDOUT}"\nfaults = "corrupt:rate=0.05"\n'
                     f'[model]\ncheckpoint = "{MODELS_DIR / "ennet.npz"}"\n', encoding="utf-8")
    out = tmp_path / "s.json"
    result = CliRunner().invoke(main, ["demo", "--bench", str(bench), "--seconds", "2",
                                       "--json", str(out), "--out", str(tmp_path / "report")])
    assert result.exit_code == 0, result.output
    assert "corrupt" in out.read_text()


@pytest.mark.realtime
def test_acquisition_runs_under_sched_fifo():
    with open_device(EmulatorDevice(HELDOUT), 4, realtime=True, duration_s=1.0) as opened:
        frame = opened.source.get(timeout=5.0)
        assert frame is not None
        assert opened.source.realtime_error is None


@pytest.mark.device
def test_the_real_device_passes_the_bench_profile(tmp_path):
    args = ["conform", "--target", os.environ["EXOHIL_DEVICE"], "--model",
            str(MODELS_DIR / "ennet.npz"), "--profile", "bench", "--out", str(tmp_path)]
    if os.environ.get("EXOHIL_DEVICE_REFERENCE"):
        args += ["--reference", os.environ["EXOHIL_DEVICE_REFERENCE"]]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output


def test_the_device_rate_is_the_emulators_recording_else_the_bench_else_the_reference(
        tmp_path):
    from estimator_synth import shoulder_recording

    slow = shoulder_recording(seconds=1.0, rate=100.0)
    emulator = BenchConfig(device=EmulatorDevice(tmp_path / "slow.mcap"), rate_hz=500.0)
    assert device_rate_hz(emulator, slow) == 100.0  # it streams its recording at its rate
    serial = BenchConfig(device=SerialDevice("/dev/ttyACM0", None))
    assert device_rate_hz(serial, None) == 250.0  # the Due's
    assert device_rate_hz(serial, slow) == 100.0  # the reference's
    assert device_rate_hz(serial.with_overrides(rate_hz=200.0), slow) == 200.0  # stated
    path = tmp_path / "bench.toml"
    for text, rate in (('[sensors]\nrate_hz = 125\n', 125.0), ('[sensors]\nnames = ["F"]\n', None)):
        path.write_text(text, encoding="utf-8")
        assert load_bench(path).rate_hz == rate


def test_a_path_that_cannot_be_a_serial_device_says_why(tmp_path):
    from exohil.harness.bench import SerialDevice

    (tmp_path / "file.mcap").write_bytes(b"")
    assert "does not exist" in SerialDevice(str(tmp_path / "none")).path_problem()
    assert "is a folder" in SerialDevice(str(tmp_path)).path_problem()
    assert "regular file" in SerialDevice(str(tmp_path / "file.mcap")).path_problem()
    assert SerialDevice("/dev/null").path_problem() is None  # a device node may be one
    assert SerialDevice("loop://").path_problem() is None


def test_the_status_line_labels_the_error_and_the_estimate(capsys):
    import numpy as np

    from exohil.harness.cmd_run import status_line
    from exohil.harness.frame_source import LinkStats
    from exohil.harness.pipeline import Status

    status_line(Status(frames=250, link=LinkStats(), last=np.array([89.0, 88.4]),
                       recent_latency_ms=np.array([1.0, 2.0]), recent_device_time_s=np.zeros(2),
                       recent_estimates=np.zeros((2, 2)), error_deg=1.5))
    line = capsys.readouterr().err
    assert "arm error   1.5°" in line and "estimate   89.0°   88.4°" in line
