"""MujocoNao: a MuJoCo NAO arm that follows commands in its own physics thread."""

import json
import math
import time

import numpy as np
import pytest
from urdf_fk import load_joints, upper_arm_x_axis

from exohil.harness.robot_mujoco import BODIES, MujocoNao
from exohil.harness.robot_stats import LogHistogram
from exohil.kinematics import NAO_LIMITS

JOINTS = load_joints()
NO_CLAMP = np.zeros(3, dtype=bool)


def settle(nao: MujocoNao, joints_deg, seconds: float = 0.6) -> None:
    nao.command(0.0, np.deg2rad(joints_deg), NO_CLAMP)
    time.sleep(seconds)


def angle_deg(a, b) -> float:
    return math.degrees(math.atan2(np.linalg.norm(np.cross(a, b)), float(np.dot(a, b))))


@pytest.mark.parametrize(("side", "pose_deg"), [("right", [10.0, -45.0, 30.0]),
                                                ("right", [-60.0, 5.0, -80.0]),
                                                ("left", [20.0, 50.0, -30.0])])
def test_arm_reaches_the_commanded_pose(side, pose_deg):
    with MujocoNao(side) as nao:
        settle(nao, pose_deg)
        reached = np.rad2deg(nao.joint_angles())
        axis, elbow_line = nao.upper_arm_axis("axis"), nao.upper_arm_axis()
        summary = nao.summary()
    # The servo holds against gravity with a small steady-state error.
    assert reached == pytest.approx(pose_deg, abs=1.0)
    wanted = upper_arm_x_axis(JOINTS, side, *np.deg2rad(pose_deg[:2]))
    assert angle_deg(axis, wanted) < 1.0
    assert angle_deg(axis, elbow_line) == pytest.approx(8.13, abs=0.01)
    assert summary["commands"] == 1 and summary["steps"] > 100
    assert summary["tracking_error_deg"]["count"] > 100
    assert summary["tracking_error_deg"]["p50"] < 1.0  # after settling most steps are close
    json.dumps(summary)


def test_summary_reports_rate_delay_and_bounded_statistics():
    with MujocoNao() as nao:
        for i in range(50):
            nao.command(i * 0.004, np.deg2rad([90.0 - i, -i * 0.5, 0.0]), NO_CLAMP)
            time.sleep(0.004)
        time.sleep(0.1)
        summary = nao.summary()
    assert summary["physics_rate_hz"] > 0 and summary["target_rate_hz"] == 500.0
    assert summary["simulated_s"] == pytest.approx(summary["steps"] * 0.002)
    delay = summary["command_delay_ms"]
    assert delay["count"] + summary["superseded_commands"] == 50
    assert 0.0 < delay["p50"] <= delay["p99"] <= delay["max"]
    for key in ("p50", "p99", "max"):
        assert key in summary["tracking_error_deg"]


def test_close_stops_the_thread_and_is_idempotent():
    nao = MujocoNao()
    nao.start()
    time.sleep(0.05)
    assert nao.running
    nao.close()
    assert not nao.running
    steps = nao.summary()["steps"]
    time.sleep(0.05)
    assert nao.summary()["steps"] == steps
    nao.close()
    with pytest.raises(RuntimeError, match="closed"):
        nao.command(0.0, np.zeros(3), NO_CLAMP)
    with pytest.raises(RuntimeError, match="closed"):
        nao.start()


def test_commands_outside_the_limits_are_clipped_and_counted():
    with MujocoNao() as nao:
        settle(nao, [150.0, -100.0, 0.0])
        reached = np.rad2deg(nao.joint_angles())
        summary = nao.summary()
    low, high = np.rad2deg(NAO_LIMITS["right"][:, 0]), np.rad2deg(NAO_LIMITS["right"][:, 1])
    assert reached[0] == pytest.approx(high[0], abs=1.0)
    assert reached[1] == pytest.approx(low[1], abs=1.0)
    assert np.all(reached <= high + 0.5) and np.all(reached >= low - 0.5)
    assert summary["out_of_range_commands"] == 1


