"""Recording format v1 file I/O (recording_writer, recording_reader): round trip, determinism,
foreign writers, bad files."""

from __future__ import annotations

import json
import re
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap.writer import CompressionType
from recording_raw_mcap import (
    BAD_FILE_CASES,
    frame,
    write_bad_file,
    write_raw_recording,
    write_sensor_messages,
)
from shared_data import SHARED_DIR

from exohil.formats.errors import RecordingError
from exohil.formats.recording import AngleStream, Recording, Segment, SensorStream
from exohil.formats.recording_messages import sensor_decimals
from exohil.formats.recording_reader import read_recording, scan_recording
from exohil.formats.recording_writer import RecordingWriter, write_recording
from exohil.formats.schemas import joint_angles_schema, sensor_frame_schema
from exohil.formats.sequence import sequence_gaps

SHARED = SHARED_DIR
SHOULDER_ANGLES = ("elv_angle", "shoulder_elv", "shoulder_rot")
FOREIGN = SHARED / "samples" / "foreign-recording-v1.mcap"

finite = st.floats(min_value=-1e4, max_value=1e4, allow_nan=False, allow_infinity=False)


@st.composite
def recordings(draw: st.DrawFn) -> Recording:
    """Small random recordings: 0-5 sensors, 0-2 joints, random seq gaps and segments."""
    sensor_count = draw(st.integers(0, 5))
    frames = draw(st.integers(0, 30)) if sensor_count else 0
    steps = draw(st.lists(st.integers(1, 4), min_size=frames, max_size=frames))
    seq = np.cumsum(np.asarray(steps, dtype=np.int64)) + draw(st.integers(0, 1000))
    t = np.sort(np.asarray(draw(st.lists(st.floats(0, 1e4), min_size=frames, max_size=frames))))
    values = np.asarray(
        draw(st.lists(finite, min_size=frames * sensor_count, max_size=frames * sensor_count))
    ).reshape(frames, sensor_count)
    mocap = {}
    for joint in draw(st.lists(st.sampled_from(["shoulder", "knee", "elbow"]), unique=True)):
        names = tuple(draw(st.lists(st.sampled_from(["a", "b", "c"]), min_size=1, unique=True)))
        samples = draw(st.integers(0, 20))
        mocap[joint] = AngleStream(
            t=np.asarray(draw(st.lists(st.floats(0, 1e4), min_size=samples, max_size=samples))),
            names=names,
            angles=np.asarray(
                draw(st.lists(finite, min_size=samples * len(names), max_size=samples * len(names)))
            ).reshape(samples, len(names)),
        )
    segments = [
        Segment(name, t0, t0 + 1.0)
        for name, t0 in draw(
            st.lists(st.tuples(st.text(max_size=5), st.floats(0, 100)), max_size=3)
        )
    ]
    return Recording(
        sensor_names=tuple(f"s{k}" for k in range(sensor_count)),
        sensors=SensorStream(seq=seq, t=t, values=values),
        mocap=mocap,
        sensor_units=draw(st.sampled_from(["mm", "dR/R0"])),
        sensor_rate_hz=draw(st.sampled_from([250.0, 100.0, 59.94])),
        mocap_rate_hz=draw(st.sampled_from([120.0, 100.0])),
        segments=segments,
        metadata=draw(st.dictionaries(st.sampled_from(["generator", "seed", "x"]), st.text())),
    )


