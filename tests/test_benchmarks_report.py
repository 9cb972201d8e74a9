"""Benchmarks report through measurements: the table, the JSON document, --help and bad
arguments. Nothing here runs a benchmark or asserts a timing."""

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from exohil.formats.measurement import Limit, Measurement, distribution

ROOT = Path(__file__).resolve().parents[1]
BENCHMARKS = ("bench_sim", "bench_recording_io", "bench_inference", "bench_emulator",
              "bench_unseen_suits")


def run_module(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", *args], cwd=ROOT, capture_output=True,
                          text=True, timeout=120)


def test_report_prints_an_aligned_table_and_writes_the_json_document(tmp_path, capsys,
                                                                    monkeypatch):
    monkeypatch.syspath_prepend(str(ROOT))
    from benchmarks.report import report

    measurements = [
        Measurement.judge("frames.delivered", 15000, "count"),
        *distribution("push.numpy", [50.0, 60.0, 400.0], "us",
                      {"p99": Limit(high=100.0, unit="us", inclusive=True)}),
        Measurement.skipped("push.onnxruntime.p99", "us", "onnxruntime is not installed"),
    ]
    out = tmp_path / "bench.json"
    report("bench_demo", measurements, out)

    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("machine: ")
    header, rows = lines[1], lines[2:-1]
    assert len(rows) == len(measurements)
    unit_column = header.index("unit")
    assert all(row[unit_column - 2:unit_column] == "  " for row in rows)
    assert "15000  count" in rows[0]
    failing = next(r for r in rows if r.startswith("push.numpy.p99"))
    assert "<= 100 us" in failing and "FAIL" in failing
    assert lines[-1] == "verdicts: 3 info, 1 fail, 1 skip"

    document = json.loads(out.read_text(encoding="utf-8"))
    assert document["benchmark"] == "bench_demo" and document["machine"]
    assert document["measurements"] == [m.to_dict() for m in measurements]
    assert [p.name for p in tmp_path.iterdir()] == ["bench.json"]  # no temporary left behind


@pytest.mark.parametrize("module", [f"benchmarks.{b}" for b in BENCHMARKS] + ["benchmarks"])
def test_every_benchmark_documents_json_in_its_help(module):
    result = run_module(module, "--help")
    assert result.returncode == 0, result.stderr
    assert "--json FILE" in result.stdout


@pytest.mark.parametrize("args", [("benchmarks.bench_sim", "--repeats", "0"),
                                  ("benchmarks.bench_emulator", "--seconds", "0"),
                                  ("benchmarks.bench_inference", "--frames", "-5"),
                                  ("benchmarks.bench_unseen_suits", "--suits", "0"),
                                  ("benchmarks.bench_recording_io", "--json",
                                   "/no/such/folder/out.json")])
def test_bad_arguments_are_refused_before_anything_runs(args):
    result = run_module(*args)
    assert result.returncode == 2
    assert result.stdout == "" and "error: argument" in result.stderr


def test_unseen_suit_sessions_share_the_suit_and_differ_in_movement(monkeypatch):
    monkeypatch.syspath_prepend(str(ROOT))
    from benchmarks.bench_unseen_suits import parse_model, session

    train, test = session(11, "train", 4.0), session(11, "test", 4.0)
    assert train.sensor_names == test.sensor_names  # the same suit
    assert session(12, "train", 4.0).sensor_names != train.sensor_names  # another geometry
    angles = [r.mocap["shoulder"].angles for r in (train, test)]
    assert angles[0].shape == angles[1].shape and not (angles[0] == angles[1]).all()
    assert (session(11, "train", 4.0).sensors.values == train.sensors.values).all()  # seeded
    assert parse_model("ann") == ("ann", ["--model", "ann"])
    refused = run_module("benchmarks.bench_unseen_suits", "--baseline", "lnnet")
    assert refused.returncode == 2 and refused.stdout == ""
    assert "--baseline 'lnnet' is not among the models" in refused.stderr
    assert parse_model("w=--model ennet --window 5") == ("w", ["--model", "ennet", "--window",
                                                               "5"])


