"""Link sanity (harness/link_decoder.py): a valid-CRC frame whose sequence number or device time
does not fit the stream is counted and dropped, never taken as a wrap; long genuine gaps and
device resets are still followed. Pure decoder tests, no I/O."""

from __future__ import annotations

import numpy as np
import pytest

from exohil.formats.wire import SEQ_MODULUS, TIME_MODULUS_US, WireFrame, encode_frame
from exohil.harness.frame_source import Frame, LinkStats
from exohil.harness.link_decoder import RESYNC_FRAMES, StreamDecoder

PERIOD_US = 4000  # 250 Hz


def wire(seq: int, t_us: int | None = None, value: int = 100) -> bytes:
    """The encoded frame ``seq`` of a 250 Hz device (time follows seq unless given)."""
    t = seq * PERIOD_US if t_us is None else t_us
    return encode_frame(WireFrame(seq % SEQ_MODULUS, t % TIME_MODULUS_US, (value, value + 1)))


def decode(*chunks: bytes, host_ns: list[int] | None = None) -> tuple[list[Frame], LinkStats]:
    stats = LinkStats()
    decoder = StreamDecoder(stats)
    out: list[Frame] = []
    for i, chunk in enumerate(chunks):
        out += decoder.feed(chunk, host_ns=0 if host_ns is None else host_ns[i])
    return out, stats


def stream(seqs: range | list[int]) -> bytes:
    return b"".join(wire(s) for s in seqs)


def test_a_stale_frame_is_dropped_not_taken_as_a_wrap() -> None:
    stale = wire(105) + wire(104, t_us=104 * PERIOD_US + 7)
    got, stats = decode(stream(range(100, 110)) + stale + stream(range(110, 115)))
    assert [f.seq for f in got] == [*range(100, 115)]
    assert got[-1].device_time_s == pytest.approx(114 * PERIOD_US / 1e6)
    assert stats.implausible == 1 and stats.duplicates == 1  # 105 is an exact repeat
    assert stats.dropped == 0


@pytest.mark.parametrize("seq_ahead", [8, 500, 30_000, 65_535])
def test_a_far_ahead_sequence_number_with_the_current_time_is_dropped(seq_ahead: int) -> None:
    """A header whose seq jumped but whose time advanced one period (e.g. a corrupt header
    that passed the CRC) disagrees with itself (by more than the jitter allowance)."""
    bogus = wire(109 + seq_ahead, t_us=110 * PERIOD_US)
    got, stats = decode(stream(range(0, 110)) + bogus + stream(range(111, 120)))
    assert [f.seq for f in got] == [*range(0, 110), *range(111, 120)]
    assert stats.implausible == 1 and stats.dropped == 1


def test_a_frame_from_the_future_in_time_is_dropped() -> None:
    bogus = wire(110, t_us=110 * PERIOD_US + 600_000_000)  # seq fits, time 10 min ahead
    got, stats = decode(stream(range(100, 110)) + bogus + stream(range(111, 120)))
    assert [f.seq for f in got] == [*range(100, 110), *range(111, 120)]
    assert stats.implausible == 1


def test_a_long_genuine_gap_is_accepted_and_counted() -> None:
    """A 10 s disconnect: seq and time agree, so the gap is real."""
    got, stats = decode(stream(range(0, 50)) + stream(range(2550, 2560)))
    assert [f.seq for f in got] == [*range(0, 50), *range(2550, 2560)]
    assert stats.dropped == 2500 and stats.implausible == 0
    assert got[-1].device_time_s == pytest.approx(2559 * PERIOD_US / 1e6)


def test_a_gap_past_the_sequence_wrap_is_unwrapped_by_device_time() -> None:
    """A 300 s outage (75,000 frames > 65,536): the u16 seq aliases, the u32 time does not;
    the host clock confirms the time passed."""
    after = range(75_050, 75_060)
    got, stats = decode(stream(range(0, 50)), stream(after), host_ns=[0, 300 * 10**9])
    assert [f.seq for f in got] == [*range(0, 50), *after]
    assert stats.dropped == 75_000


