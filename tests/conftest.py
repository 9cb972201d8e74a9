"""Shared test configuration: hypothesis profiles.

``HYPOTHESIS_PROFILE=ci`` (set by .ci/run and tox) allows 1000 examples per property, which
the conversion properties use in full; expensive properties (a pty emulator per example, file
writes) set their own lower ``max_examples``. The default ``dev`` profile runs fewer.
"""

import os
import threading

import pytest
from hypothesis import HealthCheck, settings

settings.register_profile(
    "ci", max_examples=1000, deadline=None, suppress_health_check=[HealthCheck.too_slow]
)
settings.register_profile("dev", max_examples=200, deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "dev"))


def _realtime_refusal() -> str | None:
    """Why SCHED_FIFO is refused here, or None; asked from a short-lived thread, whose
    scheduling policy ends with it."""
    from exohil.realtime import request_realtime

    answer: list[str | None] = []
    probe = threading.Thread(target=lambda: answer.append(request_realtime()))
    probe.start()
    probe.join()
    return answer[0]


def pytest_runtest_setup(item: pytest.Item) -> None:
    """Tests select on the bench's features with markers: ``device`` runs only with a real
    device named by EXOHIL_DEVICE, ``realtime`` only where SCHED_FIFO is granted."""
    if item.get_closest_marker("device") and not os.environ.get("EXOHIL_DEVICE"):
        pytest.skip("no real device: set EXOHIL_DEVICE=/dev/ttyACM0 (a URL pyserial opens)")
    if item.get_closest_marker("realtime"):
        refusal = _realtime_refusal()
        if refusal:
            pytest.skip(refusal)
