"""Readings outside a model's training data are told: by `evaluate`, by a session's report
and by the conformance suite (its compatibility check), and not for the model's own suit."""

import copy
import json

import numpy as np
import pytest
from click.testing import CliRunner
from shared_data import SHARED_DIR

from exohil.estimator.checkpoint import load_checkpoint
from exohil.estimator.coverage import (
    OUTSIDE_SIGMAS,
    CoverageTally,
    block_coverage,
    input_statistics,
    stream_coverage,
)
from exohil.estimator.dataset import Block, initial_baseline
from exohil.harness.cli import main
from exohil.harness.paths import FIXTURES_DIR, MODELS_DIR

ENNET = MODELS_DIR / "ennet.npz"
HELDOUT = FIXTURES_DIR / "paper_protocol_heldout.mcap"
FOREIGN = SHARED_DIR / "samples" / "foreign-recording-v1.mcap"


@pytest.fixture(scope="module")
def ennet():
    return load_checkpoint(ENNET)


def _model(base, mean, std, offset_frames=0, info=None):
    est = copy.copy(base)
    est.norm = copy.copy(base.norm)
    est.norm.x_mean, est.norm.x_std = np.asarray(mean, float), np.asarray(std, float)
    est.offset_frames, est.info = offset_frames, info or {}
    return est


def test_a_frame_is_outside_when_any_sensor_reads_beyond_the_bound(ennet):
    est = _model(ennet, [0, 0, 0, 0], [1, 1, 2, 1])
    inside = OUTSIDE_SIGMAS - 0.01
    values = np.array([[0, 0, 0, 0],
                       [inside, -inside, 2 * inside, 0],  # SR's σ is 2
                       [0, 0, 2 * OUTSIDE_SIGMAS + 0.1, 0],
                       [0, -OUTSIDE_SIGMAS - 0.1, 0, 0],
                       [np.nan, 50, 50, 50]])  # not counted
    tally = stream_coverage(est, values)
    assert (tally.frames, tally.outside) == (4, 2)
    assert tally.outside_percent == 50.0 and tally.warns
    low, high = tally.extremes()["SR"]
    assert low == 0 and high == pytest.approx(OUTSIDE_SIGMAS + 0.05)
    assert "SR +4.0σ" in tally.warning() and "SF -4.1σ" in tally.warning()
    assert not stream_coverage(est, values[:2]).warns
    assert CoverageTally(est).outside_percent is None and CoverageTally(est).warning() is None


def test_a_calibrated_model_counts_its_calibration_readings_as_trained_on(ennet):
    calibrated = {"calibration": {"input_mean": [100.0] * 4, "input_std": [1.0] * 4},
                  "base_info": {"calibration": {"input_mean": [-100.0] * 4,
                                                "input_std": [2.0] * 4}}}
    est = _model(ennet, [0] * 4, [1] * 4, info=calibrated)
    values = np.array([[0, 1, 0, 0], [100, 101, 99, 103], [-100, -105, -95, -107],
                       [60, 60, 60, 60], [100, 100, 100, 110]])
    tally = stream_coverage(est, values)
    assert (tally.frames, tally.outside) == (5, 2)
    # each frame against the readings it lies nearest: 60 and 110 against 100 ± 1
    assert tally.extremes()["R"] == pytest.approx((-40.0, 10.0))
    assert stream_coverage(_model(ennet, [0] * 4, [1] * 4), values).outside == 4


def _block(x):
    n = len(x)
    return Block(x=np.asarray(x, float), y=np.zeros((n, 2)), t=np.arange(n, dtype=float),
                 segment=np.full(n, "", dtype=object))


def test_readings_in_range_whose_combination_training_never_held_are_outside(ennet):
    rng = np.random.default_rng(3)
    pose = rng.uniform(-1.0, 1.0, (5000, 2))  # two degrees of freedom drive four sensors
    mixing = np.array([[1.0, 0.2, -0.5, 0.8], [0.3, 1.0, 0.9, -0.4]])
    train = pose @ mixing + rng.normal(0.0, 0.01, (5000, 4))
    kept = input_statistics([_block(train)])
    est = _model(ennet, kept["input_mean"], kept["input_std"],
                 info={"training_inputs": kept})
    assert stream_coverage(est, train).outside == 0  # the farthest frame is the reach
    unseen = rng.uniform(-1.0, 1.0, (1000, 2)) @ mixing  # same poses, and ...
    unseen[500:, 3] = -unseen[500:, 3]  # ... half with one sensor mirrored: each in range
    tally = stream_coverage(est, unseen)
    lows, highs = zip(*tally.extremes().values(), strict=True)
    assert max(highs) < OUTSIDE_SIGMAS and min(lows) > -OUTSIDE_SIGMAS
    assert 400 <= tally.outside <= 500 and tally.warns and tally.furthest > 10
    without = _model(ennet, kept["input_mean"], kept["input_std"])  # an older checkpoint
    assert stream_coverage(without, unseen).outside == 0


