"""`exohil run URL --reference REC`: the run lasts until the device's clock passes the
reference's end, says so, and exits 3 when the device stops before that end. The device is the
in-process emulator on a pty replaying a part of the held-out fixture."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from exohil.emulators.arduino import ArduinoEmulator
from exohil.formats.recording import cut_recording
from exohil.formats.recording_reader import read_recording
from exohil.formats.recording_writer import write_recording
from exohil.harness import bench
from exohil.harness.cli import main
from exohil.harness.paths import FIXTURES_DIR


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> Path:
    rec = read_recording(FIXTURES_DIR / "paper_protocol_heldout.mcap")
    path = tmp_path_factory.mktemp("reference") / "part.mcap"
    write_recording(path, cut_recording(rec, 40.0, 43.0))
    return path


def _run(reference: Path, tmp_path: Path, **emulator):
    summary = tmp_path / "summary.json"
    with ArduinoEmulator.from_recording(read_recording(reference), autostart=False,
                                        **emulator) as device:
        device.begin()
        result = CliRunner().invoke(main, ["run", device.port, "--reference", str(reference),
                                           "--sink", "none", "--json", str(summary)])
    return result, summary


def test_a_run_to_the_references_end_says_so_and_exits_0(reference, tmp_path):
    """The header said "until Ctrl-C" though the run stops at the reference's end."""
    result, summary = _run(reference, tmp_path)
    assert result.exit_code == 0, result.output
    assert "until the device's clock passes the reference's end (or Ctrl-C)" in result.output
    assert "until Ctrl-C" not in result.output
    assert json.loads(summary.read_text())["device_lost"] is None


def test_a_device_that_stops_before_the_references_end_exits_3(reference, tmp_path,
                                                                 monkeypatch):
    """The device stops 1 s into a 3 s reference: the run exited 0 after an idle 3 s."""
    monkeypatch.setattr(bench, "DEVICE_TIMEOUT_S", 4.0)  # above the old 3 s idle timeout
    result, summary = _run(reference, tmp_path, duration_s=1.0)
    assert result.exit_code == 3, result.output
    assert "the device was lost before the end (exit status 3)" in result.output
    lost = json.loads(summary.read_text())["device_lost"]
    assert "before the reference's end" in lost
