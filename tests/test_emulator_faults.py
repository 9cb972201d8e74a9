"""Fault injection end to end: the emulator's fault log reconciles exactly with what the
acquisition thread delivers over the pty, for every fault kind and random schedules.

The emulator runs faster than real time (several kHz) and the tests synchronise on events
(the reader is attached before streaming begins; the emulator's "finished" event fires once
the host has read everything; the reader waits for the last frame it must receive).
"""

from __future__ import annotations

import contextlib
import os
import termios
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from exohil.emulators.arduino import ArduinoEmulator
from exohil.emulators.fault_spec import load_fault_file, parse_fault_spec, plan_from_dicts
from exohil.emulators.faults import LOSING_KINDS, Corrupt, Disconnect, Drop, FaultRecord, Stall
from exohil.formats.wire import SEQ_MODULUS
from exohil.harness.acquisition import SerialFrameSource
from exohil.harness.frame_source import Frame, LinkStats
from exohil.harness.link_decoder import StreamDecoder

RATE_HZ = 2000.0
WAIT_S = 30.0  # fail-safe bound on event waits only; never a pacing assumption


def _values(n: int, sensors: int = 4) -> np.ndarray:
    k = np.arange(n)[:, None]
    return 300.0 + 100.0 * np.sin(2 * np.pi * k / 400.0 + np.arange(sensors)[None, :])


@dataclass
class Run:
    log: list[FaultRecord]
    generated: list[int]
    delivered: list[Frame]
    stats: LinkStats
    wire_values_mm: np.ndarray
    seq0: int
    t_us0: int
    #: generated seq = host seq + seq_base: the host numbers frames from the first wire seq it
    #: receives, so when the frames before the first wrap of the 16-bit counter are all lost
    #: it cannot know that the counter wrapped before (seq0 65535, frame 65535 lost: the host
    #: sees 0 where the generator counted 65536).
    seq_base: int


