"""`exohil demo` end to end: emulator on a pty → acquisition → reference ENNet → NAO (MuJoCo),
and its report folder; `exohil run --out` against a separately started `exohil emulate`."""

import json
import os
import signal
import subprocess
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from cli_interrupt import interrupt_once_streaming, sigint_handled_by
from click.testing import CliRunner
from PIL import Image

from exohil.harness import cmd_run
from exohil.harness.cli import main
from exohil.harness.paths import FIXTURES_DIR

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
REPORT_FILES = {"summary.json", "summary.md", "angles.png", "latency.png", "hysteresis.png",
                "arm.gif", "run.mcap", *(f"arm_{k:05d}.png" for k in range(4))}


def check_report(out: Path, output: str, received: int) -> dict:
    """Every report file is there, complete and readable; returns summary.json."""
    assert {p.name for p in out.iterdir()} == REPORT_FILES  # no temporary file left
    for name in REPORT_FILES:
        assert f"{out / name}" in output  # the report says where every file is
        if name.endswith(".png"):
            assert (out / name).read_bytes()[:8] == PNG_MAGIC, name
    with Image.open(out / "arm.gif") as gif:
        assert gif.format == "GIF" and gif.n_frames > 1
        gif.seek(gif.n_frames - 1)
        gif.load()
    from mcap.reader import make_reader

    from exohil.formats.recording_reader import read_recording

    recording = read_recording(out / "run.mcap")
    assert len(recording.sensors) == received
    with open(out / "run.mcap", "rb") as fh:
        topics = Counter(channel.topic for _, channel, _ in make_reader(fh).iter_messages())
    assert topics["/timing/stages"] == received and topics["/robot/nao"] == received
    s = json.loads((out / "summary.json").read_text())
    assert {"rmse", "direction_rmse_deg", "latency_ms", "frames", "teleop"} <= set(s)
    assert {"sent", "received", "dropped", "crc_errors"} <= set(s["frames"])
    for stats in s["latency_ms"].values():
        assert set(stats) == {"p50", "p99", "max"}
    assert "| latency.robot_step.p99 |" in (out / "summary.md").read_text()
    assert json.loads(recording.metadata["latency_ms"]) == s["latency_ms"]
    return s


