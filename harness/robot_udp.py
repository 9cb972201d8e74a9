"""NAO joint commands as UDP datagrams of JSON, one per command, for any robot bridge.

:class:`UdpJointTarget` implements the :class:`~exohil.harness.teleop.JointTarget` protocol.
Each ``command()`` sends one datagram (UTF-8 JSON, schema :data:`COMMAND_SCHEMA`, documented
in docs/robot.md)::

    {"schema": "exohil.nao_command/1", "seq": 0, "t": 1.234, "sent_unix_ns": 17...,
     "side": "right", "joints": ["RShoulderPitch", "RShoulderRoll", "RElbowYaw"],
     "rad": [0.1, -0.5, 0.0], "deg": [5.73, -28.65, 0.0], "clamped": [false, false, false]}

UDP is fire-and-forget: sending never blocks (a non-blocking socket), and a datagram the
kernel refuses is counted in the summary instead of raising, so a robot bridge that is down
cannot stall the pipeline.

The datagram may drive a real robot, so ``rad`` is always within NAO's limits for the side
(:data:`~exohil.kinematics.robot.NAO_LIMITS`, which the schema states per joint): an angle
beyond them is clipped to the limit, its ``clamped`` flag set, and the command counted
(``out_of_range`` in the summary), as ``MujocoNao`` clips to its model's limits.
"""

from __future__ import annotations

import json
import math
import socket
import time

import numpy as np

from exohil.kinematics import NAO_JOINTS, NAO_LIMITS

SCHEMA_ID = "exohil.nao_command/1"
#: Commands beyond the limits by more than this (rad) count as out of range; the clamped flag
#: is set for them (as ``robot_mujoco.LIMIT_TOLERANCE``).
LIMIT_TOLERANCE = 1e-6


def _side_limits(side: str) -> dict:
    """The schema's per-joint bounds of ``rad`` and ``deg`` for one side."""
    def bounds(limits: np.ndarray) -> list[dict]:
        return [{"type": "number", "minimum": float(lo), "maximum": float(hi)}
                for lo, hi in limits]
    limits = NAO_LIMITS[side]
    return {"if": {"properties": {"side": {"const": side}}, "required": ["side"]},
            "then": {"properties": {"rad": {"prefixItems": bounds(limits)},
                                    "deg": {"prefixItems": bounds(np.rad2deg(limits))}}}}

#: JSON schema of one datagram.
COMMAND_SCHEMA = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": SCHEMA_ID,
    "type": "object",
    "required": ["schema", "seq", "t", "sent_unix_ns", "side", "joints", "rad", "deg",
                 "clamped"],
    "additionalProperties": False,
    "properties": {
        "schema": {"const": SCHEMA_ID},
        "seq": {"type": "integer", "minimum": 0,
                "description": "datagram number from 0; a gap means a lost datagram"},
        "t": {"type": "number", "description": "the estimate's time, seconds"},
        "sent_unix_ns": {"type": "integer", "description": "sender's wall clock at sending"},
        "side": {"enum": ["right", "left"]},
        "joints": {"type": "array", "minItems": 3, "maxItems": 3,
                   "items": {"type": "string", "pattern": "^[RL](ShoulderPitch|ShoulderRoll|"
                                                         "ElbowYaw)$"}},
        "rad": {"type": "array", "minItems": 3, "maxItems": 3, "items": {"type": "number"},
                "description": "ShoulderPitch, ShoulderRoll, ElbowYaw (rad), within NAO's "
                               "limits for the side (allOf)"},
        "deg": {"type": "array", "minItems": 3, "maxItems": 3, "items": {"type": "number"},
                "description": "the same in degrees"},
        "clamped": {"type": "array", "minItems": 3, "maxItems": 3,
                    "items": {"type": "boolean"},
                    "description": "the joint's exact value was outside its limit (by the "
                                   "mapping, or clipped by the sender)"},
    },
    "allOf": [_side_limits("right"), _side_limits("left")],
}



def parse_udp_address(name: str) -> tuple[str, int]:
    """``udp:HOST:PORT`` (an IPv6 host in brackets) → (host, port); ValueError saying what is
    expected."""
    host, _, port = name.removeprefix("udp:").rpartition(":")
    host = host.removeprefix("[").removesuffix("]")
    if (not name.startswith("udp:") or not host.strip() or not host.isprintable()
            or any(c.isspace() for c in host) or not (port.isascii() and port.isdigit())
            or not 1 <= int(port) <= 65535):
        raise ValueError(f"bad robot address {name!r}: expected udp:HOST:PORT with a port "
                         "1..65535, e.g. udp:127.0.0.1:9000")
    return host, int(port)