@settings(max_examples=40, deadline=None)
@given(rec=recordings())
def test_round_trip_preserves_everything_up_to_documented_rounding(
    tmp_path_factory: pytest.TempPathFactory, rec: Recording
) -> None:
    path = tmp_path_factory.mktemp("rt") / "rec.mcap"
    write_recording(path, rec)
    back = read_recording(path)
    assert back.sensor_names == rec.sensor_names
    np.testing.assert_array_equal(back.sensors.seq, rec.sensors.seq)
    np.testing.assert_array_equal(back.sensors.t, np.round(rec.sensors.t, 6))
    kept = sensor_decimals(rec.sensors.values)  # 4, or more for a column of a small range
    np.testing.assert_array_equal(back.sensors.values, np.round(rec.sensors.values, kept))
    assert list(back.mocap) == list(rec.mocap)
    for joint, stream in rec.mocap.items():
        order = np.argsort(np.round(stream.t, 6), kind="stable")
        assert back.mocap[joint].names == stream.names
        np.testing.assert_array_equal(back.mocap[joint].t, np.round(stream.t, 6)[order])
        np.testing.assert_array_equal(back.mocap[joint].angles, np.round(stream.angles, 4)[order])
    assert back.sensor_units == rec.sensor_units
    assert back.sensor_rate_hz == rec.sensor_rate_hz
    assert back.mocap_rate_hz == rec.mocap_rate_hz
    assert back.segments == rec.segments
    for key, value in rec.metadata.items():
        assert back.metadata[key] == value


@pytest.mark.parametrize("scale", [1.0, 1e-6, 1e-9])
def test_readings_in_small_units_keep_their_levels(tmp_path: Path, scale: float) -> None:
    """Rounding to the default 4 places would leave two levels of readings of 5·10⁻⁴ F;
    a recording written whole keeps 10⁻⁵ of each sensor's range."""
    rec = _demo_recording(4.0)
    rec.sensors = SensorStream(rec.sensors.seq, rec.sensors.t, rec.sensors.values * scale)
    path = tmp_path / "small.mcap"
    write_recording(path, rec)
    back = read_recording(path).sensors.values
    span = np.ptp(rec.sensors.values, axis=0)
    assert np.all(np.abs(back - rec.sensors.values) <= 0.5e-5 * span)
    assert (sensor_decimals(rec.sensors.values) == 4) == (scale == 1.0)  # mm: as ever


def test_times_in_milliseconds_are_noted_against_the_nominal_rate(tmp_path: Path) -> None:
    from exohil.emulators.discrepancy.workflow import rate_words

    rec = _demo_recording(4.0)
    path = tmp_path / "ms.mcap"
    write_recording(path, rec)
    assert not [n for n in scan_recording(path).notes if "timestamps give" in n]
    rec.sensors = SensorStream(rec.sensors.seq, rec.sensors.t * 1000, rec.sensors.values)
    write_recording(path, rec)
    notes = [n for n in scan_recording(path).notes if "timestamps give" in n]
    assert notes == ["metadata sensor_rate_hz=250 but the timestamps give 0.25 Hz: are the "
                     "times in seconds?"]
    assert rate_words(0.25, 250.0).startswith("the frames' times give 0.25 Hz where")
    assert rate_words(249.0, 250.0) == ""


def _demo_recording(seconds: float = 20.0) -> Recording:
    seq = np.arange(int(seconds * 250))
    seq = seq[seq % 101 != 50]
    t = seq * 0.004 + 1e-5 * np.sin(seq)
    values = 300 + 20 * np.sin(np.outer(t, [1.0, 1.3, 1.7, 2.1])) + 1e-7 * seq[:, None]
    mocap_t = np.arange(int(seconds * 120)) / 120.0
    angles = np.column_stack([30 * np.sin(mocap_t), 45 + 40 * np.sin(mocap_t / 2), 0 * mocap_t])
    return Recording(
        sensor_names=("F", "SF", "SR", "R"),
        sensors=SensorStream(seq=seq, t=t, values=values),
        mocap={"shoulder": AngleStream(mocap_t, SHOULDER_ANGLES, angles)},
        segments=[Segment("abduction", 1.0, 5.0)],
        metadata={"generator": "test", "seed": "7"},
    )


@pytest.mark.parametrize("compression", ["none", "lz4", "zstd"])
def test_writing_twice_gives_identical_bytes(tmp_path: Path, compression: str) -> None:
    rec = _demo_recording()
    write_recording(tmp_path / "a.mcap", rec, compression=compression)
    write_recording(tmp_path / "b.mcap", rec, compression=compression)
    assert (tmp_path / "a.mcap").read_bytes() == (tmp_path / "b.mcap").read_bytes()


