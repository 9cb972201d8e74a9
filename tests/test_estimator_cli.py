"""exohil train / evaluate / table: happy path and one-line errors for bad inputs."""

import json

import pytest
from click.testing import CliRunner
from estimator_synth import shoulder_recording

from exohil.estimator.checkpoint import load_checkpoint, save_checkpoint
from exohil.formats.recording import cut_recording
from exohil.formats.recording_writer import write_recording
from exohil.harness.cli import main


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("rec")
    good, five = d / "good.mcap", d / "five.mcap"
    write_recording(good, shoulder_recording(seconds=3.0, seed=2))
    write_recording(five, shoulder_recording(seconds=1.0, n_sensors=5))
    ckpt = d / "ann.npz"
    result = CliRunner().invoke(main, ["train", "--model", "ann", str(good), "--out", str(ckpt),
                                       "--max-epochs", "2", "--test-fraction", "0.3"])
    assert result.exit_code == 0, result.output
    return {"good": good, "five": five, "ckpt": ckpt, "dir": d}


def _one_line_error(result):
    assert result.exit_code != 0
    assert "Traceback" not in result.output
    lines = [line for line in result.output.strip().splitlines() if line.strip()]
    assert len(lines) == 1, result.output
    assert lines[0].startswith("Error:")
    return lines[0]


def test_evaluate_writes_the_documented_json(files):
    out = files["dir"] / "m.json"
    result = CliRunner().invoke(main, ["evaluate", str(files["ckpt"]), str(files["good"]),
                                       "--json", str(out), "--test-fraction", "0.3"])
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    for stat in ("rmse", "mae", "max"):
        assert set(data[stat]) == {"elv_angle", "shoulder_elv"}
        assert all(v >= 0 for v in data[stat].values())
    assert set(data["per_segment"]) == {"abduction", "flexion"}  # the end of each movement
    assert data["model"] == "ann"


def test_missing_checkpoint(files):
    line = _one_line_error(CliRunner().invoke(
        main, ["evaluate", str(files["dir"] / "none.npz"), str(files["good"])]))
    assert "none.npz" in line and "does not exist" in line


def test_corrupt_checkpoint(files):
    bad = files["dir"] / "bad.npz"
    bad.write_bytes(b"\x00" * 100)
    _one_line_error(CliRunner().invoke(main, ["evaluate", str(bad), str(files["good"])]))


def test_recording_with_the_wrong_sensor_count(files):
    line = _one_line_error(CliRunner().invoke(
        main, ["evaluate", str(files["ckpt"]), str(files["five"])]))
    assert "expects 4 sensors" in line


def test_a_file_that_is_not_a_recording(files):
    junk = files["dir"] / "junk.mcap"
    junk.write_text("hello")
    _one_line_error(CliRunner().invoke(main, ["evaluate", str(files["ckpt"]), str(junk)]))
    _one_line_error(CliRunner().invoke(main, ["train", str(junk), "--out",
                                              str(files["dir"] / "x.npz")]))


def test_a_sensor_that_never_changes_is_warned_of(files):
    """Training on a stuck channel (or on nothing but stuck channels) said nothing."""
    from dataclasses import replace

    from exohil.formats.recording_reader import read_recording

    rec = read_recording(files["good"])
    for stuck, said in (([1], "SF reads one value over every training frame"),
                        ([0, 1, 2, 3], "every sensor reads one value over every training")):
        values = rec.sensors.values.copy()
        values[:, stuck] = 550.0
        path = files["dir"] / "stuck.mcap"
        write_recording(path, replace(rec, sensors=replace(rec.sensors, values=values)))
        result = CliRunner().invoke(main, ["train", "--model", "classical", str(path), "--out",
                                           str(files["dir"] / "stuck.npz")])
        assert result.exit_code == 0, result.output
        assert f"warning: {said}" in result.output


def test_a_plane_of_elevation_without_the_elevation_is_warned_of(files):
    """--angles elv_angle alone trains and scores θ where the arm hangs, without a word."""
    said = "elv_angle without shoulder_elv: the plane of elevation is undefined"
    for angles, warned in (("elv_angle", True), ("shoulder_elv", False),
                           ("elv_angle,shoulder_elv", False)):
        result = CliRunner().invoke(main, ["train", "--model", "classical", str(files["good"]),
                                           "--angles", angles, "--out",
                                           str(files["dir"] / "theta.npz")])
        assert result.exit_code == 0, result.output
        assert (said in result.output) is warned, result.output


