"""UdpJointTarget: one JSON datagram per NAO command, checked on loopback."""

import json
import socket

import jsonschema
import numpy as np
import pytest

from exohil.harness.robot_udp import COMMAND_SCHEMA, UdpJointTarget


@pytest.fixture
def receiver():
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(2.0)  # bounded: a lost datagram fails the test instead of hanging it
    yield sock
    sock.close()


def receive(sock: socket.socket) -> dict:
    data, _ = sock.recvfrom(65536)
    return json.loads(data.decode("utf-8"))


@pytest.mark.parametrize("side", ["right", "left"])
def test_each_command_is_one_datagram_matching_the_schema(receiver, side):
    port = receiver.getsockname()[1]
    commands = [(0.004 * k, np.deg2rad([90.0 - 10 * k, -20.0 * k, 5.0]),
                 np.array([False, k == 2, False])) for k in range(3)]
    with UdpJointTarget("127.0.0.1", port, side=side) as target:
        for t, joints, clamped in commands:
            target.command(t, joints, clamped)
        messages = [receive(receiver) for _ in commands]
        summary = target.summary()
    prefix = "R" if side == "right" else "L"
    for k, (message, (t, joints, clamped)) in enumerate(zip(messages, commands, strict=True)):
        jsonschema.validate(message, COMMAND_SCHEMA)
        assert message["seq"] == k and message["t"] == t and message["side"] == side
        assert message["joints"] == [f"{prefix}ShoulderPitch", f"{prefix}ShoulderRoll",
                                     f"{prefix}ElbowYaw"]
        assert message["rad"] == joints.tolist()
        assert message["deg"] == pytest.approx(np.rad2deg(joints).tolist())
        assert message["clamped"] == clamped.tolist()
    assert summary["commands"] == 3 and summary["datagrams_sent"] == 3
    assert summary["send_errors"] == 0 and summary["clamped_commands"] == 1
    json.dumps(summary)


def test_bad_arguments_and_commands_are_clear_errors(receiver, monkeypatch):
    with pytest.raises(ValueError, match="port"):
        UdpJointTarget("127.0.0.1", 0)
    with pytest.raises(ValueError, match="port must be an integer"):  # was an OSError
        UdpJointTarget("127.0.0.1", True)
    UdpJointTarget("127.0.0.1", np.int64(receiver.getsockname()[1])).close()  # was refused
    with monkeypatch.context() as m:  # no DNS query from a test

        def unresolvable(*args, **kwargs):
            raise socket.gaierror(socket.EAI_NONAME, "Name or service not known")

        m.setattr(socket, "getaddrinfo", unresolvable)
        with pytest.raises(ValueError, match="resolve"):
            UdpJointTarget("robot.invalid", 9)
    with pytest.raises(ValueError, match="side"):
        UdpJointTarget("127.0.0.1", 9, side="both")
    target = UdpJointTarget("127.0.0.1", receiver.getsockname()[1])
    with pytest.raises(ValueError, match="shape"):
        target.command(0.0, np.zeros(2), np.zeros(3, dtype=bool))
    with pytest.raises(ValueError, match="finite"):
        target.command(0.0, np.array([0.0, np.inf, 0.0]), np.zeros(3, dtype=bool))
    target.close()
    target.close()  # idempotent
    with pytest.raises(RuntimeError, match="closed"):
        target.command(0.0, np.zeros(3), np.zeros(3, dtype=bool))
    assert target.summary()["commands"] == 0
