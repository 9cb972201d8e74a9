"""`exohil record info`, `import csv|mot` and `plot` through click's test runner."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner, Result
from mcap.writer import CompressionType
from recording_raw_mcap import BAD_FILE_CASES, write_bad_file, write_raw_recording
from shared_data import SHARED_DIR

from exohil.formats.recording import AngleStream, Recording, Segment, SensorStream
from exohil.formats.recording_reader import read_recording
from exohil.formats.recording_writer import write_recording
from exohil.harness.cli import main

SHARED = SHARED_DIR
GRAPHENE = SHARED / "realdata" / "graphene-knee" / "S1_2_HC45.csv"
SHOULDER_MOT = SHARED / "realdata" / "shoulder-ik" / "FLX01.mot"
FOREIGN = SHARED / "samples" / "foreign-recording-v1.mcap"


def run(*args: str) -> Result:
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


def assert_one_line_error(result: Result) -> str:
    assert result.exit_code != 0
    assert "Traceback" not in result.output
    errors = [line for line in result.output.splitlines() if line.startswith("Error")]
    assert len(errors) == 1, result.output
    return errors[0]


@pytest.fixture(scope="module")
def other_lab_file(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, int]]:
    path = tmp_path_factory.mktemp("other") / "other.mcap"
    expected = write_raw_recording(path, compression=CompressionType.ZSTD, extra_channel=True)
    return path, expected


def test_record_info_json_reports_counts_gaps_and_rates(
    other_lab_file: tuple[Path, dict[str, int]],
) -> None:
    path, expected = other_lab_file
    result = run("record", "info", path, "--json")
    assert result.exit_code == 0, result.output
    info = json.loads(result.output)
    channels = {c["topic"]: c for c in info["channels"]}
    assert channels["/suit/sensors"]["messages"] == expected["sensor_frames"]
    assert channels["/mocap/shoulder"]["messages"] == expected["mocap_samples"]
    assert channels["/mocap/shoulder"]["mean_rate_hz"] == pytest.approx(120.0, rel=1e-4)
    assert channels["/debug/text"]["used"] is False
    assert info["sequence_gaps"] == {
        "gaps": expected["gaps"],
        "frames_missing": expected["missing"],
        "largest_gap": 1,
    }
    assert info["duration_s"] == pytest.approx(240.0, abs=0.01)
    assert info["sensors"]["names"] == ["F", "SF", "SR", "R"]
    assert info["metadata"]["operator"] == "someone else"
    assert any("/debug/text" in note for note in info["notes"])


def test_record_info_text_lists_channels_and_gaps(
    other_lab_file: tuple[Path, dict[str, int]],
) -> None:
    path, expected = other_lab_file
    result = run("record", "info", path)
    assert result.exit_code == 0
    assert f"{expected['gaps']} gaps, {expected['missing']} frames missing" in result.output
    assert "/mocap/shoulder" in result.output and "(ignored)" in result.output
    assert "largest gap 1 frame\n" in result.output


def test_record_info_aligns_segment_times_under_long_names() -> None:
    result = run("record", "info", Path(__file__).resolve().parents[1] / "fixtures"
                 / "paper_protocol.mcap")
    assert result.exit_code == 0, result.output
    rows = result.output.split("\nsegments")[1].splitlines()[1:]
    assert len(rows) == 5 and "azimuth_fixed_elevation_varied" in result.output
    assert len({row.index("→") for row in rows}) == 1, rows


@pytest.mark.skipif(not FOREIGN.exists(), reason="shared/samples foreign recording absent")
def test_record_info_reads_the_foreign_sample() -> None:
    info = json.loads(run("record", "info", FOREIGN, "--json").output)
    counts = {c["topic"]: c["messages"] for c in info["channels"]}
    assert counts == {"/suit/sensors": 14962, "/mocap/shoulder": 7200}


@pytest.mark.parametrize(("case", "problem"), sorted(BAD_FILE_CASES.items()))
def test_record_info_bad_file_is_one_line(tmp_path: Path, case: str, problem: str) -> None:
    path = write_bad_file(tmp_path / f"{case}.mcap", case)
    for extra in ([], ["--json"]):
        line = assert_one_line_error(run("record", "info", path, *extra))
        assert problem in line and f"{case}.mcap" in line


def _write_csv(tmp_path: Path, text: str, name: str = "table.csv") -> Path:
    path = tmp_path / name
    path.write_bytes(text.encode("utf-8-sig"))
    return path


def test_import_csv_with_bom_header_and_column_lists(tmp_path: Path) -> None:
    rows = "".join(f"{k};{10 + k};{20 + k};{k * 0.5};x\n" for k in range(50))
    source = _write_csv(tmp_path, "preamble line\nangle;a;b;knee;note\n" + rows)
    out = tmp_path / "out.mcap"
    result = run(
        "import", "csv", source, "--out", out, "--rate", "50", "--sensor-cols", "1,2",
        "--angle-cols", "0,3", "--joint", "knee", "--skip-rows", "1", "--delimiter", ";",
        "--license", "CC0",
    )
    assert result.exit_code == 0, result.output
    rec = read_recording(out)
    assert rec.sensor_names == ("a", "b")
    assert rec.mocap["knee"].names == ("angle", "knee")
    np.testing.assert_allclose(rec.sensors.values[:, 1], 20 + np.arange(50))
    np.testing.assert_allclose(rec.mocap["knee"].column("knee"), np.arange(50) * 0.5)
    np.testing.assert_allclose(rec.sensors.t[-1], 49 / 50)
    assert rec.sensor_rate_hz == rec.mocap_rate_hz == 50
    assert rec.metadata["source_sha256"] == hashlib.sha256(source.read_bytes()).hexdigest()
    assert rec.metadata["license"] == "CC0"
    assert "import csv table.csv" in rec.metadata["command"]
    assert "--sensor-cols 1,2" in rec.metadata["command"]
    assert "sensors a,b, angles angle,knee at 50 Hz" in result.output


def test_import_csv_without_angle_columns_says_so(tmp_path: Path) -> None:
    source = _write_csv(tmp_path, "1,2\n3,4\n")
    result = run("import", "csv", source, "--out", tmp_path / "o.mcap", "--rate", "10",
                 "--sensor-cols", "0,1")
    assert result.exit_code == 0, result.output
    assert "sensors c0,c1, no angles at 10 Hz" in result.output


@pytest.mark.parametrize(
    ("args", "problem"),
    [
        (["--rate", "100", "--sensor-cols", "1-x"], "not N or N-M"),
        (["--sensor-cols", "1"], "--rate"),
        (["--rate", "100"], "--sensor-cols"),
        (["--rate", "100", "--sensor-cols", "1", "--angle-cols", "1"], "both a sensor"),
        (["--rate", "100", "--sensor-cols", "9"], "column 9 is needed"),
        (["--rate", "100", "--sensor-cols", "1", "--sensor-names", "a,b"], "names for"),
    ],
)
def test_import_csv_bad_input_is_one_line(tmp_path: Path, args: list[str], problem: str) -> None:
    source = _write_csv(tmp_path, "1,2,3\n4,5,6\n")
    result = run("import", "csv", source, "--out", tmp_path / "o.mcap", *args)
    assert problem in assert_one_line_error(result)


def test_import_csv_non_numeric_cell_is_one_line(tmp_path: Path) -> None:
    source = _write_csv(tmp_path, "1,2\n3,oops\n")
    result = run("import", "csv", source, "--out", tmp_path / "o.mcap", "--rate", "10",
                 "--sensor-cols", "1")
    assert "data row 2" in assert_one_line_error(result)


@pytest.mark.skipif(not GRAPHENE.exists(), reason="shared/realdata/graphene-knee absent")
def test_import_graphene_knee_preset(tmp_path: Path) -> None:
    out = tmp_path / "hc45.mcap"
    result = run("import", "csv", GRAPHENE, "--preset", "graphene-knee", "--out", out)
    assert result.exit_code == 0, result.output
    info = json.loads(run("record", "info", out, "--json").output)
    assert len(info["sensors"]["names"]) == 5
    assert info["sensors"]["nominal_rate_hz"] == 100.0
    assert info["mocap"] == {"knee": {"angles": ["knee_flexion"], "samples": 20662}}
    channels = {c["topic"]: c for c in info["channels"]}
    assert channels["/suit/sensors"]["mean_rate_hz"] == pytest.approx(100.0)
    assert info["metadata"]["license"] == "MIT, e-Body-Lab/graphene-based-knitted-sensing-sleeve"
    assert info["metadata"]["source"] == "S1_2_HC45.csv"
    assert info["metadata"]["source_sha256"] == hashlib.sha256(GRAPHENE.read_bytes()).hexdigest()
    rec = read_recording(out)
    first_row = GRAPHENE.read_text(encoding="utf-8-sig").splitlines()[0].split(",")
    assert rec.mocap["knee"].angles[0, 0] == float(first_row[0])  # 6 decimals kept: lossless
    assert rec.sensors.values[0].tolist() == [float(v) for v in first_row[1:6]]


MOT_TEXT = (
    "Coordinates\nversion=1\nnRows=3\nnColumns=4\ninDegrees=no\nendheader\n"
    "time\tplane_elv\tshoulder_elv\taxial_rot\n"
    "0.00\t0.1\t0.2\t0.3\n0.01\t0.1\t0.25\t0.3\n0.02\t0.1\t0.3\t0.3\n"
)


def test_import_mot_makes_a_mocap_only_recording(tmp_path: Path) -> None:
    source = tmp_path / "trial.mot"
    source.write_text(MOT_TEXT)
    out = tmp_path / "trial.mcap"
    assert run("import", "mot", source, "--out", out).exit_code == 0
    rec = read_recording(out)
    assert rec.sensor_names == () and len(rec.sensors) == 0
    stream = rec.mocap["shoulder"]
    assert stream.names == ("elv_angle", "shoulder_elv", "shoulder_rot")
    expected = np.degrees([0.2, 0.25, 0.3])
    np.testing.assert_allclose(stream.column("shoulder_elv"), expected, atol=1e-4)
    assert rec.mocap_rate_hz == 100.0
    info = json.loads(run("record", "info", out, "--json").output)
    assert [c["topic"] for c in info["channels"]] == ["/mocap/shoulder"]
    text = run("record", "info", out).output
    sensors = [line for line in text.splitlines() if line.startswith("sensors")]
    assert sensors == ["sensors   none (a mocap-only recording)"], text  # no rate of nothing


def test_import_mot_claims_no_sensor_rate(tmp_path: Path) -> None:
    """A recording without sensors stored sensor_rate_hz = 250, a rate of no sensor; the key
    is left out, and reading it back (and cutting it) notes nothing about it."""
    source, out, part = tmp_path / "trial.mot", tmp_path / "trial.mcap", tmp_path / "part.mcap"
    source.write_text(MOT_TEXT)
    assert run("import", "mot", source, "--out", out).exit_code == 0
    info = json.loads(run("record", "info", out, "--json").output)
    assert "sensor_rate_hz" not in info["metadata"]
    assert info["metadata"]["mocap_rate_hz"] == "100"
    assert not [note for note in info["notes"] if "sensor_rate_hz" in note], info["notes"]
    assert run("record", "cut", out, "--start", "0.01", "--out", part).exit_code == 0
    assert "sensor_rate_hz" not in read_recording(part).metadata


def test_import_mot_without_shoulder_coordinates_is_one_line(tmp_path: Path) -> None:
    source = tmp_path / "knee.mot"
    source.write_text("endheader\ntime\tknee_angle\n0\t1\n0.01\t2\n")
    line = assert_one_line_error(run("import", "mot", source, "--out", tmp_path / "k.mcap"))
    assert "plane_elv" in line and "knee.mot" in line


@pytest.mark.skipif(not SHOULDER_MOT.exists(), reason="shared/realdata/shoulder-ik absent")
def test_import_real_shoulder_mot(tmp_path: Path) -> None:
    out = tmp_path / "flx01.mcap"
    assert run("import", "mot", SHOULDER_MOT, "--out", out, "--license", "CC BY 4.0").exit_code == 0
    rec = read_recording(out)
    elevation = rec.mocap["shoulder"].column("shoulder_elv")
    assert rec.mocap_rate_hz == pytest.approx(100.0)
    assert 60.0 < float(elevation.max()) < 120.0
    assert rec.metadata["license"] == "CC BY 4.0"


@pytest.fixture()
def loop_recording(tmp_path: Path) -> Path:
    """A shoulder loop whose sensor lags the elevation (hysteresis) with two segments."""
    t = np.arange(0, 20, 0.004)
    mocap_t = np.arange(0, 20, 1 / 120)
    elevation = 45 - 40 * np.cos(2 * np.pi * mocap_t / 5)
    lagged = 45 - 40 * np.cos(2 * np.pi * t / 5 - 0.3)
    rec = Recording(
        sensor_names=("F", "SF", "SR", "R"),
        sensors=SensorStream(np.arange(t.size), t, 300 - np.outer(lagged, [0.5, 1.0, 0.2, 0.1])),
        mocap={"shoulder": AngleStream(
            mocap_t, ("elv_angle", "shoulder_elv"), np.column_stack([0 * mocap_t, elevation])
        )},
        segments=[Segment("raise", 0.0, 10.0), Segment("lower", 10.0, 20.0)],
    )
    path = tmp_path / "loop.mcap"
    write_recording(path, rec)
    return path


@pytest.mark.parametrize(
    "args",
    [
        ["--kind", "hysteresis"],
        ["--kind", "hysteresis", "--sensor", "F", "--segment", "raise"],
        ["--kind", "timeseries", "--t0", "2", "--t1", "8"],
        ["--kind", "timeseries", "--sensor", "SF", "--sensor", "R"],
    ],
)
def test_plot_writes_a_png(loop_recording: Path, tmp_path: Path, args: list[str]) -> None:
    out = tmp_path / "plot.png"
    result = run("plot", loop_recording, *args, "--out", out)
    assert result.exit_code == 0, result.output
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert out.stat().st_size > 10_000


@pytest.mark.parametrize(("name", "magic"), [("plot.svg", b"<?xml"), ("plot.PDF", b"%PDF")])
def test_plot_writes_the_format_its_name_ends_in(
    loop_recording: Path, tmp_path: Path, name: str, magic: bytes
) -> None:
    out = tmp_path / name
    assert run("plot", loop_recording, "--kind", "hysteresis", "--out", out).exit_code == 0
    assert out.read_bytes().startswith(magic)


@pytest.mark.parametrize(
    ("args", "problem"),
    [
        (["--kind", "hysteresis", "--sensor", "XX"], "no sensor 'XX'"),
        (["--kind", "hysteresis", "--segment", "jump"], "no segment named 'jump'"),
        (["--kind", "hysteresis", "--joint", "knee"], "no mocap joint 'knee'"),
        (["--kind", "hysteresis", "--t0", "50", "--t1", "60"], "no sensor frames"),
        (["--kind", "timeseries", "--t0", "5", "--t1", "1"], "--t1 must be after --t0"),
    ],
)
def test_plot_bad_input_is_one_line(
    loop_recording: Path, tmp_path: Path, args: list[str], problem: str
) -> None:
    result = run("plot", loop_recording, *args, "--out", tmp_path / "p.png")
    assert problem in assert_one_line_error(result)


def test_plot_to_a_name_of_no_image_format_is_refused(loop_recording: Path,
                                                       tmp_path: Path) -> None:
    result = run("plot", loop_recording, "--kind", "hysteresis", "--out", tmp_path / "x.txt")
    assert "x.txt: end it in png, svg, pdf" in assert_one_line_error(result)
    assert not (tmp_path / "x.txt").exists()


@pytest.mark.parametrize(
    "command", [["record", "info"], ["import", "csv"], ["import", "mot"], ["plot"]]
)
def test_every_command_has_help(command: list[str]) -> None:
    result = run(*command, "--help")
    assert result.exit_code == 0 and "Usage:" in result.output and len(result.output) > 200


def test_record_cut_splits_a_recording_in_two(tmp_path: Path) -> None:
    src, head, tail = tmp_path / "s.mcap", tmp_path / "head.mcap", tmp_path / "tail.mcap"
    t = np.arange(2500) / 250.0
    mt = np.arange(1200) / 120.0
    write_recording(src, Recording(("F", "R"), SensorStream(np.arange(2500), t, np.ones((2500, 2))),
                                   {"shoulder": AngleStream(mt, ("elv_angle",), mt[:, None])},
                                   segments=[Segment("move", 0.0, 10.0)]))
    assert run("record", "cut", src, "--stop", "4", "--out", head).exit_code == 0
    result = run("record", "cut", src, "--start", "4", "--out", tail)
    assert result.exit_code == 0 and "1500 of 2500 sensor frames" in result.output
    a, b = read_recording(head), read_recording(tail)
    assert len(a.sensors) + len(b.sensors) == 2500
    assert len(a.mocap["shoulder"]) + len(b.mocap["shoulder"]) == 1200
    assert b.metadata["cut.source"] == "s.mcap" and b.metadata["cut.start_s"] == "4"
    assert b.metadata["cut.source_sha256"] == hashlib.sha256(src.read_bytes()).hexdigest()
    assert [(s.t0, s.t1) for s in b.segments] == [(4.0, 10.0)]
    assert "refusing to overwrite" in assert_one_line_error(
        run("record", "cut", src, "--stop", "1", "--out", src))
    assert "no sensor frames from 20 s to the end (the recording spans 9.996 s" in \
        assert_one_line_error(run("record", "cut", src, "--start", "20", "--out",
                                  tmp_path / "x.mcap"))  # was "to inf s"


def test_motion_direction_reads_frames_that_share_a_time() -> None:
    """Every second frame stamped with the time of the one before (the format allows it):
    the plot warned of a division by zero and coloured a moving arm 'still'."""
    import warnings

    from exohil.harness.recording_plots import motion_direction

    t = np.arange(2000) * 0.004
    angle = 80 + 60 * np.sin(2 * np.pi * t / 4)
    shared = t.copy()
    shared[1::2] = shared[0::2]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        plain, doubled = motion_direction(t, angle), motion_direction(shared, angle)
    assert set(np.unique(plain)) == {-1, 0, 1}
    assert np.mean(doubled == plain) > 0.98


@pytest.mark.parametrize(("header", "args", "problem"), [
    ("knee,,s2", [], "in.csv: column names: invalid sensor name ''"),
    ("knee,s,s", [], "in.csv: column names: duplicate sensor names ('s', 's')"),
    ("knee,a,b", ["--sensor-units", "dR/R0,x"], "'dR/R0,x': a unit without commas"),
])
def test_import_csv_names_the_input_for_what_its_header_holds(tmp_path: Path, header: str,
                                                               args: list[str],
                                                               problem: str) -> None:
    """A bad header name was reported against the output file; a unit with a comma was
    written into `units` ('<sensor unit>,<angle unit>'), which then reads two ways."""
    source = tmp_path / "in.csv"
    source.write_text(header + "\n1,2,3\n4,5,6\n")
    line = assert_one_line_error(run("import", "csv", source, "--rate", "100", "--sensor-cols",
                                     "1-2", "--angle-cols", "0", *args, "--out",
                                     tmp_path / "out.mcap"))
    assert problem in line
    assert not (tmp_path / "out.mcap").exists()


def test_import_csv_columns_of_ones_own_take_the_header_not_the_presets_names(
        tmp_path: Path) -> None:
    """`--preset graphene-knee --sensor-cols 1-2` failed with '5 sensor / 1 angle names for
    2 / 1 columns': the preset's five names went with the user's two columns."""
    source = tmp_path / "knee.csv"
    source.write_text("".join(f"{k},{k % 3},{k % 5},{k % 7},1,2\n" for k in range(10)))
    out = tmp_path / "knee.mcap"
    result = run("import", "csv", source, "--preset", "graphene-knee", "--sensor-cols", "1-2",
                 "--out", out)
    assert result.exit_code == 0, result.output
    rec = read_recording(out)
    assert rec.sensor_names == ("c1", "c2") and rec.mocap["knee"].names == ("knee_flexion",)