def run_emulator(faults: str | list[dict] | None, *, n: int = 400, seed: int = 0,
                 seq0: int = 0, t_us0: int = 0, late_host: bool = False) -> Run:
    """Stream ``n`` frames through the emulator to a SerialFrameSource and collect."""
    plan = plan_from_dicts(faults) if isinstance(faults, list) else faults
    emulator = ArduinoEmulator(_values(n), rate_hz=RATE_HZ, faults=plan, seed=seed, seq0=seq0,
                               t_us0=t_us0, autostart=late_host)
    with emulator:
        source = SerialFrameSource(emulator.port, backoff_initial_s=0.002, backoff_max_s=0.02)
        with source:
            assert source.wait_connected(WAIT_S)
            emulator.begin()
            assert emulator.wait_finished(WAIT_S)
            assert emulator.error is None
            log = emulator.fault_log
            lost = {r.seq for r in log if r.kind in LOSING_KINDS}
            kept = [s for s in range(seq0, seq0 + n) if s not in lost]
            expected_last = kept[-1] if kept else None
            base = SEQ_MODULUS * (kept[0] // SEQ_MODULUS) if kept else 0
            delivered: list[Frame] = []
            while expected_last is not None and (
                    not delivered or delivered[-1].seq + base < expected_last):
                frame = source.get(timeout=WAIT_S)
                assert frame is not None, "the reader stalled before the last intact frame"
                delivered.append(frame)
            stats = source.stats()
        return Run(log, list(range(seq0, seq0 + n)), delivered, stats,
                   emulator.wire_values_mm, seq0, t_us0, base)


def assert_reconciles(run: Run) -> None:
    """delivered + lost == generated, exactly as logged; nothing bad or stale delivered."""
    lost = {r.seq for r in run.log if r.kind in LOSING_KINDS}
    assert lost <= set(run.generated)
    expected = [s for s in run.generated if s not in lost]
    assert expected, "every frame was lost; the schedule tests nothing"
    got = [f.seq + run.seq_base for f in run.delivered]
    assert got == expected  # the host lost none that arrived intact, and invented none
    assert len(got) + len(lost) == len(run.generated)
    assert run.stats.frames == len(got)
    assert run.stats.dropped == sum(1 for s in lost if got[0] < s < got[-1])
    assert run.stats.overflow == 0
    for frame in run.delivered:  # payload and timestamp exactly as sent: no bad frame passed
        k = frame.seq + run.seq_base - run.seq0
        np.testing.assert_allclose(frame.values_mm, run.wire_values_mm[k % len(run.wire_values_mm)],
                                   atol=1e-9)
        assert frame.device_time_s == pytest.approx((run.t_us0 + round(k * 1e6 / RATE_HZ)) / 1e6)


def kinds(run: Run) -> dict[str, int]:
    out: dict[str, int] = {}
    for record in run.log:
        out[record.kind] = out.get(record.kind, 0) + 1
    return out


# ---- one test per fault kind ---------------------------------------------------------------


def test_no_faults_delivers_everything_across_both_wraps() -> None:
    run = run_emulator(None, n=300, seq0=65536 - 100, t_us0=2**32 - 40_000)
    assert_reconciles(run)
    assert [f.seq for f in run.delivered] == run.generated
    assert run.log == []


def test_drop_bursts() -> None:
    run = run_emulator("drop:rate=0.03,burst=4", seed=1)
    assert_reconciles(run)
    drops = [r for r in run.log if r.kind == "drop"]
    assert sum(1 for r in drops if r.details.get("burst_start")) >= 2
    assert run.stats.dropped >= 4


def test_corrupt_bytes_are_all_caught() -> None:
    run = run_emulator("corrupt:rate=0.05", seed=2)
    assert_reconciles(run)
    assert kinds(run)["corrupt"] >= 5
    assert run.stats.crc_errors + run.stats.decode_errors >= kinds(run)["corrupt"]


def test_truncated_frames_are_all_caught() -> None:
    run = run_emulator("truncate:rate=0.05", seed=3)
    assert_reconciles(run)
    assert kinds(run)["truncate"] >= 5
    assert run.stats.decode_errors + run.stats.crc_errors >= kinds(run)["truncate"]


def test_stall_then_burst_loses_nothing() -> None:
    run = run_emulator("stall:every_s=0.05,duration_ms=10", n=500)
    assert_reconciles(run)
    stalls = [r for r in run.log if r.kind == "stall"]
    assert len(stalls) == 4 and all(r.details["frames_held"] == 20 for r in stalls)
    assert [f.seq for f in run.delivered] == run.generated


def test_disconnect_and_reconnect() -> None:
    run = run_emulator("disconnect:at_s=0.08,for_s=0.02", n=600)
    assert_reconciles(run)
    outage = [r.seq for r in run.log if r.kind == "disconnect" and "at_s" in r.details]
    assert outage == list(range(160, 200))
    assert run.stats.reconnects == 1
    assert run.delivered[-1].seq == run.generated[-1]


def test_host_opening_late_loses_only_logged_frames() -> None:
    run = run_emulator(None, n=600, late_host=True)
    assert_reconciles(run)
    reasons = {r.details["reason"] for r in run.log if r.kind == "not_read"}
    assert reasons <= {"no host", "host attaching"}


@pytest.mark.parametrize(
    "spec",
    ["noise:sigma_mm=0.5", "creep:gain=0.2,tau_build_s=0.05,tau_recover_s=0.1",
     "drift:rate_mm_per_s=20"])
def test_value_effects_change_values_and_lose_nothing(spec: str) -> None:
    run = run_emulator(spec, seed=4)
    assert_reconciles(run)
    clean = np.rint(_values(400) / 0.01) * 0.01
    assert np.abs(run.wire_values_mm - clean).max() > 0.05
    assert kinds(run) == {"effect": 1}


def test_dropout_effect_drops_logged_frames() -> None:
    run = run_emulator("dropout:rate=0.05,mean_burst_frames=2", seed=5)
    assert_reconciles(run)
    assert any(r.details.get("effect") == "dropout" for r in run.log if r.kind == "drop")


# ---- random schedules ----------------------------------------------------------------------

fault_dicts = st.one_of(
    st.fixed_dictionaries({"kind": st.just("drop"), "rate": st.floats(0, 0.2),
                           "burst": st.integers(1, 5)}),
    st.fixed_dictionaries({"kind": st.just("corrupt"), "rate": st.floats(0, 0.2)}),
    st.fixed_dictionaries({"kind": st.just("truncate"), "rate": st.floats(0, 0.2)}),
    st.fixed_dictionaries({"kind": st.just("stall"), "every_s": st.floats(0.03, 0.1),
                           "duration_ms": st.floats(1, 20)}),
    st.fixed_dictionaries({"kind": st.just("disconnect"), "at_s": st.floats(0.01, 0.12),
                           "for_s": st.floats(0.002, 0.03)}),
    st.fixed_dictionaries({"kind": st.just("noise"), "sigma_mm": st.floats(0, 2)}),
    st.fixed_dictionaries({"kind": st.just("creep"), "gain": st.floats(-0.2, 0.2),
                           "tau_build_s": st.floats(0.01, 1.0)}),
    # rates far below 1/frames make effects.Dropout allocate run lengths ~1/rate (reported)
    st.fixed_dictionaries({"kind": st.just("dropout"),
                           "rate": st.one_of(st.just(0.0), st.floats(0.001, 0.1))}),
)


# Each example streams 300-700 frames through a real pty (~0.3 s); 25 examples cover
# combinations of all kinds, the per-kind tests above cover each kind on its own.
@settings(max_examples=25, deadline=None)
@given(faults=st.lists(fault_dicts, max_size=4), seed=st.integers(0, 2**31),
       n=st.integers(300, 700), seq0=st.integers(0, 65535))
@example(faults=[{"kind": "corrupt", "rate": 0.0}, {"kind": "truncate", "rate": 0.0},
                 {"kind": "truncate", "rate": 0.1953125}], seed=38733, n=300, seq0=65535)
def test_random_fault_schedules_reconcile(faults: list[dict], seed: int, n: int,
                                          seq0: int) -> None:
    run = run_emulator(faults, n=n, seed=seed, seq0=seq0, t_us0=2**32 - 100_000)
    assert_reconciles(run)


# ---- plans, determinism --------------------------------------------------------------------


def test_spec_string_and_toml_give_the_same_plan(tmp_path) -> None:
    spec = ("noise:sigma_mm=0.5/0.5/1/1;drop:rate=0.01,burst=3;corrupt:rate=0.001;"
            "stall:every_s=5,duration_ms=40;disconnect:at_s=10,for_s=0.5")
    toml = tmp_path / "faults.toml"
    toml.write_text(
        '[[fault]]\nkind = "noise"\nsigma_mm = [0.5, 0.5, 1, 1]\n'
        '[[fault]]\nkind = "drop"\nrate = 0.01\nburst = 3\n'
        '[[fault]]\nkind = "corrupt"\nrate = 0.001\n'
        '[[fault]]\nkind = "stall"\nevery_s = 5\nduration_ms = 40\n'
        '[[fault]]\nkind = "disconnect"\nat_s = 10\nfor_s = 0.5\n')
    from_spec, from_toml = parse_fault_spec(spec), load_fault_file(toml)
    assert from_spec == from_toml
    assert from_spec.frame_faults == [Drop(0.01, 3), Corrupt(0.001), Stall(5, 40),
                                      Disconnect(10, 0.5)]
    assert [e.name for e in from_spec.value_effects] == ["noise"]


@pytest.mark.parametrize(("text", "problem"), [
    ('[[faults]]\nkind = "drop"\nrate = 0.5\n', "unknown top-level key(s) 'faults'"),
    ('rate = 0.5\n[[fault]]\nkind = "drop"\n', "unknown top-level key(s) 'rate'"),
    ('[[fault]]\nkind = "drop"\nrat = 0.5\n', "drop: unknown parameter(s) rat"),
    ('[[fault]]\nkind = "noise"\nsigma = 0.5\n', "noise: unknown parameter(s) sigma"),
])
def test_a_fault_file_with_a_misspelled_name_is_refused(tmp_path, text: str,
                                                        problem: str) -> None:
    """`[[faults]]` (for `[[fault]]`) ran with no fault at all and no error."""
    path = tmp_path / "faults.toml"
    path.write_text(text)
    with pytest.raises(ValueError) as err:
        load_fault_file(path)
    assert problem in str(err.value)


@pytest.mark.parametrize("bad", ["drop:rate=2", "warp:speed=9", "drop:rate", "drop:rat=0.1",
                                 "stall:every_s=1,duration_ms=2000", "noise:sigma_mm=-1",
                                 "drop:rate=abc", "noise:sigma_mm=1/x",
                                 # non-finite or huge numbers (issue 13)
                                 "drop:rate=nan", "drop:burst=inf", "drop:burst=1e400",
                                 "stall:every_s=-inf", "disconnect:at_s=1e10",
                                 "noise:sigma_mm=nan", "lag:clock_offset_s=-inf",
                                 "noise:sigma_mm=1/nan", "hysteresis:operators=1e9",
                                 "drop:rate=true"])
def test_bad_specs_raise_value_error_naming_the_problem(bad: str) -> None:
    with pytest.raises(ValueError, match=bad.split(":")[0]):
        parse_fault_spec(bad)


def _offline_log(spec: str, seed: int) -> list[FaultRecord]:
    """Run without any host (nothing is read) and keep the seeded faults only."""
    with ArduinoEmulator(_values(300), rate_hz=20000.0, faults=spec, seed=seed) as emulator:
        assert emulator.wait_finished(WAIT_S)
        return [r for r in emulator.fault_log if r.kind != "not_read"]


def test_fault_log_is_seeded_and_adding_a_fault_does_not_reseed_others() -> None:
    base = _offline_log("drop:rate=0.05,burst=2;corrupt:rate=0.05", seed=9)
    assert base == _offline_log("drop:rate=0.05,burst=2;corrupt:rate=0.05", seed=9)
    assert base != _offline_log("drop:rate=0.05,burst=2;corrupt:rate=0.05", seed=10)
    with_truncate = _offline_log("drop:rate=0.05,burst=2;corrupt:rate=0.05;truncate:rate=0.1",
                                 seed=9)
    drops = [r.seq for r in base if r.kind == "drop"]
    assert drops and drops == [r.seq for r in with_truncate if r.kind == "drop"]


@contextlib.contextmanager
def _finished_unread(emulator: ArduinoEmulator) -> Iterator[int]:
    """A host that opens the port and flushes it ("ready", as pyserial's open() does), then
    reads nothing while the whole stream runs: yields its fd once the stream has finished."""
    fd = os.open(emulator.port, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    try:
        termios.tcflush(fd, termios.TCIFLUSH)
        emulator.begin()
        assert emulator.wait_finished(WAIT_S)
        yield fd
    finally:
        os.close(fd)


def test_a_host_that_does_not_read_fills_the_buffer_and_frames_are_logged_not_read() -> None:
    """The pty fills up (~20 KiB); the emulator neither blocks nor dies, it logs the frames it
    could not hand over, and everything it did hand over reaches the host intact later."""
    n = 3000
    emulator = ArduinoEmulator(_values(n), rate_hz=20000.0, autostart=False, drain_timeout_s=0.05)
    with emulator, _finished_unread(emulator) as fd:
        log = emulator.fault_log
        full = [r.seq for r in log if r.kind == "not_read"]
        assert full and all(r.details["reason"] == "buffer full"
                            for r in log if r.kind == "not_read")
        expected = [s for s in range(n) if s not in set(full)]
        stats = LinkStats()
        decoder = StreamDecoder(stats)
        got: list[int] = []
        for _ in range(100_000):  # bounded; ends once the last written frame is decoded
            if got and got[-1] == expected[-1]:
                break
            try:
                chunk = os.read(fd, 65536)
            except BlockingIOError:
                os.sched_yield()
                continue
            got += [f.seq % SEQ_MODULUS for f in decoder.feed(chunk, host_ns=0)]
    assert got == expected
    assert stats.crc_errors == 0 and stats.decode_errors == 0


def test_frames_a_host_has_not_read_when_the_port_closes_are_logged() -> None:
    """The port stays up after the stream until stop(); what the host has not read then is
    lost as the port closes, and logged ``not_read`` (reason ``port closed``): every frame
    generated is decoded by the host or in the log, never both, with far more unread than
    the 4 KiB the line discipline's FIONREAD counts (the old count, which logged nothing
    here)."""
    n = 3000
    emulator = ArduinoEmulator(_values(n), rate_hz=20000.0, autostart=False, drain_timeout_s=0.05)
    stream = bytearray()
    with emulator, _finished_unread(emulator) as fd:
        stream += os.read(fd, 3001)  # a little, ending inside a frame
        emulator.stop()
        try:
            stream += os.read(fd, 65536)
        except OSError:  # EIO: the port is gone
            pass
    log = emulator.fault_log
    stats = LinkStats()
    decoded = [f.seq for f in StreamDecoder(stats).feed(bytes(stream), host_ns=0)]
    lost = [r.seq for r in log if r.kind in LOSING_KINDS]
    assert sorted(decoded + lost) == list(range(n))
    closed = [r for r in log if r.details.get("reason") == "port closed"]
    written = emulator.bytes_written // emulator.frames_written  # bytes a frame
    assert len(closed) * written > 4096
    assert [r.seq for r in closed] == list(range(closed[0].seq, closed[0].seq + len(closed)))
    assert closed[0].seq == decoded[-1] + 1 and stats.crc_errors == 0


def test_a_disconnect_logs_every_frame_a_host_far_behind_had_not_read() -> None:
    """The port vanishing mid-stream under a host that reads nothing: the frames in the pty
    (about 18 KiB, far more than FIONREAD's 4 KiB) are logged ``disconnect`` in flight, so
    the log names every frame generated, the host having decoded none."""
    n = 2000
    emulator = ArduinoEmulator(_values(n), rate_hz=20000.0, autostart=False,
                               drain_timeout_s=0.02, faults="disconnect:at_s=0.05,for_s=0.01")
    with emulator, _finished_unread(emulator):
        pass
    log = emulator.fault_log
    assert sorted(r.seq for r in log if r.kind in LOSING_KINDS) == list(range(n))
    in_flight = [r.seq for r in log if r.details.get("in_flight")]
    assert len(in_flight) * (emulator.bytes_written // emulator.frames_written) > 4096


def test_frames_taken_around_a_host_still_reading_are_told_apart_exactly() -> None:
    """The port emptied while the host still reads: the emulator takes piece A, the host
    reads the next 120 bytes, the emulator takes piece B to the end. Logged are exactly the
    frames with a byte in A or B (and a frame whose tail was never written), not those the
    host read whole between them; a count from the end would log the wrong ones."""
    from exohil.emulators.arduino import _frames_not_received
    from exohil.formats.wire import WireFrame, encode_frame

    recent = [(seq, encode_frame(WireFrame(seq, seq * 500, (seq, 2 * seq, 3, 4))))
              for seq in range(100, 160)]
    stream = b"".join(data for _, data in recent)
    starts = np.cumsum([0] + [len(data) for _, data in recent])
    read_before, stolen = 523, 120  # the host read 523 bytes, then 120 between A and B
    a_end = read_before + 200
    pieces = [stream[read_before:a_end], stream[a_end + stolen:]]

    def overlapping(lo: int, hi: int) -> set[int]:
        return {recent[k][0] for k in range(len(recent)) if starts[k] < hi and starts[k + 1] > lo}

    expected = overlapping(read_before, a_end) | overlapping(a_end + stolen, len(stream))
    assert _frames_not_received(recent, pieces, 0) == sorted(expected)
    host_whole = {recent[k][0] for k in range(len(recent))
                  if starts[k] >= a_end and starts[k + 1] <= a_end + stolen}
    assert host_whole and not host_whole & expected  # frames the host read whole: not lost
    # the last frame's final 7 bytes never written: it is lost however the rest was read
    cut = _frames_not_received(recent, [stream[read_before:len(stream) - 7]], 7)
    assert cut == sorted(overlapping(read_before, len(stream)))
    assert _frames_not_received(recent, [], 0) == []


class _SlowHost(threading.Thread):
    """A host that reads ``chunk`` bytes every ``pause_s``, reopening the port whenever it
    vanishes (flushing it on open, as pyserial does), until told to stop: the bytes of each
    connection, apart (a frame cut by a disconnect must not run into the next one's)."""

    def __init__(self, path: str, chunk: int, pause_s: float) -> None:
        super().__init__(daemon=True)
        self.path, self.chunk, self.pause_s = path, chunk, pause_s
        self.connections: list[bytearray] = []
        self.attached = threading.Event()
        self.done = threading.Event()

    def run(self) -> None:
        while not self.done.is_set():
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
            except OSError:  # vanished: wait for it to come back
                time.sleep(0.001)
                continue
            termios.tcflush(fd, termios.TCIFLUSH)
            self.connections.append(bytearray())
            self.attached.set()
            try:
                while not self.done.is_set():
                    try:
                        data = os.read(fd, self.chunk)
                    except BlockingIOError:  # nothing yet
                        time.sleep(self.pause_s)
                        continue
                    except OSError:  # EIO: the port vanished
                        break
                    if not data:  # hung up
                        break
                    self.connections[-1] += data
                    time.sleep(self.pause_s)
            finally:
                os.close(fd)


@pytest.mark.parametrize("chunk, pause_s, faults", [
    (4096, 0.001, None),  # mostly keeps up
    (400, 0.01, None),  # far behind: the pty fills, the rest is unread at the end
    (300, 0.005, "disconnect:at_s=0.05,for_s=0.02"),  # behind when the port vanishes
    (2000, 0.02, "disconnect:at_s=0.05,for_s=0.02;stall:every_s=0.04,duration_ms=5"),
])
def test_every_frame_is_decoded_or_logged_however_slowly_the_host_reads(
        chunk: int, pause_s: float, faults: str | None) -> None:
    """Whatever share of the stream a host reads, each frame generated is decoded by it or
    in the fault log, never both: frames refused while the pty is full, lost when the port
    vanishes under a host that is behind, sent while it reopens the port, and left unread
    when the emulator stops."""
    n = 4000
    emulator = ArduinoEmulator(_values(n), rate_hz=20000.0, autostart=False,
                               drain_timeout_s=0.02, faults=faults)
    with emulator:
        host = _SlowHost(emulator.port, chunk, pause_s)
        host.start()
        assert host.attached.wait(WAIT_S)
        emulator.begin()
        assert emulator.wait_finished(WAIT_S)
        emulator.stop()
        host.done.set()
        host.join(WAIT_S)
    decoded = [f.seq for stream in host.connections
               for f in StreamDecoder(LinkStats()).feed(bytes(stream), host_ns=0)]
    lost = [r.seq for r in emulator.fault_log if r.kind in LOSING_KINDS]
    assert sorted(decoded + lost) == list(range(n))
    assert decoded  # the host read something: the check is not all log
    assert emulator.frames_read == len(decoded)


def test_a_stream_begun_when_attached_waits_for_a_host():
    """``begin(when_attached=True)`` starts the device clock once a host has the port open:
    a session that took longer to open it than a fault's ``at_s`` never met the fault."""
    import time

    import serial

    with ArduinoEmulator(_values(10_000), autostart=False) as emulator:
        emulator.begin(when_attached=True)
        time.sleep(0.3)
        assert emulator.frames_generated == 0  # no host yet: nothing streamed
        with serial.Serial(emulator.port, timeout=2.0) as port:
            data = port.read(200)
        assert emulator.frames_generated > 0 and data
