"""Robots in a session: ``build_robots`` names and errors, and the robot trace sink."""

import threading

import numpy as np
import pytest

from exohil.harness.bench import BenchError
from exohil.harness.frame_source import Frame
from exohil.harness.pipeline import Sample
from exohil.harness.robot_render import human_upper_arm_direction
from exohil.harness.robot_trace import RobotTraceSink
from exohil.harness.session import build_robots
from exohil.harness.teleop import SimulatedNao


def _mujoco_threads() -> int:
    return sum(t.name.startswith("mujoco-nao") for t in threading.enumerate())


def test_build_robots_by_name():
    from exohil.harness.robot_mujoco import MujocoNao
    from exohil.harness.robot_udp import UdpJointTarget

    robots = build_robots(["simulated", "mujoco", "udp:127.0.0.1:9", "udp:[::1]:9"])
    try:
        assert [type(r) for r in robots] == [SimulatedNao, MujocoNao, UdpJointTarget,
                                             UdpJointTarget]
        assert robots[1].running  # started: the teleoperation sink's close stops it
        assert (robots[2].host, robots[2].port) == ("127.0.0.1", 9)
        assert robots[3].host == "::1"
    finally:
        for robot in robots[1:]:
            robot.close()
    assert not robots[1].running


@pytest.mark.parametrize(("name", "message"), [
    ("nao", "unknown robot 'nao'; available: simulated, mujoco, udp:HOST:PORT"),
    ("udp:localhost", "bad robot address 'udp:localhost'"),
    ("udp::9000", "bad robot address 'udp::9000'"),
    ("udp:localhost:0", "bad robot address 'udp:localhost:0'"),
    ("udp:localhost:65536", "bad robot address 'udp:localhost:65536'"),
    ("udp:localhost:port", "bad robot address 'udp:localhost:port'"),
    ("udp:no-such-host.invalid:9000", "robot 'udp:no-such-host.invalid:9000': cannot resolve"),
])
def test_build_robots_rejects_bad_names_in_one_line(name, message):
    before = _mujoco_threads()
    with pytest.raises(BenchError) as err:
        build_robots(["mujoco", name])
    assert str(err.value).startswith(message) and "\n" not in str(err.value)
    assert _mujoco_threads() == before  # the robot started before the bad one was closed


class _Arm:
    """A robot whose upper-arm axis is set by the test."""

    side = "right"

    def __init__(self) -> None:
        self.axis = np.array([0.0, 0.0, -1.0])

    def body_positions(self) -> dict[str, np.ndarray]:
        return {"RShoulder": np.zeros(3), "RElbow": 0.1 * self.axis}

    def upper_arm_axis(self, line: str = "elbow") -> np.ndarray:
        return self.axis.copy()


def _sample(t: float) -> Sample:
    frame = Frame(seq=int(t * 250), device_time_s=t, values_mm=np.zeros(4), host_ns=0)
    return Sample(frame, np.zeros(2))


def test_trace_samples_at_its_rate_keeps_the_newest_and_scores_against_the_truth():
    arm = _Arm()
    sink = RobotTraceSink(arm, rate_hz=25.0, max_samples=10)
    for k in range(250):  # 1 s at 250 Hz
        sink.accept(_sample(k / 250))
    trace = sink.trace()
    assert len(trace) == 10  # 25 taken, the newest 10 kept
    assert np.allclose(np.diff(trace.device_time_s), 0.04)
    assert trace.device_time_s[-1] == pytest.approx(0.96)
    assert trace.body_names == ("RShoulder", "RElbow") and trace.bodies.shape == (10, 2, 3)
    assert np.all(np.isnan(trace.axis_error_deg()))  # no truth yet
    from dataclasses import replace

    truth = np.tile([0.0, 90.0], (10, 1))  # abducted 90° in the side plane
    truth[0] = np.nan
    scored = replace(trace, truth_deg=truth)
    human = human_upper_arm_direction(0.0, 90.0)
    expected = np.degrees(np.arccos(np.clip(human @ arm.axis, -1, 1)))
    error = scored.axis_error_deg()
    assert np.isnan(error[0]) and np.allclose(error[1:], expected) and expected > 80
    assert len(scored.arm_samples(np.arange(10))) == 9  # only where the truth is known


def test_trace_samples_again_when_device_time_restarts():
    sink = RobotTraceSink(_Arm(), rate_hz=10.0)
    for t in (5.0, 5.05, 0.0, 0.05, 0.1):
        sink.accept(_sample(t))
    assert sink.trace().device_time_s.tolist() == [5.0, 0.0, 0.1]


def test_trace_rejects_bad_settings():
    with pytest.raises(ValueError, match="rate_hz"):
        RobotTraceSink(_Arm(), rate_hz=0.0)
    with pytest.raises(ValueError, match="max_samples"):
        RobotTraceSink(_Arm(), max_samples=0)


@pytest.mark.parametrize("seconds", [float("nan"), float("inf"), 0.0, -1.0])
def test_a_session_refuses_seconds_it_cannot_run(seconds):
    """run_session(cfg, nan) failed with 'cannot convert float NaN to integer'."""
    from exohil.harness.bench import BenchConfig
    from exohil.harness.session import SessionError, run_session

    with pytest.raises(SessionError, match="seconds must be a finite number > 0"):
        run_session(BenchConfig(), seconds)