@pytest.mark.parametrize("command", [["record", "cut", "--start", "0"], ["record", "recover"]])
def test_cut_and_recover_keep_the_decimals_a_recording_was_imported_with(
        tmp_path: Path, command: list[str]) -> None:
    """An import keeps 6 places (`import csv --decimals`); cut and recover rewrote the
    recording with the writer's default of 4 and rounded the angles (and sensor values of a
    wide range) away without a word."""
    rows = [f"{k * 0.731234:.6f},{k * 1.234567 + 100:.6f}" for k in range(50)]
    source = _write_csv(tmp_path, "\n".join(rows) + "\n")
    imported, rewritten = tmp_path / "imported.mcap", tmp_path / "rewritten.mcap"
    assert run("import", "csv", source, "--out", imported, "--rate", "100", "--sensor-cols",
               "1", "--angle-cols", "0").exit_code == 0
    result = run(*command[:2], imported, *command[2:], "--out", rewritten)
    assert result.exit_code == 0, result.output
    before, after = read_recording(imported), read_recording(rewritten)
    assert after.sensors.values.tolist() == before.sensors.values.tolist()
    assert after.mocap["joint"].angles.tolist() == before.mocap["joint"].angles.tolist()
    assert before.mocap["joint"].angles[1, 0] == 0.731234  # the CSV's 6 places, as imported