@pytest.mark.parametrize(("kind", "args", "said"), [
    ("classical", ["--window", "5", "--hidden", "3"], "--hidden, --window have no effect on "
                                                      "the classical model"),
    ("ann", ["--hidden", "3", "--max-epochs", "1"], "--hidden has no effect on the ann model"),
])
def test_options_a_model_does_not_read_are_warned_of(files, kind, args, said):
    """`train --model classical --window 5 --hidden 3` was accepted without a word."""
    result = CliRunner().invoke(main, ["train", "--model", kind, *args, str(files["good"]),
                                       "--out", str(files["dir"] / "unread.npz")])
    assert result.exit_code == 0, result.output
    assert f"warning: {said}" in result.output


def test_settings_the_data_cannot_fill_are_warned_of(files):
    out = files["dir"] / "wide.npz"
    plain = CliRunner().invoke(main, ["train", "--model", "ann", str(files["good"]), "--out",
                                      str(out), "--max-epochs", "1"])
    assert plain.exit_code == 0 and "warning" not in plain.output, plain.output
    result = CliRunner().invoke(main, ["train", "--model", "ennet", str(files["good"]), "--out",
                                       str(out), "--max-epochs", "1", "--window", "200",
                                       "--dilation", "10", "--offset-frames", "5000"])
    assert result.exit_code == 0, result.output
    warnings = [line for line in result.output.splitlines() if line.startswith("warning:")]
    assert len(warnings) == 2, result.output
    assert "window spans 1991 frames (7.96 s), more than the longest training piece" in \
        warnings[0]
    assert "--offset-frames 5000 is more than the 750 sensor frames" in warnings[1]
    table = CliRunner().invoke(main, ["table", "--train", str(files["good"]), "--models",
                                      "classical,ann,ennet", "--max-epochs", "1",
                                      "--window", "200", "--dilation", "10"])
    assert table.exit_code == 0, table.output
    spans = [line for line in table.output.splitlines() if "window spans" in line]
    # the ANN reads the newest frame and the classical model no window: only the ENNet's
    # window is longer than the data (both were named, and the ANN's row said 200×10)
    assert len(spans) == 1 and spans[0].startswith("warning: ennet:"), table.output
    rows = {line.split("|")[1].strip(): line for line in table.output.splitlines()
            if line.startswith("| ")}
    assert "| 200×10 |" in rows["ennet"] and "| 200×10 |" not in rows["ann"]


def test_table_writes_a_markdown_section(files):
    md = files["dir"] / "results.md"
    md.write_text("# Results\n\nhand-written text\n")
    args = ["table", "--train", str(files["good"]), "--models", "classical,ann",
            "--max-epochs", "1", "--out", str(md), "--section", "t1"]
    for _ in range(2):  # a second run replaces the section instead of appending
        result = CliRunner().invoke(main, args)
        assert result.exit_code == 0, result.output
    text = md.read_text()
    assert text.count("<!-- table:t1 -->") == 1
    assert "hand-written text" in text
    assert "| Classical" in text and "| ANN" in text