def test_the_mappings_limit_values_are_not_out_of_range():
    # NAO_LIMITS (−76°) and the URDF (−1.32645 rad) differ by 2e-7 rad of rounding.
    with MujocoNao() as nao:
        nao.command(0.0, NAO_LIMITS["right"][:, 0], np.ones(3, dtype=bool))
        nao.command(0.0, NAO_LIMITS["right"][:, 1], np.ones(3, dtype=bool))
        summary = nao.summary()
    assert summary["out_of_range_commands"] == 0 and summary["clamped_commands"] == 2


def test_a_command_before_start_is_refused():
    """It used to be counted as taken while no physics ran (CoppeliaNao refuses it too)."""
    nao = MujocoNao()
    with pytest.raises(RuntimeError, match=r"not running \(call start\(\) first\)"):
        nao.command(0.0, np.zeros(3), NO_CLAMP)
    assert nao.summary()["commands"] == 0
    nao.start()
    nao.command(0.0, np.zeros(3), NO_CLAMP)
    nao.close()
    assert nao.summary()["commands"] == 1


def test_bad_commands_and_arguments_raise():
    nao = MujocoNao()
    nao.start()  # commands are taken only while running
    with pytest.raises(ValueError, match="shape"):
        nao.command(0.0, np.zeros(4), NO_CLAMP)
    with pytest.raises(ValueError, match="finite"):
        nao.command(0.0, np.array([np.nan, 0.0, 0.0]), NO_CLAMP)
    with pytest.raises(ValueError, match="side"):
        MujocoNao("middle")
    with pytest.raises(ValueError, match="rate_hz"):
        MujocoNao(rate_hz=100.0)
    with pytest.raises(ValueError, match="line"):
        nao.upper_arm_axis("wrist")
    with pytest.raises(ValueError, match="clamped must have shape"):  # was any shape
        nao.command(0.0, np.zeros(3), np.array([True]))
    with pytest.raises(ValueError, match="rest must be 3 finite joint angles"):  # was NaN pose
        MujocoNao(rest=(math.nan, 0.0, 0.0))
    nao.close()


def test_body_positions_name_every_body_and_start_hanging():
    nao = MujocoNao()
    bodies = nao.body_positions()
    nao.close()
    assert tuple(bodies) == BODIES
    assert bodies["RShoulder"] == pytest.approx([0.0, -0.098, 0.1])
    # hanging (pitch 90°): the elbow is 105 mm below the shoulder, 15 mm outward
    assert bodies["RElbow"] == pytest.approx([0.0, -0.113, -0.005], abs=1e-9)
    assert bodies["r_wrist"][2] < bodies["RElbow"][2]


def test_log_histogram_quantiles_match_numpy_within_a_bin():
    rng = np.random.default_rng(3)
    values = rng.lognormal(0.0, 1.5, 20000)
    hist = LogHistogram(1e-6, 1e4)
    for v in values:
        hist.add(float(v))
    width = 10 ** (1 / 200)
    for q in (0.5, 0.99):
        exact = float(np.quantile(values, q, method="inverted_cdf"))
        assert exact <= hist.quantile(q) <= exact * width * (1 + 1e-12)
    assert hist.quantile(1.0) == hist.max == values.max()
    assert hist.summary()["mean"] == pytest.approx(values.mean(), rel=1e-3)
    assert len(hist._counts) == math.ceil(10 * 200) + 2  # fixed, whatever the count


def test_log_histogram_edges_and_errors():
    hist = LogHistogram(1.0, 10.0)
    assert hist.quantile(0.5) is None and hist.summary()["max"] is None
    hist.add(0.0)
    hist.add(1e6)  # overflow: reads as the maximum
    assert hist.quantile(0.0) == 1.0 and hist.quantile(1.0) == 1e6
    with pytest.raises(ValueError):
        hist.add(-1.0)
    with pytest.raises(ValueError):
        hist.add(float("nan"))
    with pytest.raises(ValueError):
        hist.quantile(1.5)
    with pytest.raises(ValueError):
        LogHistogram(0.0, 1.0)