def test_an_aliased_gap_the_host_clock_did_not_see_is_refused() -> None:
    got, stats = decode(stream(range(0, 50)) + wire(75_050), host_ns=[0])
    assert [f.seq for f in got] == [*range(0, 50)]
    assert stats.implausible == 0 and stats.dropped == 0
    # held as the start of a possible new numbering, not delivered
    _, stats2 = decode(stream(range(0, 50)) + wire(75_050) + wire(50))
    assert stats2.implausible == 1


def test_both_wraps_in_one_stream_do_not_disturb_the_rule() -> None:
    seqs = [*range(65_530, 65_536), *range(65_536, 65_545)]
    t0 = TIME_MODULUS_US - 5 * PERIOD_US - PERIOD_US * 65_530
    got, stats = decode(b"".join(wire(s, t_us=t0 + s * PERIOD_US) for s in seqs))
    assert [f.seq for f in got] == seqs
    np.testing.assert_allclose(np.diff([f.device_time_s for f in got]), PERIOD_US / 1e6)
    assert stats.implausible == 0


def test_a_device_reset_is_followed_after_consistent_frames() -> None:
    """Both counters restart: the host takes the new numbering after RESYNC_FRAMES
    consistent frames, delivers them, and keeps its own numbering increasing."""
    before = stream(range(5000, 5100))
    after = b"".join(wire(s, t_us=1_000_000 + s * PERIOD_US, value=7) for s in range(0, 20))
    got, stats = decode(before, after, host_ns=[0, 2 * 10**9])
    assert len(got) == 120
    assert stats.sequence_resets == 1 and stats.implausible == 0
    seqs = [f.seq for f in got]
    times = [f.device_time_s for f in got]
    assert all(np.diff(seqs) == 1) and all(np.diff(times) > 0)
    assert times[100] - times[99] == pytest.approx(2.0)  # the host saw 2 s pass
    np.testing.assert_allclose(np.diff(times[100:]), PERIOD_US / 1e6)
    assert all(f.values_mm[0] == pytest.approx(0.07) for f in got[100:])


def test_the_frames_a_reboot_missed_are_counted_by_host_time() -> None:
    """A reboot restarts the numbering, so no sequence gap shows the frames the device did
    not send meanwhile: the host's clock at the device's period does (2 s at 250 Hz, less
    the one frame period between any two frames)."""
    before = stream(range(5000, 5100))
    after = b"".join(wire(s, t_us=s * PERIOD_US) for s in range(0, 20))
    _, stats = decode(before, after, host_ns=[0, 2 * 10**9])
    assert stats.sequence_resets == 1 and stats.dropped == 0
    assert stats.dropped_in_resets == 499


def test_a_reset_mid_frame_costs_the_torn_frame_only() -> None:
    torn = wire(5100)[:9]
    after = b"".join(wire(s, t_us=500_000 + s * PERIOD_US) for s in range(0, 10))
    got, stats = decode(stream(range(5000, 5100)) + torn + after)
    assert len(got) == 100 + 9  # frame 0 of the new numbering was merged with the torn bytes
    assert stats.sequence_resets == 1 and stats.decode_errors + stats.crc_errors == 1


def test_pending_candidates_are_not_delivered_until_confirmed() -> None:
    stats = LinkStats()
    decoder = StreamDecoder(stats)
    assert len(decoder.feed(stream(range(5000, 5010)), 0)) == 10
    new = [wire(s, t_us=s * PERIOD_US) for s in range(0, RESYNC_FRAMES)]
    assert decoder.feed(b"".join(new[:-1]), 0) == []
    assert decoder.pending == RESYNC_FRAMES - 1
    assert len(decoder.feed(new[-1], 0)) == RESYNC_FRAMES
    assert decoder.pending == 0 and stats.sequence_resets == 1


