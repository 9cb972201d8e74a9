"""Live recordings survive their writer: a killed process leaves a readable file that says it
was cut short, losing at most the last second, and `exohil record recover` makes it clean."""

import multiprocessing as mp
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from exohil.formats.recording_reader import read_recording, scan_recording
from exohil.formats.recording_writer import DURABLE_FLUSH_S, RecordingWriter
from exohil.harness.cli import main

RATE_HZ = 250.0
SENSORS = ("F", "SF", "SR", "R")


def _write_then_die(path: str, frames: int) -> None:
    writer = RecordingWriter(path, SENSORS, durable=True, metadata={"generator": "test"})
    start = time.monotonic()
    for k in range(frames):
        while time.monotonic() < start + k / RATE_HZ:  # a 250 Hz device
            time.sleep(0.0005)
        writer.add_sensor_frame(k, k / RATE_HZ, [100.0 + k, 200.0, 300.0, 400.0])
    os._exit(9)  # no close(): as if killed


def test_a_killed_durable_writer_loses_at_most_its_last_second(tmp_path):
    path = tmp_path / "killed.mcap"
    frames = int(3 * RATE_HZ)
    child = mp.get_context("fork").Process(target=_write_then_die, args=(str(path), frames))
    child.start()
    child.join(60)
    assert child.exitcode == 9
    scan = scan_recording(path)
    kept = len(scan.recording.sensors)
    assert scan.lost_bytes is not None and any(n.startswith("cut short") for n in scan.notes)
    assert frames - kept <= DURABLE_FLUSH_S * RATE_HZ + 5, f"kept {kept} of {frames}"
    assert np.array_equal(scan.recording.sensors.seq, np.arange(kept))  # a clean prefix
    assert scan.recording.metadata["generator"] == "test"


def test_a_closed_durable_recording_is_complete(tmp_path):
    path = tmp_path / "closed.mcap"
    with RecordingWriter(path, SENSORS, durable=True) as writer:
        writer.add_sensor_frames(np.arange(500), np.arange(500) / RATE_HZ,
                                 np.ones((500, 4)))
    scan = scan_recording(path)
    assert scan.lost_bytes is None and len(scan.recording.sensors) == 500
    assert not any("exohil.recording' records" in n for n in scan.notes)  # one metadata record


