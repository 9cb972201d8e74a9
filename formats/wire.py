"""Wire protocol v1: the byte format of sensor frames on the serial link (docs/wire-protocol.md).

A frame body (before framing) is, all multi-byte fields little-endian::

    offset size  field
    0      1     type/version byte, 0x11 (high nibble: protocol version 1, low nibble: type 1
                 = sensor frame)
    1      2     u16 sequence number, +1 per sampled frame, wraps 65535 -> 0
    3      4     u32 device timestamp in microseconds (Arduino micros()), wraps every 2**32 us
                 (about 71.6 min)
    7      1     u8 sensor count N (1..16)
    8      2N    N x u16 tendon lengths in units of 0.01 mm (0..655.35 mm)
    8+2N   2     u16 CRC-16/CCITT-FALSE over bytes 0..7+2N

The body is COBS-encoded (so it contains no 0x00) and followed by one 0x00 delimiter.

This module is pure: encoding, decoding and validation only; no I/O, threads or policy
(resynchronisation and statistics live in the harness).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

PROTOCOL_VERSION = 1
FRAME_TYPE_SENSORS = 0x1
TYPE_VERSION_BYTE = (PROTOCOL_VERSION << 4) | FRAME_TYPE_SENSORS  # 0x11
DELIMITER = 0x00
MM_PER_LSB = 0.01
#: The sensor unit the wire carries (``MM_PER_LSB`` per count).
WIRE_UNITS = "mm"
#: The largest tendon length the wire carries, mm (a u16 of 0.01 mm).
MAX_VALUE_MM = 0xFFFF * MM_PER_LSB
MAX_SENSORS = 16
SEQ_MODULUS = 1 << 16
TIME_MODULUS_US = 1 << 32
HEADER_SIZE = 8  # type/version + seq + timestamp + count
CRC_SIZE = 2
MAX_BODY_SIZE = HEADER_SIZE + 2 * MAX_SENSORS + CRC_SIZE
# COBS adds one code byte per started run of 254 bytes; bodies here are < 254 bytes.
MAX_PACKET_SIZE = MAX_BODY_SIZE + 1

_HEADER = struct.Struct("<BHIB")


class WireError(ValueError):
    """A packet that is not a valid protocol v1 frame."""


class CobsError(WireError):
    """The packet is not valid COBS (a code byte points past the end, or contains 0x00)."""


class FrameLengthError(WireError):
    """The decoded body has the wrong length, sensor count or type/version byte."""


class CrcError(WireError):
    """The CRC does not match the body."""


@dataclass(frozen=True)
class WireFrame:
    """One sensor frame as it travels on the wire.

    Attributes:
        seq: u16 sequence number (wrapped, 0..65535).
        t_us: u32 device timestamp, microseconds (wrapped, 0..2**32-1).
        raw: sensor values in units of 0.01 mm (each 0..65535).
    """

    seq: int
    t_us: int
    raw: tuple[int, ...]

    @property
    def values_mm(self) -> np.ndarray:
        """The (N,) sensor values in mm (float64)."""
        return np.asarray(self.raw, dtype=np.float64) * MM_PER_LSB


def off_the_wire(units: str) -> str | None:
    """Why readings in ``units`` cannot be streamed over wire protocol v1, as one clause
    ("sensor values are in 'V'; wire protocol v1 carries mm"); None where they can."""
    if units == WIRE_UNITS:
        return None
    return f"sensor values are in {units!r}; wire protocol v1 carries {WIRE_UNITS}"


def crc16_ccitt_false(data: bytes | bytearray | memoryview) -> int:
    """CRC-16/CCITT-FALSE: poly 0x1021, init 0xFFFF, no reflection, xorout 0 (check 0x29B1)."""
    crc = 0xFFFF
    for byte in bytes(data):
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else (crc << 1)
            crc &= 0xFFFF
    return crc


def cobs_encode(data: bytes | bytearray) -> bytes:
    """COBS-encode ``data`` (no trailing delimiter); the result contains no 0x00 byte."""
    out = bytearray()
    block = bytearray()
    for byte in data:
        if byte == 0:
            out.append(len(block) + 1)
            out += block
            block.clear()
        else:
            block.append(byte)
            if len(block) == 254:
                out.append(255)
                out += block
                block.clear()
    out.append(len(block) + 1)
    out += block
    return bytes(out)


def cobs_decode(packet: bytes | bytearray) -> bytes:
    """Decode one COBS packet (without its delimiter); raises CobsError when malformed."""
    out = bytearray()
    i = 0
    n = len(packet)
    if n == 0:
        raise CobsError("empty packet")
    while i < n:
        code = packet[i]
        if code == 0:
            raise CobsError(f"zero byte inside packet at offset {i}")
        end = i + code
        if end > n:
            raise CobsError(f"code byte at offset {i} points past the end of the packet")
        block = packet[i + 1 : end]
        if 0 in block:
            raise CobsError("zero byte inside packet")
        out += block
        i = end
        if code != 255 and i < n:
            out.append(0)
    return bytes(out)


def pack_body(frame: WireFrame) -> bytes:
    """The unframed body of ``frame`` (header, values, CRC); raises ValueError when a field
    is out of range."""
    count = len(frame.raw)
    if not 1 <= count <= MAX_SENSORS:
        raise ValueError(f"sensor count {count} outside 1..{MAX_SENSORS}")
    if not 0 <= frame.seq < SEQ_MODULUS:
        raise ValueError(f"seq {frame.seq} outside 0..65535")
    if not 0 <= frame.t_us < TIME_MODULUS_US:
        raise ValueError(f"t_us {frame.t_us} outside 0..2**32-1")
    if any(not 0 <= v <= 0xFFFF for v in frame.raw):
        raise ValueError("sensor value outside 0..65535 (0.01 mm units)")
    head = _HEADER.pack(TYPE_VERSION_BYTE, frame.seq, frame.t_us, count)
    body = head + struct.pack(f"<{count}H", *frame.raw)
    return body + struct.pack("<H", crc16_ccitt_false(body))


def encode_frame(frame: WireFrame) -> bytes:
    """The bytes sent on the wire for ``frame``: COBS(body) followed by the 0x00 delimiter."""
    return cobs_encode(pack_body(frame)) + b"\x00"


def unpack_body(body: bytes, expected_sensors: int | None = None) -> WireFrame:
    """Validate and parse a decoded body; raises FrameLengthError or CrcError."""
    if len(body) < HEADER_SIZE + 2 + CRC_SIZE:
        raise FrameLengthError(f"body of {len(body)} bytes is shorter than any frame")
    type_version, seq, t_us, count = _HEADER.unpack_from(body)
    if type_version != TYPE_VERSION_BYTE:
        raise FrameLengthError(f"type/version byte 0x{type_version:02x}, expected 0x11")
    if not 1 <= count <= MAX_SENSORS:
        raise FrameLengthError(f"sensor count {count} outside 1..{MAX_SENSORS}")
    if expected_sensors is not None and count != expected_sensors:
        raise FrameLengthError(f"sensor count {count}, expected {expected_sensors}")
    if len(body) != HEADER_SIZE + 2 * count + CRC_SIZE:
        raise FrameLengthError(f"body of {len(body)} bytes does not match {count} sensors")
    (crc,) = struct.unpack_from("<H", body, len(body) - CRC_SIZE)
    if crc != crc16_ccitt_false(body[:-CRC_SIZE]):
        raise CrcError("CRC mismatch")
    raw = struct.unpack_from(f"<{count}H", body, HEADER_SIZE)
    return WireFrame(seq=seq, t_us=t_us, raw=tuple(raw))


def decode_packet(packet: bytes, expected_sensors: int | None = None) -> WireFrame:
    """Decode one packet (the bytes between two delimiters); raises a WireError subclass."""
    if len(packet) > MAX_PACKET_SIZE:
        raise FrameLengthError(f"packet of {len(packet)} bytes is longer than any frame")
    return unpack_body(cobs_decode(packet), expected_sensors)
