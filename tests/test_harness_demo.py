"""`exohil demo` end to end: emulator on a pty → acquisition → reference ENNet → NAO."""

import json

import numpy as np
from click.testing import CliRunner

from exohil.harness.cli import main


def test_demo_streams_the_fixture_through_the_whole_chain(tmp_path):
    summary_path = tmp_path / "summary.json"
    record_path = tmp_path / "session.mcap"
    result = CliRunner().invoke(main, ["demo", "--seconds", "2", "--json", str(summary_path),
                                       "--record", str(record_path)])
    assert result.exit_code == 0, result.output
    s = json.loads(summary_path.read_text())
    assert s["frames"] > 0
    assert s["link"]["crc_errors"] == 0 and s["link"]["decode_errors"] == 0
    assert s["nao"]["commands"] == s["frames"]
    assert all(np.isfinite(v) for v in s["rmse_deg"].values())
    assert "accuracy" in result.output and "end to end" in result.output

    from exohil.formats.recording_reader import read_recording

    assert len(read_recording(record_path).sensors) == s["frames"]


def test_demo_rejects_a_missing_model_with_one_line(tmp_path):
    result = CliRunner().invoke(main, ["demo", "--model", str(tmp_path / "nope.npz")])
    assert result.exit_code != 0
    assert "checkpoint not found" in result.output
    assert "Traceback" not in result.output