def test_recover_writes_a_clean_copy_and_says_what_was_lost(tmp_path):
    path = tmp_path / "killed.mcap"
    child = mp.get_context("fork").Process(target=_write_then_die, args=(str(path), 600))
    child.start()
    child.join(60)
    kept = len(read_recording(path).sensors)
    out = tmp_path / "clean.mcap"
    result = CliRunner().invoke(main, ["record", "recover", str(path), "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert f"recovered {kept} sensor frames" in result.output and "never closed" in result.output
    clean = scan_recording(out)
    assert clean.lost_bytes is None and len(clean.recording.sensors) == kept
    again = CliRunner().invoke(main, ["record", "recover", str(out), "--out",
                                      str(tmp_path / "again.mcap")])
    assert "lost: nothing" in again.output
    refused = CliRunner().invoke(main, ["record", "recover", str(out), "--out", str(out)])
    assert refused.exit_code != 0 and "refusing to overwrite it" in refused.output


def test_recover_refuses_a_file_cut_before_its_first_record(tmp_path):
    """The first third of a recording written whole (one chunk of 20 s): recover wrote an
    empty recording, said "recovered 0 sensor frames" and exited 0."""
    from exohil.formats.recording import Recording, SensorStream
    from exohil.formats.recording_writer import write_recording

    n = 5000
    whole, cut = tmp_path / "whole.mcap", tmp_path / "cut.mcap"
    values = 500 + 50 * np.random.default_rng(0).random((n, 4))
    write_recording(whole, Recording(("F", "SF", "SR", "R"),
                                     SensorStream(np.arange(n), np.arange(n) / 250, values)))
    data = whole.read_bytes()
    cut.write_bytes(data[: len(data) // 3])
    assert scan_recording(cut).lost_bytes  # the metadata is read, no frame is
    out = tmp_path / "clean.mcap"
    result = CliRunner().invoke(main, ["record", "recover", str(cut), "--out", str(out)])
    assert result.exit_code == 1, result.output
    assert f"nothing to recover from {cut}: no complete record" in result.output
    assert not out.exists()


@pytest.mark.parametrize("cut_bytes", [8, 3])
def test_a_file_cut_only_in_its_closing_magic_says_its_footer_is_there(tmp_path, cut_bytes):
    """A closed recording whose trailing magic alone is cut: `record info` said it was never
    closed "(no footer)", and recover that segments were lost, though the footer and every
    record before it (segments included) were there."""
    from exohil.formats.recording import Segment

    whole, cut = tmp_path / "whole.mcap", tmp_path / "cut.mcap"
    with RecordingWriter(whole, SENSORS) as writer:
        writer.add_sensor_frames(np.arange(500), np.arange(500) / RATE_HZ, np.ones((500, 4)))
        writer.add_segment(Segment("all", 0.0, 1.0))
    cut.write_bytes(whole.read_bytes()[:-cut_bytes])
    scan = scan_recording(cut)
    assert scan.lost_bytes is None and scan.magic_missing == cut_bytes
    assert len(scan.recording.sensors) == 500 and [s.name for s in scan.recording.segments] \
        == ["all"]
    info = CliRunner().invoke(main, ["record", "info", str(cut)])
    assert info.exit_code == 0, info.output
    assert "no footer" not in info.output and "never closed" not in info.output
    assert "cut short after its footer" in info.output and "nothing is lost" in info.output
    out = tmp_path / "clean.mcap"
    result = CliRunner().invoke(main, ["record", "recover", str(cut), "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "never closed" not in result.output
    assert f"lost: nothing (every record was there, up to the footer; only the last " \
           f"{cut_bytes} bytes of the closing MCAP magic were missing)" in result.output
    assert out.read_bytes() == whole.read_bytes()


@pytest.mark.slow
def test_sigkill_during_a_recorded_demo_leaves_a_readable_recording(tmp_path):
    target = tmp_path / "k.mcap"
    partial = tmp_path / "k.mcap.partial"
    exohil = Path(sys.executable).with_name("exohil")
    proc = subprocess.Popen([str(exohil), "demo", "--seconds", "60", "--no-faults",
                             "--record", str(target)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            # a killed emulator cannot remove its device link: keep it here
                            env={**os.environ, "TMPDIR": str(tmp_path)})
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and (not partial.exists()
                                               or partial.stat().st_size < 50_000):
            time.sleep(0.2)
        assert partial.exists(), "the demo never started recording"
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(30)
    assert not target.exists()  # only a complete recording takes the real name
    scan = scan_recording(partial)
    assert len(scan.recording.sensors) > 0 and scan.lost_bytes is not None
    assert scan.recording.metadata.get("generator") == "exohil"


def test_a_run_that_records_no_frame_leaves_an_existing_recording_as_it_was(tmp_path):
    """A device that never sends a frame: run fails with one line, the recording already at
    --record is neither replaced by an empty one nor joined by a .partial, and the report
    folder made for the run is gone again."""
    old = tmp_path / "old.mcap"
    with RecordingWriter(old, ["a", "b"]) as writer:
        writer.add_sensor_frame(0, 0.0, [1.0, 2.0])
    before = old.read_bytes()
    result = CliRunner().invoke(main, ["run", str(tmp_path / "no-such-port"), "--duration", "1",
                                       "--record", str(old), "--out",
                                       str(tmp_path / "report" / "out")])
    assert result.exit_code != 0
    assert "no frame arrived" in result.output and "does not exist" in result.output
    assert old.read_bytes() == before
    assert sorted(p.name for p in tmp_path.glob("old.mcap*")) == ["old.mcap"]
    assert not (tmp_path / "report").exists()  # nor the report folders it made for nothing


def test_recover_of_a_file_cut_after_a_complete_record_does_not_say_nothing_was_lost(
        tmp_path, monkeypatch):
    """A durable writer killed between two syncs leaves a file that ends after a complete
    record, and recover said "lost: the 0 bytes after the last complete record", which reads
    as nothing lost, while up to a second of frames and the metadata written at close were."""
    import exohil.formats.recording_writer as recording_writer

    monkeypatch.setattr(recording_writer, "DURABLE_FLUSH_S", 0.0)  # a sync after each frame
    live, copy = tmp_path / "live.mcap", tmp_path / "killed.mcap"
    with RecordingWriter(live, SENSORS, durable=True) as writer:
        writer.add_sensor_frames(np.arange(50), np.arange(50) / RATE_HZ, np.ones((50, 4)))
        copy.write_bytes(live.read_bytes())  # the file as a kill now would leave it
    scan = scan_recording(copy)
    assert scan.lost_bytes == 0
    assert "but what its writer had not yet written out is not in it" in scan.notes[0]
    result = CliRunner().invoke(main, ["record", "recover", str(copy), "--out",
                                       str(tmp_path / "clean.mcap")])
    assert result.exit_code == 0, result.output
    assert "recovered 50 sensor frames" in result.output
    assert "lost: no partial record" in result.output and "at most its last second" in \
        result.output and "0 bytes" not in result.output
