"""The acquisition thread (harness/acquisition.py) against loop://, fakes and the emulator:
same code for every link, bounded buffer, clean shutdown in every state."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
import serial

from exohil.emulators.arduino import ArduinoEmulator
from exohil.formats.recording import Recording, SensorStream
from exohil.formats.wire import WireFrame, encode_frame
from exohil.harness.acquisition import SerialFrameSource
from exohil.harness.frame_buffer import FrameBuffer
from exohil.harness.frame_source import Frame, FrameSource

WAIT_S = 30.0  # fail-safe bound on event waits; the tests never rely on it for pacing


def _frames(seqs: range, sensors: int = 4) -> bytes:
    return b"".join(encode_frame(WireFrame(s % 65536, s * 4000 % 2**32,
                                           tuple(range(s % 100, s % 100 + sensors))))
                    for s in seqs)


def _loop_source(**kwargs) -> tuple[SerialFrameSource, serial.SerialBase]:
    """A source reading a loop:// port that the test writes into."""
    port = serial.serial_for_url("loop://", timeout=0.02)
    return SerialFrameSource("loop://", opener=lambda url, timeout: port, **kwargs), port


def _collect(source: SerialFrameSource, count: int) -> list[Frame]:
    out = []
    for _ in range(count):
        frame = source.get(timeout=WAIT_S)
        assert frame is not None
        out.append(frame)
    return out


def test_serial_source_is_a_frame_source() -> None:
    source, _ = _loop_source()
    assert isinstance(source, FrameSource)


def test_loop_url_frames_garbage_and_gaps() -> None:
    source, port = _loop_source()
    with source:
        assert source.wait_connected(WAIT_S)
        chunks = [b"\x13\x37garbage-before-sync\x00" + _frames(range(0, 10)),
                  _frames(range(12, 20))[:-5] + b"\x00" + _frames(range(25, 30))]
        for chunk in chunks:
            port.write(chunk)
        got = _collect(source, 10 + 7 + 5)
        stats = source.stats()
    seqs = [f.seq for f in got]
    assert seqs == [*range(0, 10), *range(12, 19), *range(25, 30)]
    assert stats.frames == 22 and stats.dropped == 2 + 6
    assert stats.resyncs == 2 and stats.crc_errors + stats.decode_errors == 2
    assert stats.bytes_read == sum(len(c) for c in chunks)
    assert got[3].values_mm.dtype == np.float64
    np.testing.assert_allclose(got[3].values_mm, [0.03, 0.04, 0.05, 0.06])
    assert all(a.host_ns <= b.host_ns for a, b in zip(got, got[1:], strict=False))


def test_expected_sensor_count_rejects_other_frames() -> None:
    source, port = _loop_source(expected_sensors=4)
    with source:
        assert source.wait_connected(WAIT_S)
        port.write(_frames(range(0, 3), sensors=3) + _frames(range(3, 5)))
        got = _collect(source, 2)
        stats = source.stats()
    assert [f.seq for f in got] == [3, 4]
    assert stats.decode_errors == 3


def test_full_buffer_drops_oldest_and_counts_overflow() -> None:
    source, port = _loop_source(buffer_frames=5)
    with source:
        assert source.wait_connected(WAIT_S)
        done = threading.Event()
        original_put = source._buffer.put

        def put_and_signal(frames):  # wake the test once all 20 frames are buffered
            evicted = original_put(frames)
            if frames and frames[-1].seq == 19:
                done.set()
            return evicted

        source._buffer.put = put_and_signal
        port.write(_frames(range(20)))
        assert done.wait(WAIT_S)
        got = _collect(source, 5)
        stats = source.stats()
    assert [f.seq for f in got] == list(range(15, 20))
    assert stats.overflow == 15 and stats.frames == 20


def test_frame_buffer_never_blocks_and_times_out_empty() -> None:
    buffer = FrameBuffer(2)
    frame = Frame(0, 0.0, np.zeros(1), 0)
    assert buffer.put([frame, frame, frame]) == 1
    assert len(buffer) == 2
    assert buffer.get(0) is frame and buffer.get(0) is frame
    assert buffer.get(0) is None
    with pytest.raises(ValueError):
        FrameBuffer(0)


# ---- shutdown in every state ---------------------------------------------------------------


def test_stop_while_the_emulator_streams() -> None:
    values = np.full((100, 4), 250.0)
    with ArduinoEmulator(values, rate_hz=250.0, loop=True) as emulator:
        source = SerialFrameSource(emulator.port)
        source.start()
        assert source.get(timeout=WAIT_S) is not None  # streaming reached the host
        source.stop(timeout_s=2.0)
        assert not source.alive
    assert emulator.error is None


def test_stop_while_the_port_does_not_exist(tmp_path) -> None:
    source = SerialFrameSource(str(tmp_path / "no-such-tty"), backoff_max_s=5.0)
    attempts = threading.Event()
    source._opener = lambda url, timeout: (attempts.set(), serial.serial_for_url(url))[1]
    source.start()
    assert attempts.wait(WAIT_S)
    source.stop(timeout_s=2.0)  # wakes the backoff wait at once
    assert not source.alive and not source.connected
    assert "no-such-tty" in (source.last_error or "")