def test_streaming_writer_matches_whole_recording_writer(tmp_path: Path) -> None:
    rec = _demo_recording(4.0)
    write_recording(tmp_path / "whole.mcap", rec)
    mocap = rec.mocap["shoulder"]
    with RecordingWriter(
        tmp_path / "live.mcap",
        rec.sensor_names,
        mocap_joints={"shoulder": mocap.names},
        metadata=rec.metadata,
    ) as writer:
        events = sorted(
            [(round(t * 1e9), 0, k) for k, t in enumerate(np.round(rec.sensors.t, 6))]
            + [(round(t * 1e9), 1, k) for k, t in enumerate(np.round(mocap.t, 6))]
        )
        for _, kind, k in events:
            if kind == 0:
                writer.add_sensor_frame(
                    int(rec.sensors.seq[k]), rec.sensors.t[k], rec.sensors.values[k]
                )
            else:
                writer.add_mocap_sample("shoulder", mocap.t[k], mocap.angles[k])
        writer.add_segment(rec.segments[0])
    assert (tmp_path / "live.mcap").read_bytes() == (tmp_path / "whole.mcap").read_bytes()


def test_written_messages_validate_against_their_jsonschema(tmp_path: Path) -> None:
    path = tmp_path / "rec.mcap"
    write_recording(path, _demo_recording(2.0))
    with open(path, "rb") as stream:
        reader = make_reader(stream)
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}["exohil.recording"]
        checked = 0
        for schema, channel, message in reader.iter_messages():
            assert schema.encoding == "jsonschema" and channel.message_encoding == "json"
            body = json.loads(message.data)
            jsonschema.validate(body, json.loads(schema.data))
            assert message.log_time == message.publish_time == round(body["t"] * 1e9)
            checked += 1
    assert checked == 2 * 250 - 5 + 2 * 120  # seq 50,151,…,454 dropped
    assert metadata["format"] == "exohil-recording" and metadata["version"] == "1"
    assert metadata["units"] == "mm,deg" and metadata["sensors"] == "F,SF,SR,R"
    assert json.loads(metadata["segments"]) == [{"name": "abduction", "t0": 1.0, "t1": 5.0}]


def test_full_length_protocol_fits_ten_megabytes(tmp_path: Path) -> None:
    path = tmp_path / "long.mcap"
    write_recording(path, _demo_recording(246.0))
    assert path.stat().st_size <= 10_000_000
    assert len(read_recording(path).sensors) == len(_demo_recording(246.0).sensors)


@pytest.mark.parametrize(
    ("compression", "chunked", "summary"),
    [
        (CompressionType.LZ4, True, True),
        (CompressionType.ZSTD, True, True),
        (CompressionType.NONE, False, True),
        (CompressionType.ZSTD, True, False),
        (CompressionType.NONE, False, False),
    ],
)
def test_reads_recordings_from_an_independent_writer(
    tmp_path: Path, compression: CompressionType, chunked: bool, summary: bool
) -> None:
    path = tmp_path / "other.mcap"
    expected = write_raw_recording(
        path, compression=compression, chunked=chunked, summary=summary, extra_channel=True
    )
    scan = scan_recording(path)
    rec = scan.recording
    assert len(rec.sensors) == expected["sensor_frames"] == 59940
    assert len(rec.mocap["shoulder"]) == expected["mocap_samples"] == 28800
    gaps = sequence_gaps(rec.sensors.seq)
    assert (gaps.gaps, gaps.missing, gaps.largest) == (expected["gaps"], expected["missing"], 1)
    rates = {c.topic: c.mean_rate_hz for c in scan.channels}
    assert rates["/suit/sensors"] == pytest.approx(250.0 * 59940 / 60000, rel=1e-3)
    assert rates["/mocap/shoulder"] == pytest.approx(120.0, rel=1e-4)
    assert rec.metadata["operator"] == "someone else"
    assert any("/debug/text" in note for note in scan.notes)
    assert any("other.lab" in note for note in scan.notes)
    assert rec.mocap["shoulder"].names == ("elv_angle", "shoulder_elv", "shoulder_rot")