def test_a_sphere_control_differs_from_its_recording_by_the_effect_alone(monkeypatch):
    monkeypatch.syspath_prepend(str(ROOT))
    from benchmarks.bench_discrepancy_sphere import SphereCase, make_recording

    case = SphereCase("hysteresis", 2, 3, 6.0)
    with_effect, control = make_recording(case), make_recording(replace(case, with_effect=False))
    assert with_effect.mocap["shoulder"].angles.tolist() == control.mocap[
        "shoulder"].angles.tolist()  # the same movement, seen the same way
    difference = with_effect.sensors.values - control.sensors.values
    assert abs(np.sqrt(np.mean(difference**2)) - 0.6) < 1e-9  # the effect, at its RMS


@pytest.mark.parametrize("entry, error", [
    ({"file": "rec_00.mcap", "effect": "stiction"}, "bad entry 'rec_00.mcap'"),
    ({"file": "missing.mcap", "effect": "lag"}, "bad entry 'missing.mcap'"),
])
def test_the_blind_scorer_refuses_an_answer_key_it_cannot_score(tmp_path, entry, error):
    """An answer key naming an effect outside the vocabulary or a file that is not there is
    refused with one line before any recording is run; so is a folder without one."""
    (tmp_path / "rec_00.mcap").write_bytes(b"")
    out = run_module("benchmarks.bench_discrepancy_blind", str(tmp_path))
    assert out.returncode == 2 and "truth.json not found" in out.stderr, out.stderr
    (tmp_path / "truth.json").write_text(json.dumps([entry]))
    out = run_module("benchmarks.bench_discrepancy_blind", str(tmp_path))
    assert out.returncode == 2 and error in out.stderr and "Traceback" not in out.stderr, (
        out.stderr)


def test_the_blind_scorer_refuses_twins_it_cannot_read_before_running_anything(tmp_path):
    """--twins needs every effect recording's twin summary; a clean recording needs none."""
    (tmp_path / "rec_00.mcap").write_bytes(b"")  # not a recording: it must never be run
    (tmp_path / "rec_01.mcap").write_bytes(b"")
    (tmp_path / "truth.json").write_text(json.dumps([{"file": "rec_01.mcap", "effect": "clean"},
                                                     {"file": "rec_00.mcap", "effect": "lag"}]))
    twins = tmp_path / "twins"
    twins.mkdir()
    out = run_module("benchmarks.bench_discrepancy_blind", str(tmp_path), "--twins", str(twins))
    assert out.returncode == 2 and "rec_00.json" in out.stderr, out.stderr
    assert "rec_01" not in out.stderr and "Traceback" not in out.stderr, out.stderr
    (twins / "rec_00.json").write_text(json.dumps({"gap_after": 1.0}))
    out = run_module("benchmarks.bench_discrepancy_blind", str(tmp_path), "--twins", str(twins))
    assert out.returncode == 2 and "gap_before" in out.stderr, out.stderr


def test_what_an_effect_adds_over_its_twin_is_in_noise_variances(monkeypatch, capsys):
    monkeypatch.syspath_prepend(str(ROOT))
    from benchmarks.bench_discrepancy_blind import added_over_twin, print_shown_rates

    assert added_over_twin({"gap_before": 0.5, "noise_floor": 0.1}, 0.3) == pytest.approx(16.0)
    assert added_over_twin({"gap_before": 0.3, "noise_floor": 0.1}, 0.5) == pytest.approx(-16.0)
    assert added_over_twin({"gap_before": 0.5, "noise_floor": 0.0}, 0.3) == float("inf")
    print_shown_rates([("lag", "lag", 16.0), ("creep", "clean", 1.0), ("drift", "drift", 0.99),
                       ("saturation", "clean", -3.0), ("hysteresis", "hysteresis", 2.0)])
    shown, rest = capsys.readouterr().out.splitlines()
    assert "≥ 1 noise variance" in shown and shown.endswith("2/3 (66.7%)")
    assert "add less" in rest and rest.endswith("1/2 (50.0%)")