def test_import_carries_the_license_and_source_notes_beside_its_input(tmp_path: Path) -> None:
    """A recording imported from licensed data (../shared/realdata keeps LICENSE and SOURCE.md
    beside the files, whose terms ask to keep them with anything derived) named no license
    unless --license was typed: `import mot` of shoulder-ik, `import csv` without --preset."""
    (tmp_path / "trial.mot").write_text(MOT_TEXT)
    (tmp_path / "LICENSE_data").write_text("CC BY 4.0\nCopyright (c) the authors\n")
    (tmp_path / "SOURCE.md").write_text("# Where it comes from\n")
    (tmp_path / "SOURCES.csv").write_text("1,2\n")  # data, not a notice
    (tmp_path / "SOURCE.mcap").write_bytes(b"\x89MCAP0\r\n")  # an earlier import, not one
    out = tmp_path / "out" / "trial.mcap"
    out.parent.mkdir()
    result = CliRunner().invoke(main, ["import", "mot", str(tmp_path / "trial.mot"), "--out",
                                       str(out)])
    assert result.exit_code == 0 and "warning" not in result.output, result.output
    notices = {k: v for k, v in read_recording(out).metadata.items() if k.startswith("notice.")}
    assert notices == {"notice.LICENSE_data": "CC BY 4.0\nCopyright (c) the authors\n",
                       "notice.SOURCE.md": "# Where it comes from\n"}
    shown = run("record", "info", out).output.splitlines()
    assert "  notice.LICENSE_data = CC BY 4.0\\nCopyright (c) the authors\\n" in shown
    assert "Copyright (c) the authors" not in shown  # no line of its own


