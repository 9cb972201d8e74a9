"""Wire protocol v1 (formats/wire.py) and the host's stream decoder (harness/link_decoder.py)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from exohil.formats.wire import (
    MAX_SENSORS,
    CobsError,
    CrcError,
    FrameLengthError,
    WireError,
    WireFrame,
    cobs_decode,
    cobs_encode,
    crc16_ccitt_false,
    decode_packet,
    encode_frame,
    pack_body,
)
from exohil.harness.frame_source import LinkStats
from exohil.harness.link_decoder import StreamDecoder

# The documented test vectors (docs/wire-protocol.md): frame → bytes on the wire.
VECTORS = [
    (WireFrame(0, 0, (10000, 25050, 30025, 59999)),
     "02 11 01 01 01 01 01 0a 04 10 27 da 61 49 75 5f ea 02 4a 00"),
    (WireFrame(65535, 4294967295, (33014, 29216, 44440, 30090)),
     "13 11 ff ff ff ff ff ff 04 f6 80 20 72 98 ad 8a 75 49 a3 00"),
    (WireFrame(1234, 4936000, (256, 512, 0, 65535)),
     "07 11 d2 04 40 51 4b 02 04 02 01 02 02 01 05 ff ff df 31 00"),
    (WireFrame(7, 28000, (12345,)),
     "03 11 07 03 60 6d 01 06 01 39 30 6e b7 00"),
]

frames = st.builds(
    WireFrame,
    seq=st.integers(0, 0xFFFF),
    t_us=st.integers(0, 0xFFFFFFFF),
    raw=st.lists(st.integers(0, 0xFFFF), min_size=1, max_size=MAX_SENSORS).map(tuple),
)


def test_crc_check_value() -> None:
    assert crc16_ccitt_false(b"123456789") == 0x29B1


@pytest.mark.parametrize(("frame", "wire_hex"), VECTORS)
def test_documented_vectors_encode_and_decode(frame: WireFrame, wire_hex: str) -> None:
    wire = bytes.fromhex(wire_hex)
    assert encode_frame(frame) == wire
    assert decode_packet(wire[:-1]) == frame


def test_vectors_cover_zero_bytes_and_wraps() -> None:
    bodies = [pack_body(frame) for frame, _ in VECTORS]
    assert b"\x00" in bodies[0]  # a payload with zero bytes
    assert VECTORS[1][0].seq == 0xFFFF and VECTORS[1][0].t_us == 0xFFFFFFFF  # at the wrap


@given(st.binary(max_size=700))
def test_cobs_round_trip_and_no_zero(data: bytes) -> None:
    encoded = cobs_encode(data)
    assert 0 not in encoded
    assert len(encoded) <= len(data) + len(data) // 254 + 1
    assert cobs_decode(encoded) == data


@given(frames)
def test_frame_round_trip(frame: WireFrame) -> None:
    wire = encode_frame(frame)
    assert wire.count(0) == 1 and wire[-1] == 0
    assert decode_packet(wire[:-1], expected_sensors=len(frame.raw)) == frame


@given(frames, st.data())
def test_any_single_byte_change_of_the_body_fails_the_crc(frame: WireFrame, data) -> None:
    body = bytearray(pack_body(frame))
    offset = data.draw(st.integers(0, len(body) - 1))
    body[offset] ^= data.draw(st.integers(1, 255))
    with pytest.raises(WireError):
        decode_packet(cobs_encode(bytes(body)))


def test_decoder_rejects_bad_crc_length_type_and_cobs() -> None:
    frame = VECTORS[2][0]
    body = pack_body(frame)
    bad_crc = body[:-1] + bytes([body[-1] ^ 0x01])
    with pytest.raises(CrcError):
        decode_packet(cobs_encode(bad_crc))
    with pytest.raises(FrameLengthError):
        decode_packet(cobs_encode(body[:-3] + body[-2:]))  # one byte short for 4 sensors
    with pytest.raises(FrameLengthError):
        decode_packet(cobs_encode(body), expected_sensors=3)
    with pytest.raises(FrameLengthError):
        decode_packet(cobs_encode(b"\x21" + body[1:]))  # version 2
    with pytest.raises(FrameLengthError):
        decode_packet(cobs_encode(body[:5]))
    with pytest.raises(CobsError):
        decode_packet(b"\x09\x11\x01")  # code byte points past the end


def test_encoder_rejects_out_of_range_fields() -> None:
    for bad in (WireFrame(65536, 0, (1,)), WireFrame(0, 2**32, (1,)),
                WireFrame(0, 0, ()), WireFrame(0, 0, (70000,))):
        with pytest.raises(ValueError):
            encode_frame(bad)


# ---- stream decoder ------------------------------------------------------------------------


def _stream(seqs: list[int], t_step_us: int = 4000, t0_us: int = 0) -> bytes:
    return b"".join(
        encode_frame(WireFrame(s % 65536, (t0_us + i * t_step_us) % 2**32, (100, 200, 300, 400)))
        for i, s in enumerate(seqs))


@given(
    n=st.integers(1, 40),
    garbage=st.lists(st.binary(min_size=1, max_size=40).map(lambda b: b.replace(b"\x00", b"\x01")),
                     max_size=40),
    data=st.data(),
)
def test_decoder_resyncs_after_garbage_and_any_chunking(n: int, garbage: list[bytes],
                                                        data) -> None:
    """Garbage ended by a delimiter between frames costs no frame, however bytes arrive."""
    packets = [encode_frame(WireFrame(i, i * 4000, (i, 2 * i))) for i in range(n)]
    spliced = list(packets)
    for junk in garbage:
        spliced.insert(data.draw(st.integers(0, len(spliced))), junk + b"\x00")
    stream = b"".join(spliced)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=20)))
    stats = LinkStats()
    decoder = StreamDecoder(stats)
    got = []
    for a, b in zip([0, *cuts], [*cuts, len(stream)], strict=True):
        got += decoder.feed(stream[a:b], host_ns=a)
    assert [f.seq for f in got] == list(range(n))
    assert stats.frames == n and stats.dropped == 0
    assert stats.crc_errors + stats.decode_errors == stats.resyncs
    assert stats.garbage_bytes == sum(len(j) + 1 for j in garbage)


def test_decoder_unwraps_sequence_and_time_across_wraps() -> None:
    seqs = [65533, 65534, 65535, 0, 1, 5]
    stats = LinkStats()
    frames_out = StreamDecoder(stats).feed(_stream(seqs, t_step_us=1_000_000,
                                                   t0_us=2**32 - 2_500_000), host_ns=0)
    assert [f.seq for f in frames_out] == [65533, 65534, 65535, 65536, 65537, 65541]
    assert stats.dropped == 3
    times = np.array([f.device_time_s for f in frames_out])
    np.testing.assert_allclose(np.diff(times), 1.0)
    assert times[0] == pytest.approx((2**32 - 2_500_000) / 1e6)


def test_decoder_discards_duplicates_and_counts_gaps() -> None:
    stats = LinkStats()
    got = StreamDecoder(stats).feed(_stream([10, 11, 11, 14]), host_ns=5)
    assert [f.seq for f in got] == [10, 11, 14]
    assert stats.duplicates == 1 and stats.dropped == 2
    assert all(f.host_ns == 5 for f in got)
    np.testing.assert_allclose(got[0].values_mm, [1.0, 2.0, 3.0, 4.0])


def test_decoder_relocks_after_an_overlong_run_without_delimiter() -> None:
    stats = LinkStats()
    decoder = StreamDecoder(stats)
    assert decoder.feed(b"\x55" * 500, host_ns=0) == []
    got = decoder.feed(b"\x55" * 10 + b"\x00" + _stream([3]), host_ns=0)
    assert [f.seq for f in got] == [3]
    # the closing delimiter counts, as on the reject path (a bad packet + its delimiter)
    assert stats.garbage_bytes == 511 and stats.resyncs == 1 and stats.decode_errors == 0


def test_decoder_reset_drops_the_partial_packet() -> None:
    stats = LinkStats()
    decoder = StreamDecoder(stats)
    whole = _stream([1])
    decoder.feed(whole[:7], host_ns=0)
    decoder.reset()
    assert [f.seq for f in decoder.feed(_stream([2]), host_ns=0)] == [2]
    assert stats.garbage_bytes == 7 and stats.resyncs == 1
