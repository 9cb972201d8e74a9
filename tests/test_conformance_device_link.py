"""The conformance suite against a device that is not the emulator: a fake device streaming a
recording's frames over a pty, as the firmware does (wire protocol v1, its own numbering and
clock). What it streams, not what the reference holds, is judged; and what the host can see
of its link (lost frames, rejected packets, reboots) fails the link check.
"""

from __future__ import annotations

import dataclasses
import os
import threading
import time
import tty
from pathlib import Path

import numpy as np
import pytest

from exohil.conformance.context import ConformanceRun
from exohil.conformance.profile import load_profile
from exohil.formats.measurement import Verdict
from exohil.formats.recording import cut_recording
from exohil.formats.recording_reader import read_recording
from exohil.formats.recording_writer import write_recording
from exohil.formats.wire import SEQ_MODULUS, TIME_MODULUS_US, WireFrame, encode_frame
from exohil.harness.paths import FIXTURES_DIR, MODELS_DIR

HELDOUT = FIXTURES_DIR / "paper_protocol_heldout.mcap"
ENNET = MODELS_DIR / "ennet.npz"
REFERENCE_S = 8.0


class FakeDevice:
    """Streams ``rec``'s motion over a pty at ``rate_hz`` (the frame nearest each sample
    time), numbering and stamping frames from 0 like the firmware. ``lose_every``: every
    n-th frame is numbered but never sent; ``reboot_at_s``: the device goes quiet for
    ``reboot_gap_s`` there and restarts its numbering and clock at 0."""

    QUIET_S = 2.0

    def __init__(self, rec, rate_hz: float, *, lose_every: int = 0,
                 reboot_at_s: float | None = None, reboot_gap_s: float = 0.0) -> None:
        self.t, self.values = rec.sensors.t, rec.sensors.values
        self.rate_hz, self.lose_every = rate_hz, lose_every
        self.reboot_at_s, self.reboot_gap_s = reboot_at_s, reboot_gap_s
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        os.set_blocking(self.master, False)
        self.path = os.ttyname(self.slave)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        # quiet at first, as a device is until the host has opened its port: a pty would
        # hold what it sent before that, and the host starts on the newest frames it reads
        self.stop.wait(self.QUIET_S)
        start, k, kdev = time.perf_counter(), 0, 0
        rebooted = self.reboot_at_s is None
        while not self.stop.is_set():
            st = k / self.rate_hz  # motion time since the stream began
            if not rebooted and st >= self.reboot_at_s:
                rebooted, kdev = True, 0
                time.sleep(self.reboot_gap_s)
                k = int((time.perf_counter() - start) * self.rate_hz)
                st = k / self.rate_hz
            i = min(int(np.searchsorted(self.t, self.t[0] + st)), len(self.t) - 1)
            raw = tuple(int(round(x / 0.01)) for x in self.values[i])
            frame = WireFrame(kdev % SEQ_MODULUS,
                              round(kdev / self.rate_hz * 1e6) % TIME_MODULUS_US, raw)
            k += 1
            if self.lose_every and kdev % self.lose_every == self.lose_every - 1:
                kdev += 1
            else:
                try:
                    os.write(self.master, encode_frame(frame))
                    kdev += 1
                except (BlockingIOError, OSError):
                    pass  # no host reading yet (a pty's buffer is full): wait for one
            while time.perf_counter() < start + k / self.rate_hz and not self.stop.is_set():
                time.sleep(0.0005)

    def __enter__(self) -> FakeDevice:
        self.thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop.set()
        self.thread.join(5)
        os.close(self.master)
        os.close(self.slave)


@pytest.fixture(scope="module")
def short_reference(tmp_path_factory) -> tuple[Path, object]:
    """The held-out recording's first seconds: the ground truth of every fake device here."""
    rec = cut_recording(read_recording(HELDOUT), 0.0, REFERENCE_S)
    path = tmp_path_factory.mktemp("ref") / "short.mcap"
    write_recording(path, rec)
    return path, rec


def measured(device: FakeDevice, reference: Path, check: str, profile: str = "ci") -> dict:
    """The named profile's limits, with a real-time segment the short reference can hold
    (a device's segment is its reference's span, and must reach 90 % of the profile's)."""
    limits = load_profile(profile)
    fitted = dataclasses.replace(limits, settings={**limits.settings,
                                                   "realtime_seconds": REFERENCE_S - 1.0})
    run = ConformanceRun(device.path, ENNET, fitted, reference=reference)
    with device:
        out = getattr(run, f"{check}_measurements")()
    return {m.name: m for m in out}


def test_a_device_at_another_rate_than_the_model_fails_compatibility_with_a_reference(
        short_reference) -> None:
    """The reference runs at the model's 250 Hz, the device at 100 Hz: the model's window
    would span 2.5 times the time it was trained on; the device's rate is what counts."""
    path, rec = short_reference
    got = measured(FakeDevice(rec, 100.0), path, "compatibility")
    rate = got["compatibility.rate_mismatch"]
    assert rate.verdict is Verdict.FAIL, rate.note
    assert "the device streams at 100" in rate.note and "reference's sensors at 250" in rate.note
    # the device's own frames are those checked against the training data
    assert got["compatibility.outside_training"].verdict is Verdict.PASS
    assert "frames" in got["compatibility.outside_training"].note


def test_a_device_at_the_models_rate_passes_compatibility(short_reference) -> None:
    path, rec = short_reference
    got = measured(FakeDevice(rec, 250.0), path, "compatibility")
    assert all(m.verdict is Verdict.PASS for m in got.values()), got
    assert "the device streams at 250" in got["compatibility.rate_mismatch"].note


def test_a_device_losing_frames_fails_link(short_reference) -> None:
    """Every 5th frame lost (20 %): no fault log explains it, so the link check fails."""
    path, rec = short_reference
    got = measured(FakeDevice(rec, 250.0, lose_every=5), path, "link")
    lost = got["link.lost"]
    assert lost.verdict is Verdict.FAIL and lost.value > 0.15 * got["link.frames"].value
    assert got["link.lost_on_host"].verdict is Verdict.SKIP  # no fault log to reconcile


def test_a_device_that_reboots_fails_link_and_its_gap_is_counted(short_reference) -> None:
    """A reboot restarts the numbering: the host follows it, but the frames the device did
    not send while it rebooted (1 s, ~250 frames) are lost, and the reboot itself fails.
    (After 5 s: a numbering restarted within the decoder's 1024 recent frames repeats them,
    and is rejected as duplicates.)"""
    path, rec = short_reference
    got = measured(FakeDevice(rec, 250.0, reboot_at_s=5.0, reboot_gap_s=1.0), path, "link",
                   profile="bench")
    assert got["link.sequence_resets"].value == 1
    assert got["link.sequence_resets"].verdict is Verdict.FAIL
    assert 200 <= got["link.lost"].value <= 300, got["link.lost"].note
    assert got["link.lost"].verdict is Verdict.FAIL


def test_a_sound_device_passes_link(short_reference) -> None:
    path, rec = short_reference
    got = measured(FakeDevice(rec, 250.0), path, "link", profile="bench")
    failed = [m.describe() for m in got.values() if m.verdict is Verdict.FAIL]
    assert not failed
    for name in ("link.lost", "link.rejected", "link.sequence_resets", "link.disconnects"):
        assert got[name].verdict is Verdict.PASS and got[name].value == 0