def test_missing_optional_metadata_gets_documented_defaults(tmp_path: Path) -> None:
    path = tmp_path / "bare.mcap"
    bare = {"format": "exohil-recording", "version": "1"}
    write_raw_recording(path, duration_s=2.0, metadata=bare)
    scan = scan_recording(path)
    rec = scan.recording
    assert rec.sensor_names == ("F", "SF", "SR", "R")
    assert rec.sensor_units == "mm"
    assert rec.sensor_rate_hz == pytest.approx(250.0)
    assert rec.mocap_rate_hz == pytest.approx(120.0)
    assert rec.segments == []
    assert any("sensors" in note for note in scan.notes)


@pytest.mark.skipif(not FOREIGN.exists(), reason="shared/samples foreign recording absent")
def test_foreign_sample_reads_as_it_is() -> None:
    scan = scan_recording(FOREIGN)
    rec = scan.recording
    assert len(rec.sensors) == 14962
    assert len(rec.mocap["shoulder"]) == 7200
    assert rec.sensor_names == ("F", "SF", "SR", "R")
    assert rec.sensors.values.shape == (14962, 4)
    assert sequence_gaps(rec.sensors.seq).missing == 15000 - 14962
    assert scan.notes == []


# ----------------------------------------------------------------------------- bad files


def test_good_hand_written_file_reads(tmp_path: Path) -> None:
    rec = read_recording(write_sensor_messages(tmp_path / "ok.mcap", [frame(0), frame(2)]))
    np.testing.assert_array_equal(rec.sensors.seq, [0, 2])


@pytest.mark.parametrize(("case", "problem"), sorted(BAD_FILE_CASES.items()))
def test_bad_files_raise_one_clear_error(tmp_path: Path, case: str, problem: str) -> None:
    path = write_bad_file(tmp_path / f"{case}.mcap", case)
    with pytest.raises(RecordingError, match=problem) as info:
        read_recording(path)
    message = str(info.value)
    assert str(path) in message and "\n" not in message


#: A frame that breaks the schema in one way (its body, with the problem the error names).
ONE_BAD_FRAME = {
    "bool value": (b'{"seq": 700, "t": 2.8, "values": [1, true, 3, 4]}',
                   "message 700 violates the v1 schema: 'values' must be a list of numbers"),
    "no values": (b'{"seq": 700, "t": 2.8}',
                  "message 700 violates the v1 schema: 'values' must be a list of numbers"),
    "seq a float": (b'{"seq": 700.0, "t": 2.8, "values": [1, 2, 3, 4]}',
                    "message 700 violates the v1 schema: 'seq' must be an integer"),
    "t a string": (b'{"seq": 700, "t": "2.8", "values": [1, 2, 3, 4]}',
                   "message 700 violates the v1 schema: 't' must be a number"),
    "three values": (b'{"seq": 700, "t": 2.8, "values": [1, 2, 3]}',
                     "frame 700 \\(seq 700\\) has 3 values; metadata lists 4 sensors"),
    "not an object": (b'[700, 2.8, [1, 2, 3, 4]]',
                      "message 700 violates the v1 schema: message is not a JSON object"),
}


@pytest.mark.parametrize("case", sorted(ONE_BAD_FRAME))
def test_one_bad_frame_among_many_is_named(tmp_path: Path, case: str) -> None:
    """The error names the one frame of a thousand that breaks the schema, by its index in
    log-time order."""
    body, problem = ONE_BAD_FRAME[case]
    bodies = [frame(k) for k in range(1000)]
    bodies[700] = body
    with pytest.raises(RecordingError, match=problem):
        read_recording(write_sensor_messages(tmp_path / "one_bad.mcap", bodies))


