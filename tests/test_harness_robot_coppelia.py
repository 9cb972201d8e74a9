"""CoppeliaNao against a stand-in remote API client (a real CoppeliaSim is not used in tests)."""

import sys
import threading
import time

import numpy as np
import pytest

from exohil.harness.robot_coppelia import INSTALL_HINT, CoppeliaNao, MissingClientError

NO_CLAMP = np.zeros(3, dtype=bool)


class FakeSim:
    def __init__(self, objects):
        self.objects = objects
        self.targets = {}

    def getObject(self, path):  # noqa: N802 - CoppeliaSim's name
        if path not in self.objects:
            raise Exception(f"object does not exist: {path}")  # what the real client raises
        return self.objects[path]

    def setJointTargetPosition(self, handle, position):  # noqa: N802
        assert isinstance(position, float)
        self.targets[handle] = position


class FakeClient:
    def __init__(self, sim):
        self.sim = sim

    def require(self, name):
        assert name == "sim"
        return self.sim


def wait_for(predicate, timeout=2.0):
    end = time.monotonic() + timeout
    while not predicate() and time.monotonic() < end:
        time.sleep(0.005)
    return predicate()


@pytest.mark.parametrize("side", ["right", "left"])
def test_commands_set_the_scene_joint_targets(side):
    p = "R" if side == "right" else "L"
    paths = [f"/NAO/{p}ShoulderPitch", f"/NAO/{p}ShoulderRoll", f"/NAO/{p}ElbowYaw"]
    sim = FakeSim({path: 10 + k for k, path in enumerate(paths)})
    with CoppeliaNao(side, client_factory=lambda host, port: FakeClient(sim)) as nao:
        assert nao.joint_paths == paths
        nao.command(0.0, np.array([0.1, -0.2, 0.3]), NO_CLAMP)
        assert wait_for(lambda: nao.sent == 1)
        summary = nao.summary()
    assert sim.targets == {10: 0.1, 11: -0.2, 12: 0.3}
    assert summary["commands"] == 1 and summary["sent"] == 1
    assert summary["send_ms"]["count"] == 1


def test_missing_client_package_is_a_clear_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "coppeliasim_zmqremoteapi_client", None)
    with pytest.raises(MissingClientError, match="pip install coppeliasim-zmqremoteapi-client"):
        CoppeliaNao().start()
    assert "coppeliasim-zmqremoteapi-client" in INSTALL_HINT


def test_missing_joint_and_silent_server_are_clear_errors():
    sim = FakeSim({})
    with pytest.raises(RuntimeError, match="/NAO/RShoulderPitch"):
        CoppeliaNao(client_factory=lambda h, p: FakeClient(sim)).start()
    never = threading.Event()

    def blocking_factory(host, port):
        never.wait(5.0)  # a REQ socket with no server: no answer
        raise ConnectionError("gave up")

    with pytest.raises(RuntimeError, match="no answer"):
        CoppeliaNao(connect_timeout_s=0.1, client_factory=blocking_factory).start()
    never.set()


def test_bad_arguments_and_commands():
    with pytest.raises(ValueError, match="side"):
        CoppeliaNao("both")
    with pytest.raises(ValueError, match="joint_path"):
        CoppeliaNao(joint_path="/NAO/RShoulderPitch")
    nao = CoppeliaNao(client_factory=lambda h, p: FakeClient(FakeSim({})))
    with pytest.raises(RuntimeError, match="start"):
        nao.command(0.0, np.zeros(3), NO_CLAMP)
    sim = FakeSim({f"/NAO/R{j}": k for k, j in enumerate(["ShoulderPitch", "ShoulderRoll",
                                                          "ElbowYaw"])})
    with CoppeliaNao(client_factory=lambda h, p: FakeClient(sim)) as nao:
        with pytest.raises(ValueError, match="finite"):
            nao.command(0.0, np.array([np.nan, 0.0, 0.0]), NO_CLAMP)
    nao.close()  # idempotent
    with pytest.raises(RuntimeError, match="closed"):
        nao.start()


def test_a_failed_send_is_reported_by_the_next_command():
    class FailingSim(FakeSim):
        def setJointTargetPosition(self, handle, position):  # noqa: N802
            raise ConnectionError("server went away")

    sim = FailingSim({f"/NAO/R{j}": k for k, j in enumerate(["ShoulderPitch", "ShoulderRoll",
                                                             "ElbowYaw"])})
    with CoppeliaNao(client_factory=lambda h, p: FakeClient(sim)) as nao:
        nao.command(0.0, np.zeros(3), NO_CLAMP)
        assert wait_for(lambda: not nao._thread.is_alive())
        with pytest.raises(RuntimeError, match="server went away"):
            nao.command(0.0, np.zeros(3), NO_CLAMP)