def test_import_without_a_known_license_says_so(tmp_path: Path) -> None:
    source = _write_csv(tmp_path, "1,2\n3,4\n")
    result = run("import", "csv", source, "--out", tmp_path / "o.mcap", "--rate", "10",
                 "--sensor-cols", "0-1")
    assert result.exit_code == 0
    assert "warning: no license known for table.csv" in result.output
    licensed = run("import", "csv", source, "--out", tmp_path / "p.mcap", "--rate", "10",
                   "--sensor-cols", "0-1", "--license", "CC0")
    assert "warning" not in licensed.output


@pytest.mark.skipif(not SHOULDER_MOT.exists(), reason="shared/realdata/shoulder-ik absent")
def test_the_real_motion_fixture_carries_the_license_of_its_motion() -> None:
    """real_motion_abd_flx.mcap derives from shoulder-ik (CC BY 4.0), whose terms go with
    anything derived; the license sat beside it in fixtures/ but the recording named none,
    so a copy of the file alone had lost it."""
    fixture = Path(__file__).resolve().parents[1] / "fixtures" / "real_motion_abd_flx.mcap"
    metadata = read_recording(fixture).metadata
    assert metadata["license"].startswith("CC BY 4.0")
    for name in ("LICENSE_data", "SOURCE.md"):
        assert metadata[f"notice.{name}"] == (SHOULDER_MOT.parent / name).read_text("utf-8")