def test_table_refuses_a_file_whose_section_markers_do_not_pair_up(files):
    """A stray opening marker: the first run appended a second section, the second replaced
    everything from the stray marker to the new end, the text in between with it."""
    md = files["dir"] / "stray.md"
    before = "# R\n\n<!-- table:s1 -->\nold\n\n## After\n\nkeep me after\n"
    md.write_text(before)
    args = ["table", "--train", str(files["good"]), "--models", "classical", "--out", str(md),
            "--section", "s1"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 1, result.output
    assert "the markers of section 's1' do not make one section" in result.output
    assert "| Classical" not in result.output  # refused before the training
    assert md.read_text() == before
    md.write_text("<!-- /table:s1 -->\nmine\n<!-- table:s1 -->\n")  # out of order
    assert CliRunner().invoke(main, args).exit_code == 1
    md.write_text("a\n<!-- table:s1 -->\nOLD TABLE\n<!-- /table:s1 -->\n"
                  "keep <!-- /table:s1x --> b\n")
    result = CliRunner().invoke(main, args)  # one section: replaced, the rest kept
    assert result.exit_code == 0, result.output
    text = md.read_text()
    assert text.startswith("a\n<!-- table:s1 -->\n") and "OLD TABLE" not in text
    assert text.endswith("<!-- /table:s1 -->\nkeep <!-- /table:s1x --> b\n")


def test_table_tells_test_frames_outside_the_training_readings(files):
    """Across recordings, a test suit whose readings lie 40 mm off the training suit's: the
    table says so in its column, in a note under it and in a warning line; the training
    recording's own end, as test part, lies inside."""
    other = files["dir"] / "other_suit.mcap"
    write_recording(other, shoulder_recording(seconds=2.0, seed=3, offset_mm=40.0))
    md, data = files["dir"] / "coverage.md", files["dir"] / "coverage.json"
    result = CliRunner().invoke(
        main, ["table", "--train", str(files["good"]), "--test", str(other), "--models",
               "classical", "--out", str(md), "--json", str(data)])
    assert result.exit_code == 0, result.output
    assert "warning: classical: 100.0% of" in result.stderr
    coverage = json.loads(data.read_text())["classical"]["test"]["training_coverage"]
    assert coverage["outside_percent"] == 100.0
    text = md.read_text()
    assert "test frames outside training (%)" in text
    assert "| classical | " in text and " | 100.00 | " in text
    assert "**classical: 1 % or more of the test frames lie outside" in text

    trained_on = files["dir"] / "trained_on.mcap"  # the first 40 % of its first movement
    write_recording(trained_on, cut_recording(shoulder_recording(seconds=3.0, seed=2), 0, 0.6))
    inside = CliRunner().invoke(
        main, ["table", "--train", str(files["good"]), "--test", str(trained_on), "--models",
               "classical"])
    assert inside.exit_code == 0, inside.output
    assert "warning" not in inside.stderr
    assert "lie outside" not in inside.stdout


def test_table_refuses_a_test_recording_that_shares_frames_with_a_training_one(files):
    """`table --train part --test whole`, part cut from whole, scored a model on its own
    training frames; a part of other times is a test recording like any other."""
    whole = files["dir"] / "whole_session.mcap"
    write_recording(whole, shoulder_recording(seconds=6.0, seed=4))
    parts = {}
    for name, span in (("early", ["--stop", "3"]), ("late", ["--start", "3"])):
        parts[name] = files["dir"] / f"{name}_part.mcap"
        cut = CliRunner().invoke(main, ["record", "cut", str(whole), *span, "--out",
                                        str(parts[name])])
        assert cut.exit_code == 0, cut.output
    for test in (whole, parts["late"]):
        result = CliRunner().invoke(main, ["table", "--train", str(parts["early"]), "--test",
                                           str(test), "--models", "classical"])
        if test == whole:
            assert result.exit_code == 2, result.output
            assert ("--test whole_session.mcap: the training recording early_part.mcap was "
                    "cut from whole_session.mcap: a model would be scored on frames it was "
                    "trained on") in " ".join(result.output.split())
        else:
            assert result.exit_code == 0, result.output


def test_table_rejects_unknown_models(files):
    line = _one_line_error(CliRunner().invoke(
        main, ["table", "--train", str(files["good"]), "--models", "ennet,gpt"]))
    assert "gpt" in line


def test_evaluate_min_angle_filter(files):
    out = files["dir"] / "m_min.json"
    result = CliRunner().invoke(main, ["evaluate", str(files["ckpt"]), str(files["good"]),
                                       "--min", "shoulder_elv=60", "--json", str(out)])
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    assert data["min_angle"] == {"shoulder_elv": 60.0}
    everything = CliRunner().invoke(main, ["evaluate", str(files["ckpt"]), str(files["good"])])
    assert everything.exit_code == 0
    assert 0 < data["frames"] < 750  # 3 s at 250 Hz, and φ spans 15..85° in the fixture
    line = _one_line_error(CliRunner().invoke(
        main, ["evaluate", str(files["ckpt"]), str(files["good"]), "--min", "phi>3"]))
    assert "ANGLE=DEG" in line


def test_evaluate_warns_when_the_recording_runs_at_another_rate(files):
    slow = files["dir"] / "slow.mcap"
    write_recording(slow, shoulder_recording(seconds=3.0, rate=100.0, seed=2))
    result = CliRunner().invoke(main, ["evaluate", str(files["ckpt"]), str(slow)])
    assert result.exit_code == 0, result.output
    assert result.output.startswith("warning: the recordings' sensor rate is 100 Hz, the "
                                    "model's 250 Hz: its window would span another time; "
                                    "train a model at this rate (calibration cannot change "
                                    "a model's rate)")
    calibrated = CliRunner().invoke(main, ["calibrate", str(files["ckpt"]), str(slow), "--out",
                                           str(files["dir"] / "cal.npz")])
    assert calibrated.exit_code == 1 and "calibration cannot change a model's rate" in \
        calibrated.output
    same = CliRunner().invoke(main, ["evaluate", str(files["ckpt"]), str(files["good"])])
    assert same.exit_code == 0 and "sensor rate" not in same.output


def test_evaluate_warns_when_it_scores_frames_the_model_was_trained_on(files):
    def warned(*extra):
        result = CliRunner().invoke(main, ["evaluate", str(files["ckpt"]), str(files["good"]),
                                           *extra])
        assert result.exit_code == 0, result.output
        return "frames it was trained or validated on, not a test" in result.output

    # the model was trained with --test-fraction 0.3: only that held-out end is a test
    assert warned() and warned("--test-fraction", "0.5")
    assert not warned("--test-fraction", "0.3") and not warned("--test-fraction", "0.1")
    other = files["dir"] / "other.mcap"
    write_recording(other, shoulder_recording(seconds=3.0, seed=5))
    result = CliRunner().invoke(main, ["evaluate", str(files["ckpt"]), str(other)])
    assert result.exit_code == 0 and "trained or validated on" not in result.output
    whole = files["dir"] / "whole.npz"  # trained on every frame: nothing of it is a test
    assert CliRunner().invoke(main, ["train", "--model", "ann", str(files["good"]), "--out",
                                     str(whole), "--max-epochs", "1"]).exit_code == 0
    result = CliRunner().invoke(main, ["evaluate", str(whole), str(files["good"]),
                                       "--test-fraction", "0.3"])
    assert result.exit_code == 0 and "good.mcap was used to train the model" in result.output
    assert "figures include frames it was trained" in result.output
    calibrated = files["dir"] / "calibrated.npz"  # keeps what its base model held out
    write_recording(other, shoulder_recording(seconds=6.0, seed=5))  # calibration needs 5 s
    assert CliRunner().invoke(main, ["calibrate", str(files["ckpt"]), str(other), "--steps",
                                     "2", "--jitter", "0.1", "--out",
                                     str(calibrated)]).exit_code == 0
    result = CliRunner().invoke(main, ["evaluate", str(calibrated), str(files["good"]),
                                       "--test-fraction", "0.3"])
    assert result.exit_code == 0 and "trained or validated on" not in result.output
    unknown = files["dir"] / "unknown.npz"  # made before checkpoints kept the fraction
    est = load_checkpoint(files["ckpt"])
    del est.info["test_fraction"]
    save_checkpoint(unknown, est)
    for extra, said in (((), "figures include frames"), (("--test-fraction", "0.3"),
                                                          "figures may include frames")):
        result = CliRunner().invoke(main, ["evaluate", str(unknown), str(files["good"]),
                                           *extra])
        assert result.exit_code == 0 and said in result.output, result.output


def test_training_on_recordings_at_two_rates_is_one_clear_error(files):
    slow = files["dir"] / "slow2.mcap"
    write_recording(slow, shoulder_recording(seconds=3.0, rate=100.0, seed=3))
    line = _one_line_error(CliRunner().invoke(
        main, ["train", "--model", "ann", str(files["good"]), str(slow),
               "--out", str(files["dir"] / "mixed.npz"), "--max-epochs", "1"]))
    assert "sensors at 100 Hz" in line and "at 250 Hz" in line
    assert not (files["dir"] / "mixed.npz").exists()
    # table --test at another rate than --train trained and scored every model silently
    line = _one_line_error(CliRunner().invoke(
        main, ["table", "--train", str(files["good"]), "--test", str(slow), "--models", "ann",
               "--max-epochs", "1"]))
    assert "--test recordings at 100 Hz, --train recordings at 250 Hz" in line


def test_a_recording_without_the_models_joint_is_named_in_the_error(files):
    rec = shoulder_recording(seconds=1.0)
    rec.mocap = {"knee": rec.mocap["shoulder"]}
    knee = files["dir"] / "knee.mcap"
    write_recording(knee, rec)
    line = _one_line_error(CliRunner().invoke(main, ["evaluate", str(files["ckpt"]), str(knee)]))
    assert str(knee) in line and "joint 'shoulder' not in recording" in line


@pytest.mark.parametrize("command", ["train", "evaluate", "calibrate"])
def test_a_recording_without_motion_capture_says_so(files, command):
    """It said "joint 'shoulder' not in recording (has [])", or for train "pass --joint",
    which no option can help: the recording holds no truth at all."""
    rec = shoulder_recording(seconds=1.0)
    rec.mocap = {}
    bare = files["dir"] / "bare.mcap"
    write_recording(bare, rec)
    out = str(files["dir"] / f"bare-{command}.npz")
    args = {"train": ["train", "--model", "ann", str(bare), "--out", out],
            "evaluate": ["evaluate", str(files["ckpt"]), str(bare)],
            "calibrate": ["calibrate", str(files["ckpt"]), str(bare), "--out", out]}[command]
    line = _one_line_error(CliRunner().invoke(main, args))
    assert str(bare) in line and "has no motion capture" in line


def test_accuracy_on_no_frame_at_20_degrees_is_not_measured_and_null(files):
    rec = shoulder_recording(seconds=1.0)
    rec.mocap["shoulder"].angles[:, 1] = 10.0  # the arm never reaches 20° of elevation
    low, out = files["dir"] / "low.mcap", files["dir"] / "low.json"
    write_recording(low, rec)
    result = CliRunner().invoke(main, ["evaluate", str(files["ckpt"]), str(low), "--json",
                                       str(out)])
    assert result.exit_code == 0, result.output
    assert "elv_angle not measured" in result.output and "nan" not in result.output
    assert json.loads(out.read_text())["accuracy"]["accuracy.rmse.elv_angle"] is None
    longer = shoulder_recording(seconds=4.0)
    longer.mocap["shoulder"].angles[:, 1] = 10.0
    write_recording(low, longer)
    table = CliRunner().invoke(main, ["table", "--train", str(low), "--models", "classical"])
    assert table.exit_code == 0, table.output
    assert "nan" not in table.output and "| — | — |" in table.output
    assert "—: not measured (no test frame reached 20° of elevation)." in table.output


def test_training_progress_names_the_model_as_the_command_line_does(files, monkeypatch):
    """`--model ennet-stateful` reported its epochs as [ennet], and the first line of a run
    showed 'best val inf' before any epoch was validated."""
    from exohil.estimator import training

    assert "best val —" in training._status("ennet", 1, 0.1, float("inf"), 1.0, 10.0)
    lines: list[str] = []
    monkeypatch.setattr(training, "progress_printer", lambda: lines.append)
    result = CliRunner().invoke(main, ["train", "--model", "ennet-stateful", str(files["good"]),
                                       "--out", str(files["dir"] / "st.npz"),
                                       "--max-epochs", "1"])
    assert result.exit_code == 0, result.output
    assert lines and all(line.startswith("[ennet-stateful] epoch ") for line in lines), lines


def test_recordings_in_two_sensor_units_are_refused(files):
    """Another lab's recording in volts trained beside one in mm: the model learned both as
    one unit (validation RMSE 24-26° against 2-3° in either alone), with no word; evaluate
    scored such a mix and table tested one on the other alike."""
    volts = files["dir"] / "volts.mcap"
    rec = shoulder_recording(seconds=3.0, seed=3)
    rec.sensors.values *= 0.01
    rec.sensor_units = "V"
    write_recording(volts, rec)
    out = files["dir"] / "mixed.npz"
    line = _one_line_error(CliRunner().invoke(main, ["train", "--model", "ann", str(files["good"]),
                                                     str(volts), "--out", str(out),
                                                     "--max-epochs", "1"]))
    assert line == (f"Error: {volts}: sensors in V, {files['good']} in mm: one model cannot "
                    "read both; convert them to one unit")
    assert not out.exists()
    line = _one_line_error(CliRunner().invoke(main, ["evaluate", str(files["ckpt"]),
                                                     str(files["good"]), str(volts)]))
    assert "sensors in V" in line
    line = _one_line_error(CliRunner().invoke(main, ["table", "--train", str(files["good"]),
                                                     "--test", str(volts), "--models",
                                                     "classical", "--max-epochs", "1"]))
    assert line == ("Error: --test recordings in V, --train recordings in mm: each model "
                    "would read the test in another unit; convert them to one unit")


def test_a_model_refuses_readings_in_another_unit_than_it_was_trained_on(files):
    """A checkpoint did not record its readings' unit: an mm model evaluated on another lab's
    recording in volts drew only the "outside the training readings" warning and scored 138°
    (the same motion in mm: a few degrees). The unit is now in info.sensor_units, checked
    wherever a checkpoint meets a recording (evaluate, calibrate, run, demo)."""
    from exohil.estimator.checkpoint import load_checkpoint

    assert load_checkpoint(files["ckpt"]).info["sensor_units"] == "mm"
    volts = files["dir"] / "volts-only.mcap"
    rec = shoulder_recording(seconds=3.0, seed=4)
    rec.sensors.values *= 0.01
    rec.sensor_units = "V"
    write_recording(volts, rec)
    for command in (["evaluate", str(files["ckpt"]), str(volts)],
                    ["calibrate", str(files["ckpt"]), str(volts), "--out",
                     str(files["dir"] / "cal-v.npz")]):
        line = _one_line_error(CliRunner().invoke(main, command))
        assert line == (f"Error: checkpoint was trained on sensor readings in mm, {volts} has "
                        "them in V: it would read them as mm (train a model on recordings in "
                        "V)"), command
    assert not (files["dir"] / "cal-v.npz").exists()
    # a model trained in volts records volts and reads them
    v_model = files["dir"] / "ann-v.npz"
    result = CliRunner().invoke(main, ["train", "--model", "ann", str(volts), "--out",
                                       str(v_model), "--max-epochs", "1"])
    assert result.exit_code == 0, result.output
    assert load_checkpoint(v_model).info["sensor_units"] == "V"
    assert CliRunner().invoke(main, ["evaluate", str(v_model), str(volts)]).exit_code == 0
    # ...but not from a device: the wire carries mm
    result = CliRunner().invoke(main, ["run", "loop://", "--model", str(v_model),
                                       "--duration", "1", "--sink", "none"])
    assert result.exit_code == 1, result.output
    assert result.output.strip().splitlines()[-1] == (
        f"Error: {v_model}: the model's sensor values are in 'V'; wire protocol v1 carries mm, "
        "and a device streams over it (train a model on recordings in mm)")


def test_train_warns_when_the_timestamps_disagree_with_the_nominal_rate(files):
    """Another lab's recording says sensor_rate_hz=250 while its frames come at 100 Hz:
    `record info` noted it, but train set the window up for 250 Hz without a word."""
    wrong = files["dir"] / "wrong_rate.mcap"
    rec = shoulder_recording(seconds=3.0, rate=100.0, seed=2)
    rec.sensor_rate_hz = 250.0
    write_recording(wrong, rec)
    result = CliRunner().invoke(main, ["train", "--model", "ann", str(wrong), "--out",
                                       str(files["dir"] / "wrong.npz"), "--max-epochs", "1"])
    assert result.exit_code == 0, result.output
    assert (f"{wrong}: metadata sensor_rate_hz=250 but its timestamps give 100 Hz; the model "
            "is set up for 250 Hz, so its window spans another time (are the times in "
            "seconds?)") in result.output
    good = CliRunner().invoke(main, ["train", "--model", "ann", str(files["good"]), "--out",
                                     str(files["dir"] / "good2.npz"), "--max-epochs", "1"])
    assert good.exit_code == 0 and "timestamps give" not in good.output