def test_demo_streams_the_fixture_through_the_whole_chain(tmp_path):
    summary_path = tmp_path / "summary.json"
    record_path = tmp_path / "session.mcap"
    out = tmp_path / "report"
    result = CliRunner().invoke(main, ["demo", "--seconds", "3", "--json", str(summary_path),
                                       "--record", str(record_path), "--out", str(out),
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
    assert s["teleop"]["robots"]["MujocoNao"]["commands"] == received  # the demo's robot
    assert s["frames"]["sent"] >= received
    assert all(np.isfinite(v) for v in s["rmse"].values())
    assert np.isfinite(s["direction_rmse_deg"])
    assert set(s["latency_ms"]) >= {"device_to_host", "end_to_end", "estimator", "robot_step"}
    for stat in ("p50", "p99", "max"):
        assert 0 < s["latency_ms"]["robot_step"][stat] < 1000
        assert 0 <= s["teleop"]["robot_tracking_deg"][stat] < 180
        assert 0 <= s["teleop"]["robot_axis_error_deg"][stat] <= 180
    # the arm follows the true pose: half the time within 10° (out-of-reach poses aside)
    assert s["teleop"]["robot_axis_error_deg"]["p50"] < 10
    assert "accuracy" in result.output and "end_to_end" in result.output
    # the latencies come with the machine and how loaded it was while they were taken
    assert set(s["host_load"]) == {"cpu_pressure", "cpu_steal"}
    assert f"while streaming, on {s['machine']}" in result.output
    # the console reconciles the host's frames with the device's log, as the README says
    assert ("reconciled  with the device log: lost on host 0, bad frames delivered 0, "
            "dropped unexplained 0") in result.output

    from exohil.formats.recording_reader import read_recording

    assert len(read_recording(record_path).sensors) == received
    report = check_report(out, result.output, received)
    del report["finished_at"], s["finished_at"]
    assert report == s  # --json and the folder's summary.json are the same summary


@pytest.mark.parametrize("name, output", [
    ("in.mcap", ["--record", "{input}"]),
    # the report replaces every arm_*.png in --out: an input there named so is refused
    ("arm_00001.png", ["--out", "{folder}"]),
])
def test_demo_refuses_to_write_onto_its_input(tmp_path, name, output):
    import shutil

    from exohil.harness.paths import FIXTURES_DIR

    copy = tmp_path / name
    shutil.copyfile(FIXTURES_DIR / "paper_protocol_heldout.mcap", copy)
    before = copy.read_bytes()
    result = CliRunner().invoke(main, ["demo", "--seconds", "1", "--recording", str(copy),
                                       *(a.format(input=copy, folder=tmp_path) for a in output)])
    assert result.exit_code != 0 and "refusing to overwrite it" in result.output
    assert copy.read_bytes() == before


def test_a_report_into_an_earlier_reports_folder_leaves_none_of_its_pictures(tmp_path):
    """A run without a MuJoCo robot draws no arm pictures; an earlier run's arm.gif and
    arm_0000k.png used to stay beside the new summary, as if this run had drawn them. Files
    that are not the report's (other names) stay."""
    out = tmp_path / "report"
    out.mkdir()
    earlier = ["arm.gif", "arm_00000.png", "arm_00003.png"]
    theirs = ["arm_notes.png", "arm_1.png", "arm_00000.png.bak", "notes.txt"]
    for name in earlier + theirs:
        (out / name).write_bytes(b"earlier")
    result = CliRunner().invoke(main, ["demo", "--seconds", "1", "--no-faults", "--sink",
                                       "simulated", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "no arm.gif / arm_*.png" in result.output
    left = {p.name for p in out.iterdir()}
    assert not left & set(earlier), left
    assert set(theirs) <= left
    assert all((out / name).read_bytes() == b"earlier" for name in theirs)
    listed = (out / "summary.md").read_text()
    assert "arm.gif" not in listed and "arm_0" not in listed


def test_a_report_cut_short_leaves_no_file_of_an_earlier_one(tmp_path, monkeypatch):
    """A report that stopped while drawing (killed, a full disk) left its new run.mcap beside
    the earlier report's summary.json, summary.md and pictures, which then described a run
    that was not the one in the folder."""
    from exohil.harness import demo_report

    def full_disk(result):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(demo_report, "plot_latency", full_disk)
    out = tmp_path / "report"
    out.mkdir()
    earlier = ["summary.json", "summary.md", "latency.png", "hysteresis.png", "arm.gif",
               "arm_00000.png"]
    for name in [*earlier, "notes.txt"]:
        (out / name).write_bytes(b"earlier")
    result = CliRunner().invoke(main, ["demo", "--seconds", "1", "--no-faults", "--sink",
                                       "none", "--out", str(out)])
    assert result.exit_code == 1 and "No space left on device" in result.output, result.output
    left = {p.name for p in out.iterdir()}
    assert not left & set(earlier), left
    assert (out / "notes.txt").read_bytes() == b"earlier"


def test_every_robot_target_keeps_its_statistics_in_the_summary(tmp_path):
    """`--sink` is repeatable; two targets of one class used to share one key of
    teleop.robots, so the summary kept only the last one's statistics."""
    import socket

    receivers = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(2)]
    try:
        for r in receivers:
            r.bind(("127.0.0.1", 0))
        ports = [r.getsockname()[1] for r in receivers]
        summary_path = tmp_path / "s.json"
        result = CliRunner().invoke(main, [
            "demo", "--seconds", "1", "--no-faults", "--sink", f"udp:127.0.0.1:{ports[0]}",
            "--sink", "simulated", "--sink", f"udp:127.0.0.1:{ports[1]}",
            "--json", str(summary_path), "--out", str(tmp_path / "out")])
    finally:
        for r in receivers:
            r.close()
    assert result.exit_code == 0, result.output
    s = json.loads(summary_path.read_text())
    robots = s["teleop"]["robots"]
    assert set(robots) == {"UdpJointTarget[0]", "SimulatedNao", "UdpJointTarget[1]"}
    assert [robots[f"UdpJointTarget[{k}]"]["port"] for k in range(2)] == ports
    for k in range(2):
        assert robots[f"UdpJointTarget[{k}]"]["commands"] == s["frames"]["received"]


def test_a_session_refuses_to_record_onto_its_model(tmp_path):
    import shutil

    from exohil.harness.bench import BenchConfig, EmulatorDevice
    from exohil.harness.paths import FIXTURES_DIR, MODELS_DIR
    from exohil.harness.session import SessionError, run_session

    model = tmp_path / "m.npz"
    shutil.copyfile(MODELS_DIR / "ann.npz", model)
    config = BenchConfig(device=EmulatorDevice(FIXTURES_DIR / "real_motion_abd_flx.mcap"),
                         model=model, record=tmp_path / "link.npz")
    (tmp_path / "link.npz").symlink_to(model)
    with pytest.raises(SessionError, match="refusing to record onto an input"):
        run_session(config, 1.0)


def test_a_session_at_another_frame_rate_than_the_models_says_so(tmp_path):
    """evaluate warned and conform failed on a recording at 100 Hz for a 250 Hz model; the
    demo scored it (13.9° off) without a word."""
    from dataclasses import replace

    from exohil.formats.recording import cut_recording
    from exohil.formats.recording_reader import read_recording
    from exohil.formats.recording_writer import write_recording
    from exohil.harness.paths import FIXTURES_DIR

    rec = cut_recording(read_recording(FIXTURES_DIR / "paper_protocol_heldout.mcap"), 0, 20)
    slow = replace(rec, sensors=replace(rec.sensors, t=rec.sensors.t * 2.5),
                   sensor_rate_hz=100.0)
    path, summary = tmp_path / "hz100.mcap", tmp_path / "s.json"
    write_recording(path, slow)
    result = CliRunner().invoke(main, ["demo", "--recording", str(path), "--seconds", "2",
                                       "--sink", "none", "--no-faults", "--json", str(summary)])
    assert result.exit_code == 0, result.output
    said = "the device's frame rate is 100 Hz, the model's 250 Hz"
    assert f"warning     {said}" in result.output
    assert json.loads(summary.read_text())["sensor_rate_warning"].startswith(said)


def test_a_link_that_corrupts_every_frame_is_told_from_another_sensor_count():
    from exohil.harness.session import _nothing_decoded_hint

    result = CliRunner().invoke(main, ["demo", "--seconds", "1", "--sink", "none",
                                       "--faults", "corrupt:rate=1"])
    assert result.exit_code != 0 and "packets failed their CRC" in result.output
    assert "a link that corrupts what it carries?" in result.output
    assert "sensors?" not in result.output  # it used to ask whether 4 sensors were sent
    assert _nothing_decoded_hint(0, 7, 4) == (" (7 packets had another shape: does the "
                                              "device send 4 sensors?)")
    assert _nothing_decoded_hint(0, 0, 4) == ""


def test_a_session_keeps_what_a_run_stopped_short_left(tmp_path):
    """A killed run leaves NAME.partial for `record recover`; the next run to NAME used to
    write its own .partial over it."""
    left = tmp_path / "session.mcap.partial"
    left.write_bytes(b"a killed run's frames")
    result = CliRunner().invoke(main, ["demo", "--seconds", "1", "--record",
                                       str(tmp_path / "session.mcap")])
    assert result.exit_code != 0
    assert "stopped short" in result.output and "exohil record recover" in result.output
    assert left.read_bytes() == b"a killed run's frames"


def test_demo_rejects_a_missing_model_with_one_line(tmp_path):
    result = CliRunner().invoke(main, ["demo", "--model", str(tmp_path / "nope.npz")])
    assert result.exit_code != 0
    assert "nope.npz" in result.output and "does not exist" in result.output
    assert "Traceback" not in result.output


def test_run_against_a_separately_started_emulator_records_and_reports(tmp_path):
    fixture = FIXTURES_DIR / "paper_protocol_heldout.mcap"
    emulator_tmp = tmp_path / "emulator-tmp"  # where the emulator makes its device link
    emulator_tmp.mkdir()
    proc = subprocess.Popen([str(Path(sys.executable).parent / "exohil"), "emulate",
                             str(fixture), "--duration", "30"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "TMPDIR": str(emulator_tmp)})
    try:
        port = proc.stdout.readline().strip()
        assert port, proc.stderr.read()
        out = tmp_path / "report"
        result = CliRunner().invoke(main, ["run", port, "--duration", "2", "--reference",
                                           str(fixture), "--sink", "mujoco", "--out", str(out)])
        proc.terminate()  # SIGTERM, as a service manager stops it
        assert proc.wait(timeout=30) == 0, proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert Path(port).parent.parent == emulator_tmp
    assert list(emulator_tmp.iterdir()) == []  # the device link and its folder are removed
    assert result.exit_code == 0, result.output
    s = check_report(out, result.output, json.loads((out / "summary.json").read_text())
                     ["frames"]["received"])
    assert s["frames"]["received"] > 250
    assert s["teleop"]["robots"]["MujocoNao"]["commands"] == s["frames"]["received"]
    assert all(np.isfinite(v) for v in s["rmse"].values())


def test_a_run_whose_device_is_lost_exits_3_with_its_report(tmp_path, monkeypatch):
    """An emulator that stops after 6 s of a 30 s run: the run said "the run ended before
    its time" and exited 0, so a script took it for a whole run."""
    from exohil.harness import bench

    monkeypatch.setattr(bench, "DEVICE_TIMEOUT_S", 1.0)
    fixture = FIXTURES_DIR / "paper_protocol_heldout.mcap"
    proc = subprocess.Popen([str(Path(sys.executable).parent / "exohil"), "emulate",
                             str(fixture), "--duration", "6"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        port = proc.stdout.readline().strip()
        assert port, proc.stderr.read()
        summary = tmp_path / "summary.json"
        result = CliRunner().invoke(main, ["run", port, "--duration", "30", "--json",
                                           str(summary)])
        assert proc.wait(timeout=30) == 0, proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert result.exit_code == 3, result.output
    assert "the device was lost before the end (exit status 3)" in result.output
    s = json.loads(summary.read_text())
    assert s["device_lost"] and s["frames"]["received"] > 0
    assert f"device lost {s['device_lost']}: the run ended before its time" in result.output


def test_run_rejects_a_bad_sink_with_one_line(tmp_path):
    result = CliRunner().invoke(main, ["run", "loop://", "--duration", "1", "--sink",
                                       "udp:localhost"])
    assert result.exit_code != 0
    assert "bad robot address 'udp:localhost'" in result.output
    assert "Traceback" not in result.output


def test_a_recording_at_another_rate_is_replayed_at_its_own(tmp_path):
    """Device time is the recording's time: the session's accuracy (truth aligned by device
    time) is the accuracy `evaluate` gives on the frames streamed. Before, a 100 Hz
    recording was replayed at 250 Hz and scored against the wrong poses."""
    sys.path.insert(0, str(Path(__file__).parent))
    from estimator_synth import shoulder_recording

    from exohil.formats.recording_writer import write_recording

    train, rec, part = tmp_path / "train.mcap", tmp_path / "rec.mcap", tmp_path / "part.mcap"
    write_recording(train, shoulder_recording(seconds=20.0, rate=100.0, seed=2))
    write_recording(rec, shoulder_recording(seconds=10.0, rate=100.0, seed=5))
    model = tmp_path / "ann.npz"
    runner = CliRunner()
    for args in (["train", "--model", "ann", str(train), "--out", str(model),
                  "--max-epochs", "5"],
                 ["record", "cut", str(rec), "--stop", "3", "--out", str(part)]):
        result = runner.invoke(main, args)
        assert result.exit_code == 0, result.output
    scored = tmp_path / "scored.json"
    result = runner.invoke(main, ["evaluate", str(model), str(part), "--json", str(scored)])
    assert result.exit_code == 0, result.output
    summary = tmp_path / "summary.json"
    session, out = tmp_path / "session.mcap", tmp_path / "report"
    result = runner.invoke(main, ["demo", "--recording", str(rec), "--model", str(model),
                                  "--seconds", "3", "--no-faults", "--sink", "none",
                                  "--json", str(summary), "--record", str(session),
                                  "--out", str(out)])
    assert result.exit_code == 0, result.output
    s = json.loads(summary.read_text())
    assert 290 <= s["frames"]["received"] <= 301  # 3 s at 100 Hz, not at 250 Hz
    expected = json.loads(scored.read_text())["accuracy"]["accuracy.direction_rmse"]
    assert s["direction_rmse_deg"] == pytest.approx(expected, abs=0.05)
    from exohil.formats.recording_reader import read_recording

    for written in (session, out / "run.mcap"):  # and what it writes says so
        assert read_recording(written).sensor_rate_hz == 100.0


def test_a_demo_that_never_raises_the_arm_reports_the_arm_direction_it_measured(tmp_path):
    """The fixture's first second holds the arm at rest: no frame reaches 20° of elevation,
    so there is no RMSE per angle, but there is a reference and the arm-direction RMSE is
    measured and said; not 'no reference recording'."""
    result = CliRunner().invoke(main, ["demo", "--seconds", "1", "--sink", "none",
                                       "--no-faults", "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    assert "no reference recording" not in result.output
    assert "no frame reached 20° of elevation" in result.output
    assert "arm-direction RMSE" in result.output


def _fixture_part(tmp_path, stop_s: str) -> tuple[Path, int]:
    """The held-out fixture's first ``stop_s`` seconds, cut with `exohil record cut` into
    ``tmp_path``, and its sensor frame count."""
    from exohil.formats.recording_reader import read_recording

    part = tmp_path / "part.mcap"
    result = CliRunner().invoke(main, ["record", "cut", str(FIXTURES_DIR /
                                                            "paper_protocol_heldout.mcap"),
                                       "--stop", stop_s, "--out", str(part)])
    assert result.exit_code == 0, result.output
    return part, len(read_recording(part).sensors)


def test_a_demo_longer_than_its_recording_says_it_streamed_less(tmp_path):
    """`demo --seconds 4` on a 1.5 s recording stopped at its end without a word."""
    runner = CliRunner()
    part, frames = _fixture_part(tmp_path, "1.5")
    summary = tmp_path / "summary.json"
    note = ("note        the recording holds 1.5 s of frames, so the run streamed those, "
            "not the 4 s asked for")
    for seconds, said in (("4", True), ("1.5", False)):
        result = runner.invoke(main, ["demo", "--recording", str(part), "--seconds", seconds,
                                      "--sink", "none", "--no-faults", "--json", str(summary),
                                      "--out", str(tmp_path / "report")])
        assert result.exit_code == 0, result.output
        s = json.loads(summary.read_text())
        # all of it, both times (frames sent while the host attaches are logged not read)
        assert s["frames"]["received"] + s["device_log"].get("not_read", 0) == frames
        assert bool(s["ended_early"]) == said, s["ended_early"]
        assert (note in result.output) == said, result.output


def test_two_outputs_naming_one_file_are_refused_before_any_work(tmp_path):
    """`run --record DIR/run.mcap --out DIR`: the report's run.mcap replaced the frames
    --record had written."""
    out = tmp_path / "report"
    out.mkdir()
    for command in (["run", "loop://", "--duration", "1"], ["demo", "--seconds", "1"]):
        result = CliRunner().invoke(main, [*command, "--record", str(out / "run.mcap"),
                                           "--out", str(out)])
        assert result.exit_code == 2, result.output
        assert (f"--record {out / 'run.mcap'} and --out {out / 'run.mcap'} name the same "
                "file") in result.output
        assert list(out.iterdir()) == []
    result = CliRunner().invoke(main, ["run", "loop://", "--duration", "1", "--record",
                                       str(tmp_path / "a.mcap"), "--json",
                                       str(tmp_path / "." / "a.mcap")])
    assert result.exit_code == 2 and "name the same file" in result.output


def test_a_refused_connection_is_named(tmp_path):
    """`run socket://127.0.0.1:PORT` with nothing listening said only "no frame arrived"."""
    import socket

    with socket.socket() as sock:  # a port nothing listens on once it is closed
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    result = CliRunner().invoke(main, ["run", f"socket://127.0.0.1:{port}", "--duration", "1"])
    assert result.exit_code == 1, result.output
    assert "no frame arrived from the serial device" in result.output
    assert "Connection refused" in result.output


def test_a_run_stopped_with_ctrl_c_writes_a_report_that_says_it_ended_early(tmp_path):
    """A demo or run stopped with Ctrl-C (SIGINT) mid-stream wrote a report whose summary,
    console and summary.md read as those of a whole run: nothing said it ended early."""
    out = tmp_path / "report"
    code, stdout, stderr = interrupt_once_streaming(["demo", "--seconds", "30", "--sink", "none",
                                                     "--no-faults", "--out", str(out)])
    assert code == 0, stderr
    s = json.loads((out / "summary.json").read_text())
    assert 0 < s["frames"]["received"] < 30 * 250
    assert s["ended_early"].startswith("stopped on request (Ctrl-C or SIGTERM)"), s
    assert f"{s['frames']['received']} frames" in s["ended_early"]
    assert f"note        {s['ended_early']}" in stdout
    assert s["ended_early"] in (out / "summary.md").read_text()


def test_summary_md_says_what_summary_json_says_about_the_session():
    """summary.md gave the measurements without the machine they were timed on, the device's
    fault log, a device lost, a run that ended early or the warnings: a reader of it alone
    took a cut-short run on a loaded laptop for a whole one on the bench."""
    from exohil.harness.demo_report import summary_markdown

    s = {"finished_at": "2026-12-03T18:00:00+0000", "target": "t", "model": "m",
         "model_kind": "ennet", "backend": "numpy", "wall_s": 4.8, "measurements": [],
         "frames": {"sent": 10, "received": 9, "dropped": 1, "crc_errors": 0},
         "machine": "Linux; AMD EPYC; 2 cores; python 3.11.7",
         "host_load": {"cpu_pressure": 0.42, "cpu_steal": None},
         "device_log": {"drop": 1, "not_read": 3},
         "device_lost": "the device stopped sending", "ended_early": "stopped on request",
         "training_coverage_warning": "readings outside training", "device_rate_warning": None,
         "sensor_rate_warning": "another rate"}
    md = summary_markdown(s, [])
    for said in ("CPU pressure 42 %, steal unknown while streaming, on Linux; AMD EPYC; 2 "
                 "cores; python 3.11.7", "drop 1, not_read 3",
                 "the device stopped sending", "ended early: stopped on request",
                 "warning: readings outside training", "warning: another rate"):
        assert said in md, said
    assert "None" not in md
    s.update(device_log={}, device_lost=None, ended_early=None, training_coverage_warning=None,
             sensor_rate_warning=None)
    md = summary_markdown(s, [])
    assert "nothing injected or lost" in md
    s.update(frames={**s["frames"], "sent": None}, device_log=None)  # a device without a log
    md = summary_markdown(s, [])
    assert "sent unknown (no device log)" in md and "None" not in md
    assert "ended early" not in md and "warning" not in md and "device lost" not in md


def test_the_report_says_when_it_finished_with_its_time_zone(tmp_path):
    """finished_at was local time without an offset: the same text for runs hours apart on
    machines in other zones."""
    from datetime import datetime

    out = tmp_path / "report"
    result = CliRunner().invoke(main, ["demo", "--seconds", "1", "--sink", "none",
                                       "--no-faults", "--out", str(out)])
    assert result.exit_code == 0, result.output
    finished = json.loads((out / "summary.json").read_text())["finished_at"]
    assert datetime.fromisoformat(finished).utcoffset() is not None, finished
    assert f"# exohil session report ({finished})" in (out / "summary.md").read_text()


def test_the_latency_picture_names_the_machine_it_timed(tmp_path, monkeypatch):
    """latency.png gave milliseconds with no word of the machine that took them; summary.json
    alone named it."""
    from exohil.harness import demo_report

    titles = {}
    save = demo_report._save

    def keep_title(figure, path):
        titles[path.name] = figure.get_suptitle()
        return save(figure, path)

    monkeypatch.setattr(demo_report, "_save", keep_title)
    out = tmp_path / "report"
    result = CliRunner().invoke(main, ["demo", "--seconds", "1", "--sink", "none",
                                       "--no-faults", "--out", str(out)])
    assert result.exit_code == 0, result.output
    machine = json.loads((out / "summary.json").read_text())["machine"]
    assert f"on {machine}" in titles["latency.png"], titles


def test_a_demo_on_a_looped_bench_streams_the_seconds_asked_for(tmp_path):
    """`demo --bench B --seconds 600` with `loop = true` in B streamed the fixture's 246 s
    once and told the user to set `loop = true` under [device]: the demo dropped the bench's
    loop when it filled in the emulator's faults and seed."""
    runner = CliRunner()
    part, frames = _fixture_part(tmp_path, "1")
    bench = tmp_path / "bench.toml"
    bench.write_text(f'[device]\nemulator = "{part.name}"\nloop = true\n')
    summary = tmp_path / "summary.json"
    result = runner.invoke(main, ["demo", "--bench", str(bench), "--seconds", "2.5",
                                  "--sink", "none", "--no-faults", "--json", str(summary)])
    assert result.exit_code == 0, result.output
    s = json.loads(summary.read_text())
    assert s["ended_early"] is None and "the recording holds" not in result.output
    # 2.5 s of frames: the 1 s recording two and a half times (less what the host missed
    # while it attached, logged by the device)
    assert s["frames"]["received"] + s["device_log"].get("not_read", 0) > 2 * frames


def test_a_demo_of_a_recording_on_a_unix_epoch_clock_is_scored(tmp_path):
    """Another lab's recording stamped with Unix time (1.7e9 s): the emulator sends its times
    modulo the wire's 2³² µs, so the host's device times never met the reference's, and the
    report said 'accuracy not measured: no reference recording' though it had one."""
    from exohil.formats.recording import AngleStream, SensorStream
    from exohil.formats.recording_reader import read_recording
    from exohil.formats.recording_writer import write_recording
    from exohil.harness.session import on_host_clock

    part, _ = _fixture_part(tmp_path, "3")
    rec = read_recording(part)
    epoch = 1.7e9
    rec.sensors = SensorStream(rec.sensors.seq, rec.sensors.t + epoch, rec.sensors.values)
    rec.mocap = {j: AngleStream(s.t + epoch, s.names, s.angles) for j, s in rec.mocap.items()}
    rec.segments = []
    late = tmp_path / "epoch.mcap"
    write_recording(late, rec)
    moved = on_host_clock(read_recording(late))
    wire_t0 = round(rec.sensors.t[0] * 1e6) % 2**32 / 1e6
    assert abs(moved.sensors.t[0] - wire_t0) < 1e-6
    assert abs(moved.mocap["shoulder"].t[0] - moved.sensors.t[0]) < 0.01
    result = CliRunner().invoke(main, ["demo", "--recording", str(late), "--seconds", "1",
                                       "--sink", "none", "--no-faults",
                                       "--out", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    assert "no reference recording" not in result.output
    assert "arm-direction RMSE" in result.output


def test_a_demo_of_a_recording_in_volts_names_the_file(tmp_path):
    """Another lab's recording in V: the demo refused it with 'sensor values are in 'V'; the
    wire protocol carries mm', naming no file (the model, or the recording?)."""
    from exohil.formats.recording_reader import read_recording
    from exohil.formats.recording_writer import write_recording

    part, _ = _fixture_part(tmp_path, "2")
    rec = read_recording(part)
    rec.sensors.values *= 0.01
    rec.sensor_units = "V"
    volts = tmp_path / "volts.mcap"
    write_recording(volts, rec)
    result = CliRunner().invoke(main, ["demo", "--recording", str(volts), "--seconds", "1",
                                       "--sink", "none", "--no-faults",
                                       "--out", str(tmp_path / "out")])
    assert result.exit_code == 1
    errors = [line for line in result.output.splitlines() if line.startswith("Error")]
    assert errors == [f"Error: {volts}: sensor values are in 'V'; wire protocol v1 carries "
                      "mm, and the emulator streams the recording over it"], result.output


def test_a_signal_this_process_ignores_stays_ignored_while_a_run_waits_for_one():
    """SIGTERM stops a demo or run; a SIGINT that the process was started ignoring (a
    script's `exohil run ... &`) does not (until 2026-12-07 the run took it as Ctrl-C)."""
    with sigint_handled_by(signal.SIG_IGN):
        with cmd_run.stop_on_signals() as stop:
            assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
            os.kill(os.getpid(), signal.SIGINT)
            assert not stop.wait(0.2)
            os.kill(os.getpid(), signal.SIGTERM)
            assert stop.wait(2.0)
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