@pytest.mark.parametrize("kind", ["hysteresis", "timeseries"])
def test_plot_of_an_empty_window_says_where_the_recording_lies(tmp_path: Path,
                                                               kind: str) -> None:
    """--t0/--t1 are on the recording's clock: a part cut from 10 s on keeps its times, and
    `plot --t0 0 --t1 5` of it only said the window was empty, not where the data are."""
    part = tmp_path / "part.mcap"
    t = 10 + np.arange(1000) / 250.0
    mt = 10 + np.arange(480) / 120.0
    write_recording(part, Recording(("F", "SF"), SensorStream(np.arange(1000), t,
                                                              np.ones((1000, 2))),
                                    {"shoulder": AngleStream(mt, ("shoulder_elv",), mt[:, None])}))
    line = assert_one_line_error(run("plot", part, "--kind", kind, "--t0", "0", "--t1", "5",
                                     "--out", tmp_path / "p.png"))
    assert "on the recording's clock: sensor frames 10.000 → 13.996 s, /mocap/shoulder " \
           "10.000 → 13.992 s" in line


def test_record_cut_of_an_imported_mot_cuts_its_motion_capture(tmp_path: Path) -> None:
    source, whole, part = tmp_path / "t.mot", tmp_path / "whole.mcap", tmp_path / "part.mcap"
    source.write_text(MOT_TEXT)
    assert run("import", "mot", source, "--out", whole, "--license", "CC0").exit_code == 0
    result = run("record", "cut", whole, "--start", "0.01", "--out", part)
    assert result.exit_code == 0, result.output
    assert "2 of 3 mocap samples, 0.010 → 0.020 s after the first mocap sample" in result.output
    assert read_recording(part).mocap["shoulder"].t.tolist() == [0.01, 0.02]


