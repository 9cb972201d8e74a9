"""Alignment, sequence gaps, CSV tables, .mot → recording, and reader robustness to bad bytes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from exohil.formats.alignment import angles_at_sensor_times, in_mocap_gap
from exohil.formats.column_table import TableError, parse_columns, read_table
from exohil.formats.errors import RecordingError
from exohil.formats.mot_import import shoulder_recording_from_mot
from exohil.formats.opensim_mot import MotData
from exohil.formats.recording import AngleStream, Recording, Segment, SensorStream
from exohil.formats.recording_reader import read_recording
from exohil.formats.recording_writer import write_recording
from exohil.formats.sequence import sequence_gaps


def _recording(sensor_t: np.ndarray, mocap_t: np.ndarray, angles: np.ndarray) -> Recording:
    return Recording(
        sensor_names=("F",),
        sensors=SensorStream(np.arange(sensor_t.size), sensor_t, np.zeros((sensor_t.size, 1))),
        mocap={"shoulder": AngleStream(mocap_t, ("elv_angle", "shoulder_elv"), angles)},
    )


def test_angles_interpolate_linearly_and_are_nan_outside_the_mocap_span() -> None:
    mocap_t = np.array([1.0, 2.0, 3.0])
    angles = np.array([[0.0, 10.0], [10.0, 30.0], [20.0, 30.0]])
    rec = _recording(np.array([0.5, 1.0, 1.25, 2.5, 3.0, 3.5]), mocap_t, angles)
    out = angles_at_sensor_times(rec, "shoulder", ["shoulder_elv", "elv_angle"])
    expected = np.array(
        [[np.nan, np.nan], [10.0, 0.0], [15.0, 2.5], [30.0, 15.0], [30.0, 20.0], [np.nan, np.nan]]
    )
    np.testing.assert_array_equal(out, expected)


@settings(max_examples=100, deadline=None)
@given(
    slope=st.floats(-100, 100),
    offset=st.floats(-100, 100),
    times=st.lists(st.floats(0, 10), min_size=2, max_size=30, unique=True),
)
def test_interpolating_a_linear_motion_is_exact(
    slope: float, offset: float, times: list[float]
) -> None:
    mocap_t = np.sort(np.asarray(times))
    angles = np.column_stack([slope * mocap_t + offset, mocap_t])
    sensor_t = np.linspace(mocap_t[0], mocap_t[-1], 17)
    out = angles_at_sensor_times(_recording(sensor_t, mocap_t, angles), "shoulder", ["elv_angle"])
    dropout = in_mocap_gap(sensor_t, mocap_t)  # samples spaced unevenly enough to be one
    assert np.array_equal(np.isnan(out[:, 0]), dropout)
    np.testing.assert_allclose(out[~dropout, 0], slope * sensor_t[~dropout] + offset,
                               atol=1e-9 * (1 + abs(slope)))


def test_a_mocap_dropout_has_no_angles() -> None:
    """The format stores no NaN: a time gap is how a file marks lost markers. Across one the
    arm drew no straight line, so there is no ground truth (4 sample intervals or more)."""
    mocap_t = np.r_[np.arange(0.0, 2.0, 0.01), np.arange(2.5, 4.0, 0.01)]  # 0.5 s lost
    angles = np.column_stack([mocap_t * 10.0, mocap_t])
    sensor_t = np.arange(0.0, 3.99, 0.004)
    out = angles_at_sensor_times(_recording(sensor_t, mocap_t, angles), "shoulder", ["elv_angle"])
    lost = (sensor_t > mocap_t[199]) & (sensor_t < 2.5)
    assert lost.sum() == 127 and np.isnan(out[lost]).all() and np.isfinite(out[~lost]).all()
    held = np.r_[np.arange(0.0, 2.0, 0.01), np.arange(2.025, 4.0, 0.01)]  # 3.5 intervals
    out = angles_at_sensor_times(_recording(sensor_t, held, np.column_stack([held, held])),
                                 "shoulder", ["elv_angle"])
    assert np.isfinite(out).all()


def test_alignment_rejects_unknown_joint_and_angle() -> None:
    rec = _recording(np.zeros(1), np.zeros(1), np.zeros((1, 2)))
    with pytest.raises(RecordingError, match="no mocap joint 'knee'"):
        angles_at_sensor_times(rec, "knee")
    with pytest.raises(RecordingError, match="no angle"):
        angles_at_sensor_times(rec, "shoulder", ["shoulder_rot"])


def test_sequence_gaps_counts_gaps_missing_frames_and_largest() -> None:
    gaps = sequence_gaps(np.array([0, 1, 3, 4, 9, 10]))
    assert (gaps.gaps, gaps.missing, gaps.largest) == (2, 5, 4)
    assert sequence_gaps(np.array([], dtype=np.int64)).gaps == 0


@pytest.mark.parametrize(
    ("spec", "columns"),
    [("0", [0]), ("1-5", [1, 2, 3, 4, 5]), ("3, 1,6-7", [3, 1, 6, 7])],
)
def test_parse_columns(spec: str, columns: list[int]) -> None:
    assert parse_columns(spec) == columns


@pytest.mark.parametrize("spec", ["", "a", "3-1", "-1", "1,1", "1-2-3"])
def test_parse_columns_rejects_bad_specs(spec: str) -> None:
    with pytest.raises(TableError, match="bad column spec"):
        parse_columns(spec)


def test_read_table_handles_bom_and_detects_no_header(tmp_path: Path) -> None:
    path = tmp_path / "t.csv"
    path.write_bytes("\ufeff1.5,2,3\r\n4,5,6\r\n\r\n".encode())
    table = read_table(path, [2, 0])
    assert table.header is None
    np.testing.assert_array_equal(table.data, [[3.0, 1.5], [6.0, 4.0]])


def test_mot_in_radians_becomes_degrees_and_has_no_sensors() -> None:
    mot = MotData(
        time=np.array([0.0, 0.01]),
        columns={"plane_elv": np.array([0.0, np.pi / 2]), "shoulder_elv": np.array([0.1, 0.2]),
                 "axial_rot": np.zeros(2)},
        in_degrees=False,
        header={},
    )
    rec = shoulder_recording_from_mot(mot, {"source": "x.mot"})
    np.testing.assert_allclose(rec.mocap["shoulder"].column("elv_angle"), [0.0, 90.0])
    assert rec.sensor_names == () and rec.sensors.values.shape == (0, 0)
    assert rec.mocap_rate_hz == 100.0


@pytest.mark.parametrize(("time", "plane", "problem"), [
    ([0.0, 0.01, 0.02], [0.0, np.nan, 1.0], "data row 2, column plane_elv: nan is not a finite"),
    ([-1.0, 0.0, 1.0], [0.0, 0.0, 1.0], "data row 1: time -1 s; a recording's times start at 0"),
])
def test_a_mot_row_the_format_cannot_hold_is_named(time, plane, problem) -> None:
    """These were refused by the writer, naming the output file and no row."""
    mot = MotData(time=np.array(time), columns={"plane_elv": np.array(plane),
                                                "shoulder_elv": np.zeros(3),
                                                "axial_rot": np.zeros(3)},
                  in_degrees=True, header={})
    with pytest.raises(RecordingError, match=problem):
        shoulder_recording_from_mot(mot, {})


def _small_file(tmp_path: Path, compression: str) -> bytes:
    t = np.arange(200) * 0.004
    rec = Recording(
        sensor_names=("F", "SF"),
        sensors=SensorStream(np.arange(200), t, np.column_stack([t, 2 * t])),
        mocap={"shoulder": AngleStream(t[::2], ("shoulder_elv",), t[::2, None])},
        segments=[Segment("a", 0.0, 0.5)],
    )
    path = tmp_path / f"base_{compression}.mcap"
    write_recording(path, rec, compression=compression)
    return path.read_bytes()


@settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    compression=st.sampled_from(["none", "lz4", "zstd"]),
    flips=st.lists(st.tuples(st.floats(0, 1, exclude_max=True), st.integers(0, 255)), max_size=4),
    cut=st.one_of(st.none(), st.floats(0, 1, exclude_max=True)),
)
def test_damaged_files_raise_only_recording_error(
    tmp_path: Path, compression: str, flips: list[tuple[float, int]], cut: float | None
) -> None:
    data = bytearray(_small_file(tmp_path, compression))
    for where, byte in flips:
        data[int(where * len(data))] = byte
    if cut is not None:
        data = data[: int(cut * len(data))]
    path = tmp_path / "damaged.mcap"
    path.write_bytes(bytes(data))
    try:
        rec = read_recording(path)
    except RecordingError as exc:
        assert str(path) in str(exc)
    else:
        assert len(rec.sensors) <= 200


def test_cut_recording_keeps_one_span_of_every_stream() -> None:
    from exohil.formats.recording import cut_recording

    t = 5.0 + np.arange(1000) / 250.0  # 4 s of sensors starting at 5 s on the clock
    mt = 5.0 + np.arange(480) / 120.0
    rec = _recording(t, mt, np.column_stack([mt, -mt]))
    rec.segments = [Segment("a", 5.0, 6.5), Segment("b", 6.5, 9.0)]
    rec.metadata = {"source": "test"}
    part = cut_recording(rec, 1.0, 2.0)
    assert len(part.sensors) == 250
    assert part.sensors.t[0] == t[250] and part.sensors.seq[0] == 250
    assert np.all((part.mocap["shoulder"].t >= 6.0) & (part.mocap["shoulder"].t < 7.0))
    assert len(part.mocap["shoulder"]) == 120
    assert [(s.name, s.t0, s.t1) for s in part.segments] == [("a", 6.0, 6.5), ("b", 6.5, 7.0)]
    assert part.metadata == {"source": "test"}
    assert len(cut_recording(rec, 3.0, float("inf")).sensors) == 250
    for start, stop, problem in [(2.0, 2.0, "empty span"), (10.0, 20.0, "no sensor frames")]:
        with pytest.raises(ValueError, match=problem):
            cut_recording(rec, start, stop)


def test_cut_recording_cuts_a_recording_without_sensors_by_its_motion_capture() -> None:
    """An imported .mot has no sensor frames; cutting it was refused ("no sensor frames to
    cut"), so the only way to trim one was to re-import a trimmed file."""
    from exohil.formats.recording import cut_recording

    mt = 5.0 + np.arange(480) / 120.0  # 4 s of mocap starting at 5 s on the clock
    rec = _recording(np.empty(0), mt, np.column_stack([mt, -mt]))
    rec.sensor_names, rec.sensors.values = (), np.empty((0, 0))
    part = cut_recording(rec, 1.0, 2.0)
    assert len(part.sensors) == 0 and len(part.mocap["shoulder"]) == 120
    assert part.mocap["shoulder"].t[0] == mt[120]
    with pytest.raises(ValueError, match="no mocap samples from 10 s to the end"):
        cut_recording(rec, 10.0, float("inf"))