def _sample(k: int, **angles: object) -> bytes:
    return json.dumps({"t": k / 100, "elv_angle": 10.0 + k, "shoulder_elv": 20, **angles}).encode()


def test_mocap_fields_in_another_order_are_read_by_name(tmp_path: Path) -> None:
    samples = [_sample(k) for k in range(300)]
    samples[200] = b'{"shoulder_elv": 20, "elv_angle": 210.0, "t": 2.0}'
    rec = read_recording(write_sensor_messages(tmp_path / "order.mcap", [frame(0)],
                                               shoulder_bodies=samples))
    shoulder = rec.mocap["shoulder"]
    assert shoulder.names == ("elv_angle", "shoulder_elv")
    np.testing.assert_array_equal(shoulder.angles[:, 0], 10.0 + np.arange(300))
    np.testing.assert_array_equal(shoulder.t, np.arange(300) / 100)


@pytest.mark.parametrize(("sample", "problem"), [
    (_sample(200, shoulder_rot=0.0), "message 200 violates the v1 schema: fields"),
    (_sample(200, shoulder_elv=True), "message 200 violates the v1 schema: angle fields must"),
    (b'{"elv_angle": 210.0, "shoulder_elv": 20}', "message 200 violates the v1 schema: 't'"),
])
def test_one_bad_mocap_sample_among_many_is_named(tmp_path: Path, sample: bytes,
                                                  problem: str) -> None:
    samples = [_sample(k) for k in range(300)]
    samples[200] = sample
    with pytest.raises(RecordingError, match=problem):
        read_recording(write_sensor_messages(tmp_path / "bad_sample.mcap", [frame(0)],
                                             shoulder_bodies=samples))


def test_a_negative_time_is_named_in_seconds(tmp_path: Path) -> None:
    """Another lab's clock that starts at -5 s was refused as 'has time np.float64(-5.0)':
    numpy's repr, and no word on what to do."""
    path = write_bad_file(tmp_path / "negative.mcap", "negative_time")
    with pytest.raises(RecordingError) as info:
        read_recording(path)
    message = str(info.value)
    assert "message 0 has time -1 s; times must be finite and >= 0 s" in message
    assert "np." not in message and "start at 0 or later" in message


def test_missing_file_is_a_recording_error(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match="cannot read"):
        read_recording(tmp_path / "nope.mcap")


def test_writer_refuses_what_the_reader_would_reject(tmp_path: Path) -> None:
    with RecordingWriter(tmp_path / "w.mcap", ("F", "SF")) as writer:
        writer.add_sensor_frame(3, 0.0, [1.0, 2.0])
        with pytest.raises(RecordingError, match="increase strictly"):
            writer.add_sensor_frame(3, 0.004, [1.0, 2.0])
        with pytest.raises(RecordingError, match=r"must be \(1, 2\)"):
            writer.add_sensor_frame(4, 0.004, [1.0])
        with pytest.raises(RecordingError, match="finite"):
            writer.add_sensor_frame(4, 0.004, [1.0, float("nan")])
        with pytest.raises(RecordingError, match="not declared"):
            writer.add_mocap_sample("knee", 0.0, [1.0])
    assert len(read_recording(tmp_path / "w.mcap").sensors) == 1


def test_schemas_are_valid_jsonschema_and_reject_wrong_frames() -> None:
    sensor = sensor_frame_schema(4)
    shoulder = joint_angles_schema("shoulder", SHOULDER_ANGLES)
    for schema in (sensor, shoulder):
        jsonschema.Draft202012Validator.check_schema(schema)
    jsonschema.validate({"seq": 1, "t": 0.004, "values": [1, 2, 3, 4.5]}, sensor)
    for bad in (
        {"seq": 1, "t": 0.004, "values": [1, 2, 3]},
        {"seq": 1.5, "t": 0.004, "values": [1, 2, 3, 4]},
        {"t": 0.004, "values": [1, 2, 3, 4]},
        {"seq": 1, "t": 0.004, "values": [1, 2, "3", 4]},
    ):
        with pytest.raises(jsonschema.ValidationError):
            jsonschema.validate(bad, sensor)
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate({"t": 0.0, "elv_angle": 1.0, "shoulder_elv": 2.0}, shoulder)