def test_simulated_real_motion_carries_the_notes_beside_its_mot(tmp_path: Path) -> None:
    """`simulate --protocol mot:` derives a recording from licensed motion as `import mot`
    does, but carried no license or source note (only `fixtures build` added them)."""
    rows = "".join(f"{k / 100:.2f}\t0.1\t{0.2 + 0.3 * k / 200:.4f}\t0.3\n" for k in range(201))
    motion = (MOT_TEXT.split("time\t")[0].replace("nRows=3", "nRows=201")
              + "time\tplane_elv\tshoulder_elv\taxial_rot\n" + rows)
    licensed, bare = tmp_path / "licensed", tmp_path / "bare"
    for folder in (licensed, bare):
        folder.mkdir()
        (folder / "trial.mot").write_text(motion)
    (licensed / "LICENSE_data").write_text("CC BY 4.0\n")
    (licensed / "SOURCE.md").write_text("# Where it comes from\n")
    result = run("simulate", "--protocol", f"mot:{licensed / 'trial.mot'}", "--out",
                 tmp_path / "a.mcap")
    assert result.exit_code == 0 and "warning: no LICENSE" not in result.output, result.output
    metadata = read_recording(tmp_path / "a.mcap").metadata
    assert metadata["notice.LICENSE_data"] == "CC BY 4.0\n"
    assert metadata["notice.SOURCE.md"] == "# Where it comes from\n"
    result = run("simulate", "--protocol", f"mot:{bare / 'trial.mot'}", "--out",
                 tmp_path / "b.mcap")
    assert result.exit_code == 0, result.output
    assert "warning: no LICENSE or SOURCE file beside trial.mot" in result.output