def test_the_rest_offset_is_removed_as_the_streaming_engine_removes_it(ennet):
    rng = np.random.default_rng(4)
    values = 40.0 + rng.normal(0.0, 1.0, (600, 4)).cumsum(axis=0) * 0.3
    est = _model(ennet, [0] * 4, [2.5] * 4, offset_frames=50)
    streamed = CoverageTally(est)
    for start in (0, 7, 8, 49, 51, 300):  # blocks that split the first 50 frames
        stop = {0: 7, 7: 8, 8: 49, 49: 51, 51: 300, 300: 600}[start]
        streamed.add(values[start:stop])
    seen = Block(x=values - initial_baseline(values, 50), y=np.zeros((600, 2)),
                 t=np.arange(600.0), segment=np.full(600, "", dtype=object))
    whole = block_coverage(est, [seen])
    assert 0 < streamed.outside < streamed.frames
    assert (streamed.frames, streamed.outside) == (whole.frames, whole.outside)
    for name, (low, high) in whole.extremes().items():
        assert streamed.extremes()[name] == pytest.approx((low, high), rel=1e-12)


@pytest.mark.skipif(not FOREIGN.exists(), reason="the other lab's sample is not here")
def test_evaluate_warns_on_another_suits_readings_and_not_on_its_own(tmp_path):
    runs = {}
    for name, recording in (("own", HELDOUT), ("foreign", FOREIGN)):
        out = tmp_path / f"{name}.json"
        result = CliRunner().invoke(main, ["evaluate", str(ENNET), str(recording),
                                           "--json", str(out)])
        assert result.exit_code == 0, result.output
        runs[name] = (result.output, json.loads(out.read_text())["training_coverage"])
    output, coverage = runs["own"]
    assert "warning" not in output and coverage["outside_percent"] < 0.1  # 8 of 61,431 frames
    output, coverage = runs["foreign"]
    assert output.startswith("warning: 100.0% of ") and "exohil calibrate" in output
    assert coverage["outside_percent"] == 100
    assert all(low < -OUTSIDE_SIGMAS for low, high in coverage["extremes_sigmas"].values())


@pytest.mark.skipif(not FOREIGN.exists(), reason="the other lab's sample is not here")
def test_a_session_on_another_suit_reports_it(tmp_path):
    summary = tmp_path / "summary.json"
    result = CliRunner().invoke(main, ["demo", "--recording", str(FOREIGN), "--seconds", "2",
                                       "--no-faults", "--json", str(summary)])
    assert result.exit_code == 0, result.output
    s = json.loads(summary.read_text())
    assert s["training_coverage"]["outside_percent"] == 100
    assert s["training_coverage"]["frames"] == s["frames"]["received"]
    assert f"warning     {s['training_coverage_warning']}" in result.output
    measured = {m["name"]: m for m in s["measurements"]}
    assert measured["compatibility.outside_training"]["value"] == 100


@pytest.mark.skipif(not FOREIGN.exists(), reason="the other lab's sample is not here")
def test_conformance_fails_compatibility_on_another_suits_readings(tmp_path):
    verdicts = {}
    for name, recording in (("own", HELDOUT), ("foreign", FOREIGN)):
        out = tmp_path / name
        result = CliRunner().invoke(main, ["conform", "--target", f"emulator:{recording}",
                                           "--model", str(ENNET), "--out", str(out),
                                           "-k", "compatibility"])
        report = json.loads((out / "conformance.json").read_text())
        check = next(c for c in report["checks"] if c["name"] == "compatibility")
        measured = {m["name"]: m for m in check["measurements"]}["compatibility.outside_training"]
        verdicts[name] = (check["verdict"], measured["value"])
        assert result.exit_code != 0  # -k left the profile's other checks out
    assert verdicts["own"][0] == "pass" and verdicts["own"][1] < 0.1  # 8 frames
    assert verdicts["foreign"][0] == "fail" and verdicts["foreign"][1] == 100