@pytest.mark.skipif(not FOREIGN.exists(), reason="shared/samples foreign recording absent")
def test_foreign_messages_follow_the_canonical_schemas() -> None:
    validators = {
        "/suit/sensors": jsonschema.Draft202012Validator(sensor_frame_schema(4)),
        "/mocap/shoulder": jsonschema.Draft202012Validator(
            joint_angles_schema("shoulder", SHOULDER_ANGLES)
        ),
    }
    checked = 0
    with open(FOREIGN, "rb") as stream:
        for _, channel, message in make_reader(stream).iter_messages():
            if checked % 50 == 0:  # a 1-in-50 sample keeps this fast; all kinds are covered
                validators[channel.topic].validate(json.loads(message.data))
            checked += 1
    assert checked == 14962 + 7200


def test_a_file_cut_short_after_its_metadata_reads_what_is_complete(tmp_path: Path) -> None:
    # another lab's writer, killed mid-file: the reader keeps every complete record and says so
    path = tmp_path / "cut.mcap"
    write_raw_recording(path, duration_s=4.0)
    full = scan_recording(path)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    cut = scan_recording(path)
    assert full.lost_bytes is None and cut.lost_bytes is not None and cut.lost_bytes > 0
    assert any(note.startswith("cut short") for note in cut.notes)
    kept = len(cut.recording.sensors)
    assert 0 < kept < len(full.recording.sensors)
    np.testing.assert_array_equal(cut.recording.sensors.seq, full.recording.sensors.seq[:kept])


_FOUR = ["F", "SF", "SR", "R"]


@pytest.mark.parametrize(("act", "said"), [
    (lambda w: w.add_sensor_frames([1, 2, 3], [0.3, 0.2, 0.1], np.zeros((3, 4))),
     "sensor times must not go back"),
    (lambda w: (w.add_sensor_frames([1], [0.3], np.zeros((1, 4))),
                w.add_sensor_frames([2], [0.2], np.zeros((1, 4)))),
     "sensor times must not go back"),
    (lambda w: w.add_sensor_frames([1.5, 2.7], [0.1, 0.2], np.zeros((2, 4))),
     "sensor seq must be a 1-D array of whole numbers"),
    (lambda w: w.add_segment(Segment("a", float("nan"), 1.0)), "finite times, t0 <= t1"),
    (lambda w: w.add_segment(("a", 0.0, 1.0)), "a segment is a Segment(name, t0, t1)"),
    (lambda w: w.add_message(w.add_channel("/est", "x", {}), -1.0, {"a": 1}),
     "times must be finite and >= 0 s"),
])
def test_the_writer_refuses_at_the_call_what_its_reader_would_refuse(tmp_path, act, said):
    """Times going back and a NaN segment were written into files read_recording refuses; a
    tuple for a segment failed at close, leaving the whole recording unreadable; 1.5 was
    stored as seq 1."""
    path = tmp_path / "r.mcap"
    writer = RecordingWriter(path, _FOUR)
    with pytest.raises(RecordingError, match=re.escape(said)):
        act(writer)
    writer.add_sensor_frames([10], [1.0], np.zeros((1, 4)))  # the writer is still usable
    writer.close()
    assert len(read_recording(path).sensors) >= 1


@pytest.mark.parametrize("rate", [0.0, -1.0, float("nan"), float("inf")])
def test_the_writer_refuses_a_rate_its_reader_would_refuse(tmp_path, rate):
    with pytest.raises(RecordingError, match="sensor_rate_hz must be a positive number"):
        RecordingWriter(tmp_path / "r.mcap", _FOUR, sensor_rate_hz=rate)
    assert not (tmp_path / "r.mcap").exists()
