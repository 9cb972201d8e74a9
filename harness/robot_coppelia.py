"""NAO joint commands to a NAO in CoppeliaSim through its ZMQ remote API.

:class:`CoppeliaNao` implements the :class:`~exohil.harness.teleop.JointTarget` protocol by
setting the target positions (radians) of the scene's NAO arm joints with
``sim.setJointTargetPosition``. It needs the optional package
``coppeliasim-zmqremoteapi-client`` (imported on :meth:`CoppeliaNao.start`, with a clear error
when missing) and a running CoppeliaSim with the ZMQ remote API add-on (port 23000 by
default) and a NAO in the scene. The test suite exercises it only against a stand-in client;
see docs/robot.md.

Remote API calls are round trips, so they run in a sender thread: :meth:`command` swaps the
newest command in under a lock and returns; a command the sender has not taken yet is
replaced (counted as superseded).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any, Literal

import numpy as np

from exohil.harness.robot_stats import LogHistogram
from exohil.kinematics import NAO_JOINTS

INSTALL_HINT = ("the CoppeliaSim target needs the package coppeliasim-zmqremoteapi-client: "
                "pip install coppeliasim-zmqremoteapi-client")


class MissingClientError(RuntimeError):
    """The optional package coppeliasim-zmqremoteapi-client is not installed."""


def _remote_api_client(host: str, port: int) -> Any:
    try:
        from coppeliasim_zmqremoteapi_client import RemoteAPIClient
    except ImportError as err:
        raise MissingClientError(INSTALL_HINT) from err
    return RemoteAPIClient(host=host, port=port)


class CoppeliaNao:
    """Drives one NAO arm in CoppeliaSim.

    Args:
        side: "right" or "left".
        host, port: the CoppeliaSim ZMQ remote API server.
        joint_path: object path of each joint, ``{joint}`` replaced by e.g.
            ``RShoulderPitch``; adjust it to the scene's NAO model.
        connect_timeout_s: how long :meth:`start` waits for the server and the joint handles.
        client_factory: ``(host, port) -> client`` with ``require("sim")``; the default is
            ``coppeliasim_zmqremoteapi_client.RemoteAPIClient``.
    """

    def __init__(self, side: Literal["right", "left"] = "right", host: str = "localhost",
                 port: int = 23000, *, joint_path: str = "/NAO/{joint}",
                 connect_timeout_s: float = 5.0,
                 client_factory: Callable[[str, int], Any] | None = None) -> None:
        if side not in ("right", "left"):
            raise ValueError(f"side must be 'right' or 'left', got {side!r}")
        if "{joint}" not in joint_path:
            raise ValueError(f"joint_path must contain '{{joint}}', got {joint_path!r}")
        self.side, self.host, self.port = side, host, port
        self.joint_names = [("R" if side == "right" else "L") + j for j in NAO_JOINTS]
        self.joint_paths = [joint_path.format(joint=name) for name in self.joint_names]
        self._timeout = connect_timeout_s
        self._factory = client_factory or _remote_api_client
        self._cond = threading.Condition()
        self._pending: np.ndarray | None = None
        self._stop = False
        self._closed = False
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._thread: threading.Thread | None = None
        self.commands = 0
        self.superseded = 0
        self.sent = 0
        self._send_ms = LogHistogram(1e-3, 1e5)

    def start(self) -> None:
        """Connect (in the sender thread) and look up the joints. Raises
        :class:`MissingClientError` (a RuntimeError) when the client package is missing, and
        RuntimeError when the server does not answer within ``connect_timeout_s``,
        or a joint is not in the scene. No-op when started."""
        if self._closed:
            raise RuntimeError("CoppeliaNao is closed")
        if self._thread is not None:
            return
        self._thread = threading.Thread(target=self._run, name="coppelia-nao", daemon=True)
        self._thread.start()
        if not self._ready.wait(self._timeout):
            self.close()
            raise RuntimeError(f"no answer from CoppeliaSim at {self.host}:{self.port} within "
                               f"{self._timeout} s (is the ZMQ remote API running?)")
        if self._error is not None:
            error = self._error
            self.close()
            if isinstance(error, MissingClientError):
                raise error
            raise RuntimeError(f"CoppeliaSim at {self.host}:{self.port}: {error}") from error

    def _run(self) -> None:
        try:
            client = self._factory(self.host, self.port)
            sim = client.require("sim")
            handles = [sim.getObject(path) for path in self.joint_paths]
        except Exception as err:  # reported by start()
            self._error = err
            self._ready.set()
            return
        self._ready.set()
        while True:
            with self._cond:
                while self._pending is None and not self._stop:
                    self._cond.wait()
                if self._stop:
                    return
                target, self._pending = self._pending, None
            assert target is not None  # the wait above ends with a target or on stop
            began = time.perf_counter()
            try:
                for handle, angle in zip(handles, target, strict=True):
                    sim.setJointTargetPosition(handle, float(angle))
            except Exception as err:  # the next command() reports it
                self._error = err
                return
            self._send_ms.add((time.perf_counter() - began) * 1e3)
            self.sent += 1

    def command(self, t: float, joints: np.ndarray, clamped: np.ndarray) -> None:
        """Queue ``joints`` (radians, NAO_JOINTS order) as the newest target. ValueError for a
        wrong shape or non-finite angles; RuntimeError when not started, closed, or when an
        earlier send failed (the sender thread then stopped)."""
        if self._closed or self._thread is None:
            raise RuntimeError("CoppeliaNao is not running (call start() first)")
        if self._error is not None:
            raise RuntimeError(f"CoppeliaSim sender stopped: {self._error}") from self._error
        angles = np.asarray(joints, dtype=float)
        if angles.shape != (3,) or not np.all(np.isfinite(angles)):
            raise ValueError(f"joints must be 3 finite angles, got {angles.tolist()}")
        with self._cond:
            if self._pending is not None:
                self.superseded += 1
            self._pending = angles.copy()
            self.commands += 1
            self._cond.notify()

    def close(self) -> None:
        """Stop the sender thread (it finishes a send in progress). Idempotent. A thread
        blocked on a server that never answered is left to exit with the process."""
        self._closed = True
        with self._cond:
            self._stop = True
            self._cond.notify()
        if self._thread is not None and self._ready.is_set():
            self._thread.join(timeout=5.0)

    def __enter__(self) -> CoppeliaNao:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def summary(self) -> dict:
        """JSON-able: commands, sent, superseded, and the remote calls' time per command (ms)."""
        return {"host": self.host, "port": self.port, "side": self.side,
                "joint_paths": self.joint_paths, "commands": self.commands, "sent": self.sent,
                "superseded_commands": self.superseded,
                "send_ms": self._send_ms.summary()}
