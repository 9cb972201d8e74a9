"""Decoder fuzzing (harness/link_decoder.py): random bytes, bit flips, truncated, duplicated
and reordered frames, long garbage runs and zero-byte bursts, fed in random chunks.

Whatever the input: no exception; every delivered frame is one that a strict reference
decoder finds, CRC-valid, in the input (so no frame with a bad CRC is ever delivered, and
nothing is invented); delivered sequence numbers and device times increase strictly; every
valid frame is accounted for (delivered, duplicate, implausible or pending). Without
reordering or bit flips, every frame whose bytes arrived intact is delivered with its exact
numbering: the decoder is back in sync within one frame of any damage.

Each example decodes a few hundred frames in pure Python (a few ms); the example counts are
set here, not by the hypothesis profile, so the file runs in a few seconds in CI. For a longer
campaign set ``EXOHIL_FUZZ_EXAMPLES`` (docs/reliability.md).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

from hypothesis import given, settings
from hypothesis import strategies as st

from exohil.formats.wire import (
    SEQ_MODULUS,
    TIME_MODULUS_US,
    WireError,
    WireFrame,
    decode_packet,
    encode_frame,
)
from exohil.harness.frame_source import Frame, LinkStats
from exohil.harness.link_decoder import StreamDecoder

EXAMPLES = int(os.environ.get("EXOHIL_FUZZ_EXAMPLES", "150"))


@dataclass(frozen=True)
class Base:
    """``n`` frames of a device: wire seq from ``seq0``, period ``period_us``."""

    frames: list[WireFrame]


@st.composite
def base_streams(draw: st.DrawFn, min_frames: int = 5, max_frames: int = 120) -> Base:
    n = draw(st.integers(min_frames, max_frames))
    seq0 = draw(st.integers(0, SEQ_MODULUS - 1))
    t0 = draw(st.integers(0, TIME_MODULUS_US - 1))
    period = draw(st.integers(50, 20_000))
    sensors = draw(st.integers(1, 4))
    values = draw(st.lists(st.integers(0, 0xFFFF), min_size=sensors, max_size=sensors))
    return Base([WireFrame((seq0 + k) % SEQ_MODULUS, (t0 + k * period) % TIME_MODULUS_US,
                           tuple((v + 37 * k) % 0x10000 for v in values)) for k in range(n)])


garbage = st.one_of(
    st.binary(min_size=1, max_size=60),  # random bytes, zeros included
    st.binary(min_size=300, max_size=1500).map(lambda b: b.replace(b"\x00", b"\x5a")),  # long run
    st.integers(1, 64).map(lambda n: b"\x00" * n),  # zero-byte burst
)


def valid_frames(data: bytes) -> list[WireFrame]:
    """What a strict reference decoder finds in ``data``: every packet that decodes."""
    out = []
    for packet in data.split(b"\x00")[:-1]:
        try:
            out.append(decode_packet(packet))
        except WireError:
            pass
    return out


def feed_in_chunks(data: bytes, cuts: list[int]) -> tuple[list[Frame], LinkStats, int]:
    stats = LinkStats()
    decoder = StreamDecoder(stats)
    got: list[Frame] = []
    bounds = sorted({0, len(data), *(c % (len(data) + 1) for c in cuts)})
    for a, b in zip(bounds, bounds[1:], strict=False):
        got += decoder.feed(data[a:b], host_ns=a)
    return got, stats, decoder.pending


def as_wire(frame: Frame) -> tuple[int, int, tuple[int, ...]]:
    raw = tuple(int(round(v * 100)) for v in frame.values_mm)
    return frame.seq % SEQ_MODULUS, round(frame.device_time_s * 1e6), raw


def assert_sound(data: bytes, got: list[Frame], stats: LinkStats, pending: int) -> None:
    """The invariants that hold for any input (module doc)."""
    valid = valid_frames(data)
    renumbered = stats.sequence_resets > 0  # then only the values identify a frame
    keys = [(None if renumbered else f.seq, f.raw) for f in valid]
    i = 0
    for frame in got:  # delivered ⊆ valid frames of the input, in input order
        seq, _, raw = as_wire(frame)
        key = (None if renumbered else seq, raw)
        while i < len(keys) and keys[i] != key:
            i += 1
        assert i < len(keys), f"delivered frame seq {seq} {raw} is not a valid frame of the input"
        i += 1
    assert all(b.seq > a.seq for a, b in zip(got, got[1:], strict=False))
    assert all(b.device_time_s > a.device_time_s for a, b in zip(got, got[1:], strict=False))
    assert stats.frames == len(got)
    assert stats.frames + stats.duplicates + stats.implausible + pending == len(valid)
    assert stats.crc_errors + stats.decode_errors <= stats.resyncs


@settings(max_examples=EXAMPLES, deadline=None)
@given(data=st.binary(max_size=3000), cuts=st.lists(st.integers(0, 3000), max_size=30))
def test_random_bytes_never_crash_or_deliver(data: bytes, cuts: list[int]) -> None:
    got, stats, pending = feed_in_chunks(data, cuts)
    assert_sound(data, got, stats, pending)
    assert stats.bytes_read == len(data)


@settings(max_examples=EXAMPLES, deadline=None)
@given(base=base_streams(), damage=st.data(), cuts=st.lists(st.integers(0, 10**6), max_size=30))
def test_truncation_garbage_and_zero_bursts_cost_at_most_the_frame_they_touch(
        base: Base, damage: st.DataObject, cuts: list[int]) -> None:
    packets = [encode_frame(f) for f in base.frames]
    n_damage = damage.draw(st.integers(0, 8))
    for _ in range(n_damage):
        k = damage.draw(st.integers(0, len(packets) - 1))
        if damage.draw(st.booleans()) and len(packets[k]) > 2:  # truncate: keep 1..len-2
            # bytes of the encoded frame, then its delimiter
            cut = damage.draw(st.integers(1, len(packets[k]) - 2))
            packets[k] = packets[k][:cut] + b"\x00"
        else:  # garbage before frame k
            packets[k] = damage.draw(garbage) + packets[k]
    data = b"".join(packets)
    got, stats, pending = feed_in_chunks(data, cuts)
    assert_sound(data, got, stats, pending)
    intact = set(data.split(b"\x00"))
    expected = [k for k, f in enumerate(base.frames) if encode_frame(f)[:-1] in intact]
    assert len(expected) >= len(base.frames) - n_damage  # damage reaches one frame at most
    first = expected[0] if expected else 0
    assert [f.seq - got[0].seq + first for f in got] == expected  # exact numbering, no loss
    assert stats.implausible == 0 and stats.sequence_resets == 0 and pending == 0


@settings(max_examples=EXAMPLES, deadline=None)
@given(base=base_streams(), edits=st.data(), cuts=st.lists(st.integers(0, 10**6), max_size=30))
def test_duplicated_and_reordered_frames_keep_the_numbering(
        base: Base, edits: st.DataObject, cuts: list[int]) -> None:
    order = list(range(len(base.frames)))
    for _ in range(edits.draw(st.integers(0, 10))):
        k = edits.draw(st.integers(0, len(order) - 2))
        if edits.draw(st.booleans()):
            order[k], order[k + 1] = order[k + 1], order[k]  # two frames swapped
        else:
            order.insert(k + 1, order[k])  # a frame repeated
    data = b"".join(encode_frame(base.frames[k]) for k in order)
    got, stats, pending = feed_in_chunks(data, cuts)
    assert_sound(data, got, stats, pending)
    assert stats.sequence_resets == 0
    # unwrapped numbering is the device's: seq offsets from the first delivered frame
    first = order[0]
    offsets = [f.seq - got[0].seq + first for f in got]
    assert all(as_wire(f)[0] == base.frames[k].seq for f, k in zip(got, offsets, strict=True))
    # whatever was not delivered went missing behind a later frame, or was a repeat
    assert set(order) - set(offsets) <= {k for i, k in enumerate(order)
                                         if any(j > k for j in order[:i])}


@settings(max_examples=EXAMPLES, deadline=None)
@given(base=base_streams(), flips=st.data(), cuts=st.lists(st.integers(0, 10**6), max_size=30))
def test_bit_flips_and_everything_at_once_never_deliver_a_bad_frame(
        base: Base, flips: st.DataObject, cuts: list[int]) -> None:
    data = bytearray(b"".join(encode_frame(f) for f in base.frames))
    for _ in range(flips.draw(st.integers(1, 40))):
        pos = flips.draw(st.integers(0, len(data) - 1))
        data[pos] ^= 1 << flips.draw(st.integers(0, 7))
    pieces = bytes(data).split(b"\x00")
    for _ in range(flips.draw(st.integers(0, 5))):  # splice in garbage, repeats, swaps
        k = flips.draw(st.integers(0, len(pieces) - 1))
        action = flips.draw(st.sampled_from(["garbage", "repeat", "swap"]))
        if action == "garbage":
            pieces.insert(k, flips.draw(garbage).replace(b"\x00", b""))
        elif action == "repeat":
            pieces.insert(k, pieces[k])
        elif k + 1 < len(pieces):
            pieces[k], pieces[k + 1] = pieces[k + 1], pieces[k]
    stream = b"\x00".join(pieces)
    got, stats, pending = feed_in_chunks(stream, cuts)
    assert_sound(stream, got, stats, pending)