@pytest.mark.parametrize("kind", ["hysteresis", "timeseries"])
def test_plot_window_on_a_unix_epoch_clock(tmp_path: Path, kind: str) -> None:
    """Another lab's tool stamps frames with Unix time (1.7e9 s): `plot --t0/--t1` take times
    on the recording's clock, but refused any beyond ±1e9 s, and the empty-window error of
    `--t0 10` told the user to pass the 1.7e9 s times the option refused."""
    rec_path, image = tmp_path / "epoch.mcap", tmp_path / "p.png"
    epoch = 1.7e9
    t = epoch + np.arange(2500) / 250.0
    mt = epoch + np.arange(1200) / 120.0
    values = np.column_stack([np.sin(t - epoch), np.cos(t - epoch)])
    angles = 30 + 20 * np.sin(mt - epoch)[:, None]
    write_recording(rec_path, Recording(("F", "SF"), SensorStream(np.arange(2500), t, values),
                                        {"shoulder": AngleStream(mt, ("shoulder_elv",), angles)}))
    result = run("plot", rec_path, "--kind", kind, "--t0", f"{epoch + 2:.0f}",
                 "--t1", f"{epoch + 6:.0f}", "--out", image)
    assert result.exit_code == 0, result.output
    assert image.stat().st_size > 0


def test_a_hysteresis_plot_without_overlapping_mocap_says_so_not_a_window(tmp_path: Path) -> None:
    """A part cut where another lab's motion capture had not started yet (its /mocap/shoulder
    holds no sample) was refused with 'no sensor frames with mocap in the chosen time window',
    though no window was chosen, and the empty stream went unnamed."""
    part = tmp_path / "part.mcap"
    t = np.arange(500) / 250.0
    write_recording(part, Recording(("F", "SF"), SensorStream(np.arange(500), t,
                                                              np.ones((500, 2))),
                                    {"shoulder": AngleStream(np.zeros(0), ("shoulder_elv",),
                                                             np.zeros((0, 1)))}))
    line = assert_one_line_error(run("plot", part, "--kind", "hysteresis",
                                     "--out", tmp_path / "p.png"))
    assert line == ("Error: no sensor frame lies within the /mocap/shoulder samples of "
                    "shoulder_elv (sensor frames 0.000 → 1.996 s, /mocap/shoulder: none)")
