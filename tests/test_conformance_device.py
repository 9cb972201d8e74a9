"""`exohil conform --target DEVICE --reference REC`: a serial device streamed to its
reference's end. The device is the in-process emulator on a pty replaying a part of the
held-out fixture (its device clock is the recording's), started when the host opens the port
(a device reset by the host's open) or streaming already (a device that was on before).

Each test proves a way such a run passed that it should not have: a device lost mid-run, a
segment that missed part of the reference, a reference shorter than the profile's segment, a
latency failure discarded for a retry that cannot run, and a device that never came, tried
again by every check."""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
from click.testing import CliRunner

from exohil.emulators.arduino import ArduinoEmulator
from exohil.formats.recording import cut_recording
from exohil.formats.recording_reader import read_recording
from exohil.formats.recording_writer import write_recording
from exohil.harness import bench
from exohil.harness.cli import main
from exohil.harness.paths import FIXTURES_DIR, MODELS_DIR

ENNET = MODELS_DIR / "ennet.npz"
SEGMENT_CHECKS = ("accuracy", "latency", "link", "teleop")

#: No accuracy limits: the built-in reference coverage is what the accuracy check judges here.
PROFILE = """
name = "device-test"
description = "a 3 s real-time segment; accuracy judged on its coverage of the reference"
[settings]
realtime_seconds = 3
latency_attempts = ATTEMPTS
[checks.compatibility]
[checks.heldout]
[checks.accuracy]
[checks.latency]
LATENCY
[checks.link]
[checks.conversions]
[checks.teleop]
"""


def profile(tmp_path: Path, attempts: int = 1, latency: str = "") -> Path:
    path = tmp_path / "device.toml"
    path.write_text(PROFILE.replace("ATTEMPTS", str(attempts)).replace("LATENCY", latency),
                    encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def heldout():
    return read_recording(FIXTURES_DIR / "paper_protocol_heldout.mcap")


def reference(heldout, tmp_path: Path, seconds: float) -> Path:
    path = tmp_path / f"part{seconds:g}.mcap"
    write_recording(path, cut_recording(heldout, 40.0, 40.0 + seconds))
    return path


@contextmanager
def device(ref: Path, on_open: bool = True, **kwargs) -> Iterator[ArduinoEmulator]:
    """The emulator replaying ``ref``: from its first frame once the host opens the port
    (``on_open``), else streaming from now on."""
    emulator = ArduinoEmulator.from_recording(read_recording(ref), autostart=not on_open,
                                              **kwargs)
    with emulator:
        if on_open:
            def begin_on_open() -> None:
                deadline = time.monotonic() + 120.0
                while not emulator._port.host_attached() and time.monotonic() < deadline:
                    time.sleep(0.005)
                emulator.begin()

            threading.Thread(target=begin_on_open, daemon=True).start()
        yield emulator


def conform(port: str, ref: Path, prof: Path, out: Path,
            checks: tuple[str, ...] = SEGMENT_CHECKS) -> tuple[int, str, dict]:
    result = CliRunner().invoke(main, ["conform", "--target", port, "--reference", str(ref),
                                       "--model", str(ENNET), "--profile", str(prof),
                                       "--out", str(out), "-k", " or ".join(checks)])
    report = json.loads((out / "conformance.json").read_text())
    return result.exit_code, result.output, report


def checks(report: dict) -> dict[str, dict]:
    return {c["name"]: c for c in report["checks"]}


def measured(report: dict) -> dict[str, dict]:
    return {m["name"]: m for c in report["checks"] for m in c["measurements"]}


def test_a_segment_that_cannot_run_is_tried_once_for_every_check(tmp_path, heldout,
                                                                 monkeypatch):
    """A device that never appears: each of accuracy, latency, link and teleop waited out
    the device timeout again (52 s where 13 s do), and could have judged different
    segments."""
    from exohil.conformance import context

    monkeypatch.setattr(bench, "DEVICE_TIMEOUT_S", 1.0)
    calls = []
    real = context.run_session

    def counted(*args, **kwargs):
        calls.append(args)
        return real(*args, **kwargs)

    monkeypatch.setattr(context, "run_session", counted)
    ref = reference(heldout, tmp_path, 4.0)
    code, output, report = conform(str(tmp_path / "ttyNONE"), ref, profile(tmp_path),
                                   tmp_path / "out")
    assert code != 0
    assert len(calls) == 1
    messages = {checks(report)[name]["message"] for name in SEGMENT_CHECKS}
    assert len(messages) == 1 and "could not run" in messages.pop()
