"""A serial device streamed to its reference's end (``run_session(config, None)`` with a
``SerialDevice`` that has a reference): an outage shorter than ``DEVICE_TIMEOUT_S`` is ridden
out, and a device that stops before the reference's end is ``device_lost``. The device is the
in-process emulator on a pty, replaying a part of the held-out fixture (its device clock is
the recording's clock)."""

from __future__ import annotations

from pathlib import Path

import pytest

from exohil.emulators.arduino import ArduinoEmulator
from exohil.formats.recording import cut_recording
from exohil.formats.recording_reader import read_recording
from exohil.formats.recording_writer import write_recording
from exohil.harness import bench
from exohil.harness.bench import BenchConfig, SerialDevice
from exohil.harness.paths import FIXTURES_DIR
from exohil.harness.session import run_session

MODEL = FIXTURES_DIR / "models" / "ennet.npz"


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> Path:
    """7 s of the held-out fixture, as a file (a device's reference is a path)."""
    rec = read_recording(FIXTURES_DIR / "paper_protocol_heldout.mcap")
    path = tmp_path_factory.mktemp("reference") / "part.mcap"
    write_recording(path, cut_recording(rec, 40.0, 47.0))
    return path


def _session(reference: Path, **emulator):
    rec = read_recording(reference)
    # the device's clock starts once the session has the port open: on a busy machine the
    # session took over 1.5 s to open it, so the outage below met no host and was not seen
    with ArduinoEmulator.from_recording(rec, autostart=False, **emulator) as device:
        device.begin(when_attached=True)
        config = BenchConfig(device=SerialDevice(device.port, reference), model=MODEL,
                             robots=())
        return rec, run_session(config, None, reference=rec)


def test_an_outage_shorter_than_the_device_timeout_is_ridden_out(reference):
    """A 3.5 s USB disconnect 1.5 s in: the run used to end 3 s into the outage (an idle
    timeout of its own), "complete", with 1.5 s of the 7 s reference scored."""
    rec, result = _session(reference, faults="disconnect:at_s=1.5,for_s=3.5")
    link = result.run.link
    assert link.disconnects == 1 and link.reconnects == 1
    assert result.device_lost is None
    assert result.run.last_device_time_s >= float(rec.sensors.t[-1]) - 0.01
    assert result.run.frames > 0.25 * len(rec.sensors)  # after the outage too


def test_a_device_that_stops_before_the_references_end_is_lost(reference, monkeypatch):
    """The device stops streaming 3 s into a 7 s reference: the run ended 3 s later with
    nothing said, so conform passed and `exohil run` exited 0 on 3 s of the reference."""
    monkeypatch.setattr(bench, "DEVICE_TIMEOUT_S", 4.0)  # above the old 3 s idle timeout
    rec, result = _session(reference, duration_s=3.0)
    assert result.run.last_device_time_s < float(rec.sensors.t[0]) + 3.1
    assert result.device_lost is not None
    assert "no frame from" in result.device_lost
    assert "before the reference's end" in result.device_lost