def test_the_sweep_lists_what_did_not_halve_beside_its_control_and_floor(monkeypatch, capsys):
    monkeypatch.syspath_prepend(str(ROOT))
    from benchmarks.bench_discrepancy import print_short_of_half
    from exohil.emulators.discrepancy.hidden import Case

    def summary(named, before, after, floor=0.15):
        return {"effects": [named] if named else [], "gap_before": before, "gap_after": after,
                "noise_floor": floor}

    stop, creep = Case("saturation", "alt", 1, 7), Case("creep", "lib", 2, 7)
    print_short_of_half({
        stop: summary("saturation", 0.29, 0.18),  # half 0.145 under the floor: hopeless
        creep: summary("creep", 0.50, 0.30),  # could have halved
        Case("drift", "alt", 2, 7): summary("drift", 0.25, 0.20),  # hopeless, no control run
        Case("lag", "lib", 1, 7): summary("lag", 0.80, 0.20),  # halved: not listed
        Case("clean", "alt", 1, 7): summary("", 0.17, 0.17),  # stop's control
    })
    lines = capsys.readouterr().out.strip().splitlines()
    assert [line.split()[0] for line in lines[1:4]] == [stop.label, creep.label,
                                                        "drift/alt/m2/s7"]
    assert "clean control 0.170" in lines[1] and "clean control not run" in lines[2]
    assert lines[-1].startswith("of these 3, 2 have a gap before under twice the noise floor")


@pytest.mark.parametrize("text, error", [
    ("[{", "not JSON"),
    ('{"file": "rec_00.mcap", "effect": "lag"}', "must be a list of objects"),
])
def test_the_blind_scorer_refuses_an_answer_key_that_is_not_a_list(tmp_path, text, error):
    (tmp_path / "truth.json").write_text(text)
    out = run_module("benchmarks.bench_discrepancy_blind", str(tmp_path))
    assert out.returncode != 0 and error in out.stderr and "Traceback" not in out.stderr, (
        out.stderr)


def test_the_anchor_angle_is_seen_from_the_caps_centre_in_the_generators_frames(monkeypatch):
    """The third blind generator's check of nearly opposite anchors: on a round cap at the
    origin that the scapula does not tilt, an anchor straight below the cap's centre and a
    humerus anchor straight above it are 180° apart; turned to the side, 90°."""
    monkeypatch.syspath_prepend(str(ROOT))  # found before only if an earlier test had put it
    from benchmarks.blind3 import generate as blind3
    from benchmarks.blind3.antipodal import anchor_angles_deg

    suit = blind3.Suit(np.random.default_rng(0), 1)
    suit.axes, suit.cap_offset, suit.pivot = np.full(3, 50.0), np.zeros(3), np.zeros(3)
    suit.rhythm, suit.onscap = 0.0, [False]
    suit.prox, suit.dist = [np.array([0.0, -80.0, 0.0])], [np.array([0.0, 120.0, 0.0])]
    zero = np.zeros(1)
    assert anchor_angles_deg(suit, zero, zero, zero)[0, 0] == pytest.approx(180.0)
    suit.prox = [np.array([80.0, 0.0, 0.0])]
    assert anchor_angles_deg(suit, zero, zero, zero)[0, 0] == pytest.approx(90.0)


def test_the_anchor_check_refuses_missing_summaries_before_regenerating(tmp_path):
    """Every twin's summary must be there, with the steps of the reading, before minutes of
    regenerating begin."""
    (tmp_path / "rec_00.json").write_text("{}")
    out = run_module("benchmarks.blind3.antipodal", str(tmp_path), "--only", "0", "1")
    assert out.returncode == 2 and "rec_01.json is missing" in out.stderr, out.stderr
    assert "Traceback" not in out.stderr and "twin" not in out.stdout, out
    out = run_module("benchmarks.blind3.antipodal", str(tmp_path), "--only", "40")
    assert out.returncode == 2 and "no twin 40" in out.stderr, out.stderr
    (tmp_path / "rec_01.json").write_text(json.dumps({"localisation_after": {"steps": []}}))
    out = run_module("benchmarks.blind3.antipodal", str(tmp_path), "--only", "0", "1")
    assert out.returncode == 2 and "rec_00.json has no steps of the reading" in out.stderr
    assert "Traceback" not in out.stderr and "twin" not in out.stdout, out
