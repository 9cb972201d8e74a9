"""`exohil demo` end to end: emulator on a pty → acquisition → reference ENNet → NAO."""

import json

import numpy as np
from click.testing import CliRunner

from exohil.harness.cli import main


def test_demo_streams_the_fixture_through_the_whole_chain(tmp_path):
    summary_path = tmp_path / "summary.json"
    record_path = tmp_path / "session.mcap"
    result = CliRunner().invoke(main, ["demo", "--seconds", "3", "--json", str(summary_path),
                                       "--record", str(record_path),
                                       "--faults", "corrupt:rate=0.02;drop:rate=0.01"])
    assert result.exit_code == 0, result.output
    s = json.loads(summary_path.read_text())
    received = s["frames"]["received"]
    assert received > 0
    # every corrupted frame is rejected; one whose corruption made a new delimiter (0x00) is
    # rejected as two packets, so packets can outnumber corrupted frames
    rejected = s["link"]["crc_errors"] + s["link"]["decode_errors"]
    assert s["device_log"]["corrupt"] > 0 and rejected >= s["device_log"]["corrupt"]
    measured = {m["name"]: m for m in s["measurements"]}
    for exact in ("link.lost_on_host", "link.bad_frames_delivered", "link.dropped_unexplained"):
        assert measured[exact]["value"] == 0, measured[exact]
    assert s["teleop"]["robots"]["SimulatedNao"]["commands"] == received
    assert all(np.isfinite(v) for v in s["rmse"].values())
    assert np.isfinite(s["direction_rmse_deg"])
    assert set(s["latency_ms"]) >= {"device_to_host", "end_to_end", "estimator"}
    assert "accuracy" in result.output and "end_to_end" in result.output

    from exohil.formats.recording_reader import read_recording

    assert len(read_recording(record_path).sensors) == received


def test_demo_refuses_to_record_onto_its_input(tmp_path):
    import shutil

    from exohil.harness.paths import FIXTURES_DIR

    copy = tmp_path / "in.mcap"
    shutil.copyfile(FIXTURES_DIR / "paper_protocol_heldout.mcap", copy)
    before = copy.read_bytes()
    result = CliRunner().invoke(main, ["demo", "--seconds", "1", "--recording", str(copy),
                                       "--record", str(copy)])
    assert result.exit_code != 0 and "refusing to record onto an input" in result.output
    assert copy.read_bytes() == before


def test_demo_rejects_a_missing_model_with_one_line(tmp_path):
    result = CliRunner().invoke(main, ["demo", "--model", str(tmp_path / "nope.npz")])
    assert result.exit_code != 0
    assert "checkpoint not found" in result.output
    assert "Traceback" not in result.output