def test_stop_during_an_emulated_disconnect_and_the_host_reconnects() -> None:
    values = np.full((100, 4), 250.0)
    emulator = ArduinoEmulator(values, rate_hz=1000.0, loop=True,
                               faults="disconnect:at_s=0.05,for_s=0.1", autostart=False)
    with emulator:
        source = SerialFrameSource(emulator.port, backoff_initial_s=0.002, backoff_max_s=0.01)
        with source:
            assert source.wait_connected(WAIT_S)
            emulator.begin()
            seqs = []
            while not seqs or seqs[-1] < 200:  # frames after the outage ended (k >= 150)
                frame = source.get(timeout=WAIT_S)
                assert frame is not None
                seqs.append(frame.seq)
            assert source.stats().reconnects == 1
            assert not any(50 <= s < 150 for s in seqs)
        assert not source.alive
    assert emulator.error is None


def test_stop_while_the_port_vanished() -> None:
    values = np.full((100, 4), 250.0)
    emulator = ArduinoEmulator(values, rate_hz=1000.0, loop=True,
                               faults="disconnect:at_s=0.01,for_s=600", autostart=False)
    with emulator:
        source = SerialFrameSource(emulator.port, backoff_max_s=5.0)
        source.start()
        assert source.wait_connected(WAIT_S)
        emulator.begin()
        for _ in range(int(WAIT_S / 0.05)):  # until the port has vanished under the reader
            if not source.connected:
                break
            source.get(timeout=0.05)
        assert not source.connected
        source.stop(timeout_s=2.0)
        assert not source.alive


def test_host_may_close_and_reopen_while_the_emulator_streams() -> None:
    values = np.full((100, 4), 250.0)
    with ArduinoEmulator(values, rate_hz=1000.0, loop=True) as emulator:
        last_seqs = []
        for _ in range(2):
            with SerialFrameSource(emulator.port) as source:
                frame = source.get(timeout=WAIT_S)
                assert frame is not None
                last_seqs.append(emulator.frames_generated)
        assert last_seqs[1] > last_seqs[0]
        assert emulator.error is None and not emulator.finished
        reasons = {r.details.get("reason") for r in emulator.fault_log if r.kind == "not_read"}
        assert reasons <= {"no host", "host attaching", "host closed the port"}


def test_emulator_takes_a_recording_and_stops_between_slow_frames() -> None:
    k = np.arange(5)
    rec = Recording(("F", "SF", "SR", "R"), SensorStream(k, k / 250.0, np.full((5, 4), 123.45)))
    emulator = ArduinoEmulator(rec, rate_hz=0.01)  # next frame due in 100 s
    emulator.start()
    emulator.stop(timeout_s=5.0)  # wakes the pacing wait
    assert emulator.finished and emulator.error is None
    assert emulator.frames_generated <= 1  # frame 0 is due at once, frame 1 never came
    np.testing.assert_allclose(emulator.wire_values_mm, 123.45)


@pytest.mark.parametrize(("kwargs", "said"), [
    ({"url": None}, "url must be a device path or a pyserial URL"),
    ({"url": "loop://", "read_timeout_s": None}, "read_timeout_s must be a finite number"),
    ({"url": "loop://", "read_timeout_s": -1.0}, "read_timeout_s must be a finite number"),
    ({"url": "loop://", "backoff_initial_s": 0.0}, "backoff_initial_s must be a finite number"),
])
def test_a_source_refuses_settings_it_cannot_run_with(kwargs, said):
    """read_timeout_s=None left the reader thread running after stop(); url=None crashed the
    thread with a TypeError."""
    url = kwargs.pop("url")
    with pytest.raises(ValueError, match=said):
        SerialFrameSource(url, **kwargs)


def test_a_url_pyserial_can_never_open_ends_the_reader_and_a_source_runs_once():
    """'bogus://x' was retried for ever with alive True; start() after stop() did nothing."""
    source = SerialFrameSource("bogus://x")
    source.start()
    deadline = time.monotonic() + 5.0
    while source.alive and time.monotonic() < deadline:
        time.sleep(0.01)
    assert not source.alive and "bogus" in (source.last_error or "")
    source.stop()
    with pytest.raises(RuntimeError, match="a source runs once"):
        source.start()
    unstarted = SerialFrameSource("loop://")
    unstarted.stop()
    with pytest.raises(RuntimeError, match="a source runs once"):
        unstarted.start()


def test_an_emulator_refuses_what_the_wire_cannot_carry_and_runs_once(tmp_path, monkeypatch):
    """NaN went out as 0 mm (only a counter said so); duration_s=nan failed inside int();
    an emulator never started left its /tmp folder; a second start() failed on a missing
    pty link."""
    import gc
    import tempfile

    with pytest.raises(ValueError, match="frame 0, sensor 0 is nan"):
        ArduinoEmulator(np.array([[np.nan, 1.0, 2.0, 3.0]] * 10))
    for bad in (float("nan"), float("inf"), 0.0):
        with pytest.raises(ValueError, match="duration_s must be a finite number"):
            ArduinoEmulator(np.ones((10, 4)), duration_s=bad, loop=True)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    never = ArduinoEmulator(np.ones((10, 4)))
    assert list(tmp_path.iterdir())  # its link folder
    del never
    gc.collect()
    assert list(tmp_path.iterdir()) == []
    used = ArduinoEmulator(np.ones((10, 4)))
    used.start()
    used.stop()
    with pytest.raises(RuntimeError, match="an emulator runs once"):
        used.start()
    assert list(tmp_path.iterdir()) == []


def test_waiting_on_an_emulator_never_started_is_an_error_not_a_hang():
    emulator = ArduinoEmulator(np.ones((10, 4)), autostart=False)
    with pytest.raises(RuntimeError, match="never started"):
        emulator.wait_finished(None)
    emulator.stop()