class UdpJointTarget:
    """Sends each NAO command to ``host:port`` as one UDP datagram of JSON.

    Args:
        host: IPv4/IPv6 address or name of the receiver (resolved once, here).
        port: UDP port, 1..65535.
        side: the arm the commands are for; names the joints (``RShoulderPitch`` ...).

    Raises ValueError for a bad port or a host that does not resolve.
    """

    def __init__(self, host: str, port: int, side: str = "right") -> None:
        if side not in ("right", "left"):
            raise ValueError(f"side must be 'right' or 'left', got {side!r}")
        if isinstance(port, bool) or not isinstance(port, int | np.integer) \
                or not 1 <= port <= 65535:
            raise ValueError(f"port must be an integer 1..65535, got {port!r}")
        port = int(port)
        try:
            family, _, _, _, address = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)[0]
        except (socket.gaierror, UnicodeError) as err:
            raise ValueError(f"cannot resolve UDP host {host!r}: {err}") from None
        self.host, self.port, self.side = host, port, side
        self._address = address
        self._sock: socket.socket | None = socket.socket(family, socket.SOCK_DGRAM)
        self._sock.setblocking(False)
        self._names = [("R" if side == "right" else "L") + name for name in NAO_JOINTS]
        self._seq = 0
        self.bytes_sent = 0
        self.send_errors = 0
        self.last_error: str | None = None
        self.clamped_commands = 0
        self.out_of_range = 0
        self._limits = NAO_LIMITS[side]

    def command(self, t: float, joints: np.ndarray, clamped: np.ndarray) -> None:
        """Send one datagram: ``joints`` radians in NAO_JOINTS order, ``clamped`` flags.

        Angles beyond NAO's limits for the side are clipped to them; a joint clipped by more
        than ``LIMIT_TOLERANCE`` is flagged clamped and the command counted as out of range.
        Raises ValueError for a wrong shape or non-finite values, RuntimeError after close.
        """
        if self._sock is None:
            raise RuntimeError("UdpJointTarget is closed")
        angles = np.asarray(joints, dtype=float)
        flags = np.asarray(clamped, dtype=bool)
        if angles.shape != (3,) or flags.shape != (3,):
            raise ValueError(f"joints and clamped must have shape (3,), got {angles.shape} "
                             f"and {flags.shape}")
        if not (np.all(np.isfinite(angles)) and math.isfinite(t)):
            raise ValueError(f"t and joints must be finite, got t={t!r}, {angles.tolist()}")
        target = np.clip(angles, self._limits[:, 0], self._limits[:, 1])
        beyond = np.abs(target - angles) > LIMIT_TOLERANCE
        flags = flags | beyond
        message = {"schema": SCHEMA_ID, "seq": self._seq, "t": float(t),
                   "sent_unix_ns": time.time_ns(), "side": self.side, "joints": self._names,
                   "rad": target.tolist(), "deg": np.rad2deg(target).tolist(),
                   "clamped": flags.tolist()}
        payload = json.dumps(message, allow_nan=False, separators=(",", ":")).encode()
        self._seq += 1
        self.clamped_commands += int(flags.any())
        self.out_of_range += int(beyond.any())
        try:
            self.bytes_sent += self._sock.sendto(payload, self._address)
        except OSError as err:  # full buffer, unreachable network: count, do not stall
            self.send_errors += 1
            self.last_error = f"{type(err).__name__}: {err}"

    def close(self) -> None:
        """Close the socket. Idempotent."""
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def __enter__(self) -> UdpJointTarget:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def summary(self) -> dict:
        """JSON-able: destination, commands and datagrams sent, bytes, send errors, commands
        with a clamped joint and commands clipped here to NAO's limits (``out_of_range``)."""
        return {"host": self.host, "port": self.port, "side": self.side,
                "commands": self._seq, "datagrams_sent": self._seq - self.send_errors,
                "bytes_sent": self.bytes_sent, "send_errors": self.send_errors,
                "last_error": self.last_error, "clamped_commands": self.clamped_commands,
                "out_of_range": self.out_of_range}
