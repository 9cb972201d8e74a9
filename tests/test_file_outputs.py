"""Nothing overwritten by accident: whole-file outputs, outputs that are inputs refused, reads
that check the format before loading, and too little data refused (issue 13)."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from exohil.formats import atomic
from exohil.formats.errors import RecordingError
from exohil.formats.recording import AngleStream, Recording, SensorStream
from exohil.formats.recording_reader import read_recording
from exohil.formats.recording_writer import RecordingWriter, write_recording
from exohil.harness.cli import main

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures"
RECORDING = FIXTURES / "real_motion_abd_flx.mcap"
MODEL = FIXTURES / "models" / "ann.npz"


def _siblings(path: Path) -> list[str]:
    return sorted(p.name for p in path.parent.iterdir())


# ---------------------------------------------------------------- whole-file writes


@pytest.mark.parametrize("error", [RuntimeError, KeyboardInterrupt])
def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path, error):
    target = tmp_path / "out.txt"
    target.write_text("old")
    with pytest.raises(error), atomic.replacing(target) as tmp:
        tmp.write_text("half")
        raise error()
    assert target.read_text() == "old"
    assert _siblings(target) == ["out.txt"]


def test_a_complete_write_replaces_the_file(tmp_path):
    target = tmp_path / "out.txt"
    target.write_text("old")
    atomic.write_text(target, "new")
    assert target.read_text() == "new" and _siblings(target) == ["out.txt"]


def test_a_recording_interrupted_while_written_leaves_the_old_one(tmp_path, monkeypatch):
    target = tmp_path / "rec.mcap"
    shutil.copyfile(RECORDING, target)
    before = target.read_bytes()
    rec = read_recording(RECORDING)

    def interrupted(self, *args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(RecordingWriter, "add_sensor_frames", interrupted)
    with pytest.raises(KeyboardInterrupt):
        write_recording(target, rec)
    assert target.read_bytes() == before and _siblings(target) == ["rec.mcap"]


def test_a_recording_with_a_bad_value_names_the_target_not_the_temporary(tmp_path):
    rec = Recording(sensor_names=("a",), sensors=SensorStream(
        np.arange(3), np.arange(3) / 100, np.array([[1.0], [np.nan], [2.0]])), mocap={})
    with pytest.raises(RecordingError, match=r"^\S*bad\.mcap: sensor values must be finite"):
        write_recording(tmp_path / "bad.mcap", rec)
    assert _siblings(tmp_path / "bad.mcap") == []


def test_same_file_sees_links(tmp_path):
    data = tmp_path / "a.mcap"
    data.write_bytes(b"x")
    (tmp_path / "soft.mcap").symlink_to(data)
    os.link(data, tmp_path / "hard.mcap")
    assert atomic.same_file(tmp_path / "soft.mcap", [data]) == data
    assert atomic.same_file(tmp_path / "hard.mcap", [tmp_path / "other", data]) == data
    assert atomic.same_file(tmp_path / "new.mcap", [data]) is None


# ---------------------------------------------------------------- outputs that are inputs

_COMMANDS = {
    "demo --record": ["demo", "--recording", "{rec}", "--record", "{rec}", "--seconds", "2"],
    "demo --json": ["demo", "--recording", "{rec}", "--json", "{rec}", "--seconds", "2"],
    "demo --out": ["demo", "--recording", "{dir}/run.mcap", "--out", "{dir}", "--seconds", "2"],
    "demo --model": ["demo", "--model", "{model}", "--record", "{model}", "--seconds", "2"],
    "import mot": ["import", "mot", "{rec}", "--out", "{rec}"],
    "import csv": ["import", "csv", "{rec}", "--rate", "100", "--sensor-cols", "1",
                   "--out", "{rec}"],
    "train": ["train", "--model", "ann", "{rec}", "--out", "{rec}"],
    "evaluate": ["evaluate", "{model}", "{rec}", "--json", "{model}"],
    "table --out": ["table", "--train", "{rec}", "--out", "{rec}"],
    "plot": ["plot", "{rec}", "--kind", "timeseries", "--out", "{rec}"],
    "simulate": ["simulate", "--protocol", "mot:{rec}", "--out", "{rec}"],
    "simulate --protocol replay:": ["simulate", "--protocol", "replay:{link}", "--out", "{rec}"],
    "emulate": ["emulate", "{rec}", "--fault-log", "{rec}", "--duration", "1"],
    "discrepancy": ["discrepancy", "{dir}/report.md", "--out", "{dir}"],
    "record recover": ["record", "recover", "{rec}", "--out", "{link}"],
    "conform": ["conform", "--target", "emulator:{dir}/run.mcap", "--model", "{model}",
                "--out", "{dir}"],
}


@pytest.mark.parametrize("name", sorted(_COMMANDS))
def test_an_output_that_is_an_input_is_refused_before_any_work(tmp_path, name):
    folder = tmp_path / "report"
    folder.mkdir()
    rec, model = tmp_path / "rec.mcap", tmp_path / "model.npz"
    shutil.copyfile(RECORDING, rec)
    shutil.copyfile(RECORDING, folder / "run.mcap")
    shutil.copyfile(RECORDING, folder / "report.md")
    shutil.copyfile(MODEL, model)
    (tmp_path / "link.mcap").symlink_to(rec)
    inputs = [rec, model, folder / "run.mcap", folder / "report.md"]
    before = {p: p.read_bytes() for p in inputs}
    args = [a.format(rec=rec, model=model, dir=folder, link=tmp_path / "link.mcap")
            for a in _COMMANDS[name]]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 2, result.output
    assert "refusing to overwrite" in result.output and "Traceback" not in result.output
    assert {p: p.read_bytes() for p in inputs} == before
    assert sorted(p.name for p in folder.iterdir()) == ["report.md", "run.mcap"]


# ---------------------------------------------------------------- reads check first


@pytest.mark.parametrize("special", ["/dev/zero", "fifo", "folder"])
def test_reading_a_file_that_is_not_a_regular_file_is_refused_at_once(tmp_path, special):
    if special == "fifo":
        path = tmp_path / "pipe.mcap"
        os.mkfifo(path)  # opening it would block until a writer comes
    elif special == "folder":
        path = tmp_path
    else:
        path = Path(special)
    with pytest.raises(RecordingError, match="not a regular file"):
        read_recording(path)


def test_record_info_on_dev_zero_is_one_line():
    result = CliRunner().invoke(main, ["record", "info", "/dev/zero"])
    assert result.exit_code == 1
    assert result.output == "Error: /dev/zero: not a regular file\n"


def test_a_nan_cell_in_a_csv_is_refused_and_the_old_output_kept(tmp_path):
    good, bad, out = tmp_path / "good.csv", tmp_path / "bad.csv", tmp_path / "out.mcap"
    good.write_text("a,b\n1,2\n3,4\n5,6\n")
    bad.write_text("a,b\n1,2\n3,nan\n5,6\n")
    args = ["--rate", "100", "--sensor-cols", "1", "--angle-cols", "0", "--out", str(out)]
    assert CliRunner().invoke(main, ["import", "csv", str(good), *args]).exit_code == 0
    before = out.read_bytes()
    result = CliRunner().invoke(main, ["import", "csv", str(bad), *args])
    assert result.exit_code == 1
    assert "data row 2, column 1: 'nan' is not a finite number" in result.output
    assert out.read_bytes() == before and _siblings(out) == ["bad.csv", "good.csv", "out.mcap"]


@pytest.mark.parametrize("frames", [1, 2, 100])
def test_training_on_too_little_data_is_one_line_and_writes_nothing(tmp_path, frames):
    rec = read_recording(RECORDING)
    s, m = rec.sensors, rec.mocap["shoulder"]
    short = tmp_path / "short.mcap"
    write_recording(short, Recording(
        sensor_names=rec.sensor_names, sensors=SensorStream(s.seq[:frames], s.t[:frames],
                                                            s.values[:frames]),
        mocap={"shoulder": AngleStream(m.t[:frames], m.names, m.angles[:frames])}))
    result = CliRunner().invoke(main, ["train", "--model", "ann", str(short),
                                       "--out", str(tmp_path / "m.npz")])
    assert result.exit_code == 1 and "Traceback" not in result.output
    assert len(result.output.strip().splitlines()) == 1, result.output
    assert not (tmp_path / "m.npz").exists()


@pytest.mark.parametrize("args", [
    ["simulate", "--out", "{bad}/x.mcap"],
    ["import", "mot", str(RECORDING), "--out", "{bad}/x.mcap"],
    ["emulate", str(RECORDING), "--duration", "1", "--fault-log", "{bad}/f.log"],
    ["discrepancy", str(RECORDING), "--out", "{bad}/d"],
    ["demo", "--out", "{bad}/report"],
    ["conform", "--target", f"emulator:{RECORDING}", "--model", str(MODEL), "--out", "{bad}/c"],
])
@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs Linux /proc")
def test_an_output_folder_that_takes_no_files_is_refused_before_any_work(args):
    # /proc exists but no new file can be created in it, even by root
    result = CliRunner().invoke(main, [a.format(bad="/proc") for a in args])
    assert result.exit_code == 2, result.output
    assert "cannot write in folder /proc: no new file can be created there" in result.output
