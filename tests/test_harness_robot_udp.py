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
    roll = -1.0 if side == "right" else 1.0  # within either side's limits (-76°..18° right)
    commands = [(0.004 * k, np.deg2rad([90.0 - 10 * k, roll * 20.0 * k, 5.0]),
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


@pytest.mark.parametrize("side", ["right", "left"])
def test_angles_beyond_naos_limits_are_clipped_flagged_and_counted(receiver, side):
    """The datagram may drive a real NAO: 3 rad of pitch used to go out as is, with clamped
    false, and the schema accepted it."""
    from exohil.kinematics.robot import NAO_LIMITS

    limits = NAO_LIMITS[side]
    roll_out = -1.5 if side == "right" else 1.5  # beyond -76° (right) / 76° (left)
    with UdpJointTarget("127.0.0.1", receiver.getsockname()[1], side=side) as target:
        target.command(0.0, np.array([3.0, 0.0, 0.0]), np.zeros(3, bool))
        target.command(0.004, np.array([0.0, roll_out, -2.5]), np.array([True, False, False]))
        target.command(0.008, limits[:, 1].copy(), np.zeros(3, bool))  # at the limit: as is
        messages = [receive(receiver) for _ in range(3)]
        summary = target.summary()
    assert messages[0]["rad"] == [limits[0, 1], 0.0, 0.0]
    assert messages[0]["clamped"] == [True, False, False]
    assert messages[1]["rad"] == [0.0, limits[1, 0 if side == "right" else 1], limits[2, 0]]
    assert messages[1]["clamped"] == [True, True, True]
    assert messages[2]["rad"] == limits[:, 1].tolist()
    assert messages[2]["clamped"] == [False, False, False]
    for message in messages:
        jsonschema.validate(message, COMMAND_SCHEMA)
        assert message["deg"] == pytest.approx(np.rad2deg(message["rad"]).tolist())
    assert summary["out_of_range"] == 2 and summary["clamped_commands"] == 2


def test_the_schema_states_naos_limits_per_side():
    from exohil.kinematics.robot import NAO_LIMITS

    message = {"schema": "exohil.nao_command/1", "seq": 0, "t": 0.0, "sent_unix_ns": 0,
               "side": "right", "joints": ["RShoulderPitch", "RShoulderRoll", "RElbowYaw"],
               "rad": [3.0, 0.0, 0.0], "deg": [171.9, 0.0, 0.0], "clamped": [False] * 3}
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(message, COMMAND_SCHEMA)
    # a right arm's roll of -60° is within its limits and beyond the left arm's
    roll = np.deg2rad(-60.0)
    message.update(rad=[0.0, roll, 0.0], deg=[0.0, -60.0, 0.0])
    jsonschema.validate(message, COMMAND_SCHEMA)
    assert NAO_LIMITS["left"][1, 0] > roll
    message.update(side="left", joints=["LShoulderPitch", "LShoulderRoll", "LElbowYaw"])
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(message, COMMAND_SCHEMA)


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
