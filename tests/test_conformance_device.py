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


def test_a_whole_reference_streamed_passes_and_shows_its_coverage(heldout, tmp_path):
    """The control: a 4 s reference streamed from its first frame, under a 3 s segment."""
    ref = reference(heldout, tmp_path, 4.0)
    with device(ref) as emulator:
        code, output, report = conform(emulator.port, ref, profile(tmp_path), tmp_path / "out")
    assert all(checks(report)[name]["verdict"] == "pass" for name in SEGMENT_CHECKS), output
    coverage = measured(report)["accuracy.reference_coverage"]
    assert coverage["verdict"] == "pass" and coverage["value"] >= 99.0
    assert "of the reference's 995 frames" in coverage["note"]


def test_a_device_lost_mid_run_fails_every_check_of_the_segment(heldout, tmp_path,
                                                                  monkeypatch):
    """The device stops 2 s into a 4 s reference: conform passed on what it had streamed,
    the loss said nowhere."""
    monkeypatch.setattr(bench, "DEVICE_TIMEOUT_S", 4.0)  # above the old 3 s idle timeout
    ref = reference(heldout, tmp_path, 4.0)
    with device(ref, duration_s=2.0) as emulator:
        code, output, report = conform(emulator.port, ref, profile(tmp_path), tmp_path / "out")
    assert code != 0
    for name in SEGMENT_CHECKS:
        check = checks(report)[name]
        assert check["verdict"] == "fail", (name, check)
        assert "the device was lost during the real-time segment" in check["message"]
        assert "before the reference's end" in check["message"]


def test_a_device_already_streaming_misses_the_reference_and_fails_accuracy(heldout,
                                                                            tmp_path):
    """The device streams 2.5 s of a 5 s reference before the run opens it: accuracy
    passed on the half it scored, and nothing showed the reference's frame count."""
    ref = reference(heldout, tmp_path, 5.0)
    with device(ref, on_open=False) as emulator:
        time.sleep(2.5)
        code, output, report = conform(emulator.port, ref, profile(tmp_path), tmp_path / "out",
                                       ("accuracy", "latency"))
    assert code != 0
    coverage = measured(report)["accuracy.reference_coverage"]
    assert coverage["verdict"] == "fail" and coverage["value"] < 90.0, coverage
    assert "of the reference's 1245 frames" in coverage["note"]
    assert checks(report)["accuracy"]["verdict"] == "fail"
    latency = checks(report)["latency"]  # a 5 s reference, of which under 2.7 s streamed
    assert latency["verdict"] == "skip", latency
    assert "the device streamed only part of it" in latency["message"]


def test_a_reference_shorter_than_the_profiles_segment_does_not_pass_the_segment_checks(
        heldout, tmp_path):
    """A 2 s reference under a 3 s segment: latency, link and teleop passed on it (any
    segment of 1 s did); accuracy is judged on the reference it covers."""
    ref = reference(heldout, tmp_path, 2.0)
    with device(ref) as emulator:
        code, output, report = conform(emulator.port, ref, profile(tmp_path), tmp_path / "out")
    assert code != 0
    assert checks(report)["accuracy"]["verdict"] == "pass", output
    for name in ("latency", "link", "teleop"):
        check = checks(report)[name]
        assert check["verdict"] == "skip", (name, check)
        assert "where 3 s are asked for" in check["message"]
        assert "give a reference of at least 2.7 s" in check["message"]


def test_latency_of_a_device_with_a_reference_is_judged_on_its_one_segment(heldout, tmp_path):
    """latency_attempts = 2 and a limit no machine meets: the check asked the device for a
    second segment, found its clock past the reference's end and was skipped, the first
    segment's failure discarded."""
    ref = reference(heldout, tmp_path, 4.0)
    prof = profile(tmp_path, attempts=2, latency='"latency.end_to_end.p50" = "< 0.001 ms"')
    with device(ref) as emulator:
        code, output, report = conform(emulator.port, ref, prof, tmp_path / "out",
                                       ("latency",))
    latency = checks(report)["latency"]
    assert latency["verdict"] == "fail", latency
    assert "latency.end_to_end.p50" in latency["message"]
    attempts = measured(report)["latency.attempts"]
    assert attempts["value"] == 1
    assert "judged on the one segment" in attempts["note"]


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