def test_a_broken_run_of_candidates_is_counted_implausible() -> None:
    stale = wire(50) + wire(51)  # two old frames, then the stream goes on
    got, stats = decode(stream(range(100, 110)) + stale + stream(range(110, 115)))
    assert [f.seq for f in got] == [*range(100, 115)]
    assert stats.implausible == 2 and stats.sequence_resets == 0


def test_reconnect_gap_is_counted_as_dropped_in_disconnects() -> None:
    stats = LinkStats()
    decoder = StreamDecoder(stats)
    decoder.feed(stream(range(0, 10)), 0)
    decoder.feed(stream(range(10, 12)) + wire(12)[:5], 0)
    decoder.reset()  # the link was lost mid-frame
    got = decoder.feed(stream(range(400, 405)), 0)
    assert [f.seq for f in got] == [*range(400, 405)]
    assert stats.dropped == 388 and stats.dropped_in_disconnects == 388
    assert stats.garbage_bytes == 5


def test_a_block_of_overtaken_frames_is_late_not_a_reset() -> None:
    """Frames arriving in order but after newer ones (found by the fuzz campaign: swaps and
    repeats made three stale frames look like a new numbering) are late frames."""
    data = stream(range(100, 110)) + wire(115) + stream(range(110, 115)) + stream(range(116, 120))
    got, stats = decode(data)
    assert [f.seq for f in got] == [*range(100, 110), *range(115, 120)]
    assert stats.implausible == 5 and stats.sequence_resets == 0


@pytest.mark.parametrize("chunk", [10_001, 10_000, 300, 64, 7, 1])
def test_a_long_run_without_delimiter_is_one_resync_however_it_is_chunked(chunk: int) -> None:
    """10,000 noise bytes then 0x00 gave 1, 156 or 227 resyncs depending on the read size,
    and garbage 10000 (the closing delimiter, counted on the reject path, was not)."""
    data = wire(4) + b"\x55" * 10_000 + b"\x00" + wire(5)
    frames, stats = decode(*(data[i:i + chunk] for i in range(0, len(data), chunk)))
    assert [f.seq for f in frames] == [4, 5]
    assert stats.resyncs == 1 and stats.garbage_bytes == 10_001
    assert stats.bytes_read == len(data)


def test_a_reset_during_a_long_run_counts_its_bytes_not_another_resync() -> None:
    stats = LinkStats()
    decoder = StreamDecoder(stats)
    decoder.feed(b"\x55" * 600, host_ns=0)
    decoder.feed(b"\x55" * 100, host_ns=1)
    decoder.reset()
    assert stats.resyncs == 1 and stats.garbage_bytes == 700


@pytest.mark.parametrize("overrun_us", [6_000, 20_000, 40_000, 100_000, 5_000_000])
def test_firmware_skip_ahead_after_an_overrun_shows_a_plain_gap(overrun_us: int) -> None:
    """The reference sketch after an overrun: the next frame is stamped late, seq advanced by
    the periods skipped (exohil_pace_advance), then back on the period grid. The decoder
    delivers every frame with the device's numbering: a gap, no implausible frame, no reset
    (a catch-up burst instead cost frames or took false resets; docs/reliability.md)."""
    stamps = [k * PERIOD_US + 120 for k in range(100)]
    late = stamps[-1] + PERIOD_US + overrun_us  # when the overrunning iteration got going
    skipped = (late - (stamps[-1] + PERIOD_US)) // PERIOD_US
    seq = 100 + skipped
    deadline = (seq + 1) * PERIOD_US
    frames = [(seq, late)] + [(seq + 1 + k, deadline + k * PERIOD_US + 120) for k in range(50)]
    data = b"".join(wire(k, t) for k, t in zip(range(100), stamps, strict=True))
    data += b"".join(wire(s, t) for s, t in frames)
    got, stats = decode(data)
    assert [f.seq for f in got] == [*range(100), *(s for s, _ in frames)]
    assert stats.dropped == skipped and stats.implausible == 0 and stats.sequence_resets == 0
