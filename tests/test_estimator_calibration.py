"""exohil calibrate: a trained network adapted to another wearer's data, its provenance, its
refusals, and the calibrated checkpoint in evaluate and the conformance suite."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest
from click.testing import CliRunner
from estimator_synth import shoulder_recording

from exohil.estimator.calibration import (
    JITTER_CANDIDATES,
    METHOD,
    CalibrationConfig,
    CalibrationError,
    calibrate,
)
from exohil.estimator.checkpoint import load_checkpoint
from exohil.estimator.coverage import block_coverage
from exohil.estimator.dataset import DatasetError, TargetSpec, recording_blocks
from exohil.estimator.splits import Split, cut_at_segments
from exohil.estimator.training import TrainConfig, train
from exohil.formats.digest import sha256_file
from exohil.formats.recording import cut_recording
from exohil.formats.recording_writer import write_recording
from exohil.harness.cli import main
from exohil.harness.paths import FIXTURES_DIR, MODELS_DIR

TARGET = TargetSpec("shoulder", ("elv_angle", "shoulder_elv"))
SENSORS = ("F", "SF", "SR", "R")
FAST = CalibrationConfig(steps=150, jitter=0.1)


def blocks(rec):
    return recording_blocks(rec, TARGET)


def wearer_b(seconds: float, seed: int):
    """Another wearer: the same suit, its sensors read 6 mm longer (a new donning)."""
    return shoulder_recording(seconds=seconds, seed=seed, offset_mm=6.0)


@pytest.fixture(scope="module")
def base():
    train_part = [*blocks(shoulder_recording(seconds=30.0, seed=1)),
                  *blocks(shoulder_recording(seconds=30.0, seed=3))]
    val_part = blocks(shoulder_recording(seconds=6.0, seed=2))
    cfg = TrainConfig(kind="ennet", window=6, dilation=4, hidden=16, dense=(32,),
                      max_epochs=40, time_budget_s=120.0)
    return train(Split(train_part, val_part, [], "test"), SENSORS, TARGET, cfg)


def rmse(est, part) -> float:
    err = np.concatenate(est.predict(part)) - np.concatenate([b.y for b in part])
    return float(np.sqrt(np.mean(err**2)))


def test_calibration_brings_the_error_on_another_wearer_down(base):
    test_part = blocks(wearer_b(20.0, seed=7))
    before = rmse(base, test_part)
    assert before > 2 * rmse(base, blocks(shoulder_recording(seconds=20.0, seed=7)))
    weights = base.weights()
    est = calibrate(base, blocks(wearer_b(15.0, seed=5)), FAST)
    assert rmse(est, test_part) < 0.5 * before
    assert all(np.array_equal(weights[k], v) for k, v in base.weights().items())


def test_calibrated_info_names_what_it_came_from(base):
    source = [{"file": "cal.mcap", "sha256": "ab" * 32}]
    part = blocks(wearer_b(8.0, seed=5))
    est = calibrate(base, part, FAST, base_source={"file": "base.npz", "sha256": "cd" * 32},
                    sources=source)
    cal = est.info["calibration"]
    assert cal["method"] == METHOD
    assert cal["base_checkpoint"] == {"file": "base.npz", "sha256": "cd" * 32}
    assert cal["recordings"] == source
    frames = sum(len(b) for b in part)  # frames with ground truth
    assert 1990 <= frames <= 2000 and cal["frames"] == frames
    assert cal["seconds"] == round(frames / 250.0, 2)
    assert cal["config"]["steps"] == 150
    assert cal["accuracy_after"]["accuracy.direction_rmse"] < \
        cal["accuracy_before"]["accuracy.direction_rmse"]
    assert est.info["sources"][-1] == {**source[0], "role": "calibration"}
    assert est.info["base_info"] == base.info
    x = np.concatenate([b.x for b in part])  # where its readings lie joins the coverage
    assert cal["input_mean"] == pytest.approx(x.mean(axis=0).tolist())
    assert cal["input_std"] == pytest.approx(x.std(axis=0).tolist())
    assert block_coverage(est, part).outside == 0
    # the base model's reading unit goes on (the calibration recordings were checked
    # against it); a base that does not record one gives a model that does not either
    assert "sensor_units" not in base.info and "sensor_units" not in est.info
    in_mm = copy.copy(base)
    in_mm.info = {**base.info, "sensor_units": "mm"}
    assert calibrate(in_mm, part, FAST).info["sensor_units"] == "mm"


def test_the_jitter_is_the_largest_within_one_standard_error_of_the_best(base):
    part = cut_at_segments(blocks(wearer_b(12.0, seed=5)))  # as exohil calibrate cuts them
    est = calibrate(base, part, CalibrationConfig(steps=50))
    cal = est.info["calibration"]
    scores = {float(j): s for j, s in cal["jitter_selection"].items()}
    assert sorted(scores) == sorted(JITTER_CANDIDATES)
    best = min(scores.values(), key=lambda s: s["mse"])
    within = [j for j, s in scores.items() if s["mse"] <= best["mse"] + best["se"]]
    assert cal["jitter"] == max(within)
    assert all(s["se"] > 0 for s in scores.values())  # two segments: two held-out blocks
    given = calibrate(base, blocks(wearer_b(6.0, seed=5)), CalibrationConfig(steps=5, jitter=0))
    assert given.info["calibration"]["jitter"] == 0 and not \
        given.info["calibration"]["jitter_selection"]


def test_calibration_is_reproducible_for_a_seed(base):
    part = blocks(wearer_b(6.0, seed=5))
    a = calibrate(base, part, CalibrationConfig(steps=20, jitter=0.1, seed=3)).weights()
    b = calibrate(base, part, CalibrationConfig(steps=20, jitter=0.1, seed=3)).weights()
    c = calibrate(base, part, CalibrationConfig(steps=20, jitter=0.1, seed=4)).weights()
    assert all(np.array_equal(a[k], b[k]) for k in a)
    assert not all(np.array_equal(a[k], c[k]) for k in a)


def test_too_little_data_and_models_without_a_window_are_refused(base):
    with pytest.raises(DatasetError, match="too little calibration data"):
        calibrate(base, blocks(wearer_b(3.0, seed=5)), FAST)
    part = blocks(shoulder_recording(seconds=8.0, seed=1))
    split = Split(part, [], [], "test")
    classical = train(split, SENSORS, TARGET, TrainConfig(kind="classical"))
    with pytest.raises(CalibrationError, match="no network"):
        calibrate(classical, part, FAST)
    stateful = train(split, SENSORS, TARGET, TrainConfig(kind="ennet", stateful=True, hidden=8,
                                                         dense=(8,), max_epochs=1))
    with pytest.raises(CalibrationError, match="stateful"):
        calibrate(stateful, part, FAST)


# ------------------------------------------------------------------------------------- CLI

def invoke(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def test_calibrate_then_evaluate_from_the_command_line(tmp_path, base):
    from exohil.estimator.checkpoint import save_checkpoint

    ckpt, cal, test = tmp_path / "base.npz", tmp_path / "cal.mcap", tmp_path / "test.mcap"
    save_checkpoint(ckpt, base)
    write_recording(cal, wearer_b(12.0, seed=5))
    write_recording(test, wearer_b(10.0, seed=8))
    out = tmp_path / "calibrated.npz"
    result = invoke("calibrate", ckpt, cal, "--out", out, "--steps", "150")
    assert result.exit_code == 0, result.output
    assert "calibrated on 11.99 s from 1 recording(s)" in result.output
    assert "12.0 s of calibration frames" in result.output  # under the 30 s advised
    assert "30 s or more is advised" in result.output
    assert "one pose" not in result.output
    est = load_checkpoint(out)
    assert est.info["calibration"]["base_checkpoint"] == {"file": "base.npz",
                                                          "sha256": sha256_file(ckpt)}
    # with what each was cut from (nothing here) and its span, for the heldout check
    assert [{k: r[k] for k in ("file", "sha256", "cut_from")}
            for r in est.info["calibration"]["recordings"]] == [
        {"file": "cal.mcap", "sha256": sha256_file(cal), "cut_from": []}]
    assert est.info["command"].startswith("exohil ")  # sys.argv: pytest's under CliRunner
    scores = {}
    for name in (ckpt, out):
        result = invoke("evaluate", name, test, "--json", tmp_path / f"{name.stem}.json")
        assert result.exit_code == 0, result.output
        scores[name] = json.loads((tmp_path / f"{name.stem}.json").read_text())
    direction = {k: v["accuracy"]["accuracy.direction_rmse"] for k, v in scores.items()}
    assert direction[out] < 0.5 * direction[ckpt]


def test_evaluate_refuses_a_calibrated_model_its_calibration_frames(tmp_path, base):
    """Every frame of a calibration recording trained the calibrated model: evaluate refuses
    it, and a part cut from it, whatever --test-fraction; the base model still takes it."""
    from exohil.estimator.checkpoint import save_checkpoint

    ckpt, cal, part = tmp_path / "base.npz", tmp_path / "cal.mcap", tmp_path / "part.mcap"
    save_checkpoint(ckpt, base)
    write_recording(cal, wearer_b(8.0, seed=5))
    assert invoke("record", "cut", cal, "--start", "4", "--out", part).exit_code == 0
    out = tmp_path / "calibrated.npz"
    result = invoke("calibrate", ckpt, cal, "--out", out, "--steps", "5", "--jitter", "0.1")
    assert result.exit_code == 0, result.output
    for scored, extra in ((cal, ()), (part, ()), (cal, ("--test-fraction", "0.3"))):
        result = invoke("evaluate", out, scored, *extra)
        assert result.exit_code == 2, result.output
        assert f"RECORDING {scored.name}: " in result.output
        assert "scored on frames it was trained on" in result.output
        assert "accuracy:" not in result.output
    assert invoke("evaluate", ckpt, cal).exit_code == 0


def test_evaluate_scores_the_recording_a_calibration_was_cut_from_only_after_it(tmp_path,
                                                                                 base):
    """Calibrated on the first 6 s of a 20 s recording (two 10 s segments): the whole is
    refused, and so is --test-fraction 0.5 (its tails 5–10 s and 15–20 s meet the first 6 s);
    --test-fraction 0.3 (7–10 s and 17–20 s) is scored (results.md, the knee's commands)."""
    from exohil.estimator.checkpoint import save_checkpoint

    ckpt, whole, cal = tmp_path / "base.npz", tmp_path / "whole.mcap", tmp_path / "cal.mcap"
    save_checkpoint(ckpt, base)
    write_recording(whole, wearer_b(20.0, seed=5))
    assert invoke("record", "cut", whole, "--stop", "6", "--out", cal).exit_code == 0
    out = tmp_path / "calibrated.npz"
    result = invoke("calibrate", ckpt, cal, "--out", out, "--steps", "5", "--jitter", "0.1")
    assert result.exit_code == 0, result.output
    for extra, refused in (((), True), (("--test-fraction", "0.5"), True),
                           (("--test-fraction", "0.3"), False)):
        result = invoke("evaluate", out, whole, *extra)
        assert result.exit_code == (2 if refused else 0), (extra, result.output)
        assert ("the training recording cal.mcap was cut from whole.mcap, and frames scored "
                "here are among its calibration frames" in result.output) == refused


def test_calibration_frames_of_one_pose_are_warned_of(tmp_path, base):
    from exohil.estimator.checkpoint import save_checkpoint

    ckpt, cal = tmp_path / "base.npz", tmp_path / "still.mcap"
    save_checkpoint(ckpt, base)
    rec = wearer_b(8.0, seed=5)
    for stream in rec.mocap.values():
        stream.angles[:] = stream.angles[0]  # the arm held still the whole time
    write_recording(cal, rec)
    result = invoke("calibrate", ckpt, cal, "--out", tmp_path / "c.npz", "--steps", "2",
                    "--jitter", "0.1")
    assert result.exit_code == 0, result.output
    assert "warning: the calibration frames' angles span 0.0° at most: one pose" in \
        result.output


@pytest.mark.parametrize("problem", ["out is input", "rate", "sensors"])
def test_calibrate_bad_input_is_one_line(tmp_path, base, problem):
    from exohil.estimator.checkpoint import save_checkpoint

    ckpt, cal = tmp_path / "base.npz", tmp_path / "cal.mcap"
    save_checkpoint(ckpt, base)
    rec = {"out is input": wearer_b(8.0, seed=5),
           "rate": shoulder_recording(seconds=8.0, rate=100.0),
           "sensors": shoulder_recording(seconds=8.0, n_sensors=5)}[problem]
    write_recording(cal, rec)
    out = ckpt if problem == "out is input" else tmp_path / "out.npz"
    result = invoke("calibrate", ckpt, cal, "--out", out, "--steps", "5")
    assert result.exit_code != 0
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error:"), result.output
    expected = {"out is input": "refusing to overwrite", "rate": "100 Hz, the model's 250 Hz",
                "sensors": "expects 4 sensors"}[problem]
    assert expected in lines[0]
    assert not (tmp_path / "out.npz").exists()


def test_a_copy_of_a_calibration_recording_is_refused(tmp_path, base):
    """The same recording under two names would weigh its frames twice."""
    from exohil.estimator.checkpoint import save_checkpoint

    ckpt, cal, copy = tmp_path / "base.npz", tmp_path / "cal.mcap", tmp_path / "copy.mcap"
    save_checkpoint(ckpt, base)
    write_recording(cal, wearer_b(8.0, seed=5))
    copy.write_bytes(cal.read_bytes())
    result = invoke("calibrate", ckpt, cal, copy, "--out", tmp_path / "out.npz", "--steps", "5")
    assert result.exit_code == 2, result.output
    assert "RECORDING cal.mcap and RECORDING copy.mcap hold the same recording" in result.output
    assert not (tmp_path / "out.npz").exists()


def test_calibrating_again_on_the_same_frames_is_warned_of(tmp_path, base):
    """A calibrated checkpoint calibrated again on its calibration recording, or on a part
    cut from it: the model has fitted those frames already."""
    from exohil.estimator.checkpoint import save_checkpoint

    ckpt, cal, part = tmp_path / "base.npz", tmp_path / "cal.mcap", tmp_path / "part.mcap"
    save_checkpoint(ckpt, base)
    write_recording(cal, wearer_b(8.0, seed=5))
    assert invoke("record", "cut", cal, "--stop", "6", "--out", part).exit_code == 0
    fast = ("--steps", "2", "--jitter", "0.1")
    once = invoke("calibrate", ckpt, cal, "--out", tmp_path / "once.npz", *fast)
    assert once.exit_code == 0, once.output
    assert "frames the model has fitted" not in once.output
    for again, why in ((cal, "cal.mcap was used to train the model (as cal.mcap)"),
                       (part, "part.mcap was cut from the training recording cal.mcap")):
        result = invoke("calibrate", tmp_path / "once.npz", again, "--out",
                        tmp_path / "twice.npz", *fast)
        assert result.exit_code == 0, result.output
        assert f"warning: {why}: it holds frames the model has fitted" in result.output


def test_too_little_data_is_one_line_without_the_one_pose_warning(tmp_path, base):
    """Too short a recording is refused; that it also holds one pose is not worth a line."""
    from exohil.estimator.checkpoint import save_checkpoint

    ckpt, cal = tmp_path / "base.npz", tmp_path / "still.mcap"
    save_checkpoint(ckpt, base)
    rec = wearer_b(3.0, seed=5)
    for stream in rec.mocap.values():
        stream.angles[:] = stream.angles[0]
    write_recording(cal, rec)
    result = invoke("calibrate", ckpt, cal, "--out", tmp_path / "out.npz", "--steps", "5")
    assert result.exit_code != 0
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error: too little calibration data"), \
        result.output


def test_conformance_takes_a_calibrated_model_and_refuses_its_calibration_data(tmp_path):
    """The reference ENNet calibrated on the first 8 s of the held-out fixture: scored on that
    part, the held-out check fails; scored on the rest, it passes and accuracy is measured."""
    from exohil.formats.recording_reader import read_recording

    whole = read_recording(FIXTURES_DIR / "paper_protocol_heldout.mcap")
    cal, rest = tmp_path / "cal.mcap", tmp_path / "rest.mcap"
    write_recording(cal, cut_recording(whole, 0.0, 8.0))
    write_recording(rest, cut_recording(whole, 8.0, 40.0))
    calibrated = tmp_path / "calibrated.npz"
    result = invoke("calibrate", MODELS_DIR / "ennet.npz", cal, "--out", calibrated,
                    "--steps", "20", "--jitter", "0.1")
    assert result.exit_code == 0, result.output
    profile = tmp_path / "p.toml"
    profile.write_text('name = "cal"\ndescription = "held-out and accuracy"\n[settings]\n'
                       '[checks.compatibility]\n[checks.heldout]\n[checks.accuracy]\n',
                       encoding="utf-8")
    verdicts = {}
    for target in (cal, rest):
        out = tmp_path / target.stem
        invoke("conform", "--target", f"emulator:{target}", "--model", calibrated,
               "--profile", profile, "--out", out)
        report = json.loads((out / "conformance.json").read_text())
        verdicts[target] = {c["name"]: c["verdict"] for c in report["checks"]}
    assert verdicts[cal]["heldout"] == "fail"
    assert verdicts[rest]["heldout"] == "pass"
    assert verdicts[rest]["accuracy"] in ("pass", "fail")  # measured, whatever the limits say


def test_demo_and_run_refuse_a_calibrated_model_its_calibration_frames(tmp_path):
    """demo's --recording and run's --reference are the ground truth a run is scored on:
    refused when they hold the calibration frames, before any device starts; the base model
    takes the same files."""
    from exohil.formats.recording_reader import read_recording

    cal = tmp_path / "cal.mcap"
    write_recording(cal, cut_recording(read_recording(FIXTURES_DIR / "paper_protocol_heldout.mcap"),
                                       0.0, 8.0))
    calibrated = tmp_path / "calibrated.npz"
    result = invoke("calibrate", MODELS_DIR / "ennet.npz", cal, "--out", calibrated,
                    "--steps", "2", "--jitter", "0.1")
    assert result.exit_code == 0, result.output
    missing = tmp_path / "no-device"
    commands = {"--recording": ["demo", "--recording", cal, "--seconds", "1", "--sink", "none",
                                "--no-faults", "--out", tmp_path / "report"],
                "--reference": ["run", missing, "--reference", cal, "--duration", "1",
                                "--sink", "none"]}
    for option, command in commands.items():
        result = invoke(*command, "--model", calibrated)
        assert result.exit_code == 2, result.output
        assert f"{option} cal.mcap: cal.mcap was used to train the model" in result.output
        assert not (tmp_path / "report").exists()
    result = invoke(*commands["--reference"], "--model", MODELS_DIR / "ennet.npz")
    assert result.exit_code == 1 and "no frame arrived" in result.output, result.output
