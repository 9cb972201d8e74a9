"""The pipeline drives any FrameSource through an estimator into sinks (a fake device here)."""

import queue
import threading
import time

import numpy as np

from exohil.harness.frame_source import Frame, FrameSource, LinkStats
from exohil.harness.pipeline import Pipeline, percentiles_us


class FakeSource:
    """A FrameSource fed from a list; counts frames like a link would."""

    def __init__(self, frames):
        self._q = queue.Queue()
        for f in frames:
            self._q.put(f)
        self._stats = LinkStats(frames=len(frames))

    def start(self):
        pass

    def stop(self):
        pass

    def get(self, timeout=None):
        try:
            return self._q.get(timeout=timeout)
        except queue.Empty:
            return None

    def stats(self):
        return self._stats


class SumEstimator:
    """Angles = (sum of values, number of frames seen): checks order and statefulness."""

    def __init__(self):
        self.count = 0
        self.out = np.zeros(2)

    def push(self, values):
        self.count += 1
        self.out[:] = (values.sum(), self.count)
        return self.out  # a reused buffer, like the real engine


def frames(n):
    now = time.perf_counter_ns()
    return [Frame(seq=k, device_time_s=k / 250, values_mm=np.full(4, float(k)), host_ns=now)
            for k in range(n)]


def test_fake_source_satisfies_the_protocol():
    assert isinstance(FakeSource([]), FrameSource)


def test_every_frame_reaches_every_sink_in_order():
    seen = []
    run = Pipeline(FakeSource(frames(50)), SumEstimator(),
                   [lambda f, a: seen.append((f.seq, a.copy()))]).run(max_frames=50)
    assert run.frames == 50 and [s for s, _ in seen] == list(range(50))
    assert np.array_equal(run.estimates[:, 0], 4.0 * np.arange(50))
    assert np.array_equal(run.estimates[:, 1], np.arange(1, 51))  # buffer reuse did not alias
    assert np.array_equal(run.seq, np.arange(50))
    assert np.all(run.latency_ns >= run.compute_ns) and np.all(run.compute_ns >= 0)


def test_run_ends_when_the_source_goes_quiet_or_stop_is_set():
    run = Pipeline(FakeSource(frames(5)), SumEstimator()).run(idle_timeout_s=0.2)
    assert run.frames == 5
    stop = threading.Event()
    stop.set()
    assert Pipeline(FakeSource(frames(5)), SumEstimator()).run(stop=stop).frames == 0


def test_percentiles_in_microseconds():
    ns = np.arange(1, 101) * 1000
    p = percentiles_us(ns)
    assert p["max_us"] == 100.0 and p["p50_us"] == 50.5
    assert np.isnan(percentiles_us(np.array([], dtype=np.int64))["p50_us"])


def test_recorder_sink_writes_every_frame_it_was_given(tmp_path):
    from exohil.formats.recording_reader import read_recording
    from exohil.harness.recorder import RecorderSink

    path = tmp_path / "session.mcap"
    with RecorderSink(path, ("F", "SF", "SR", "R"), metadata={"generator": "test"}) as recorder:
        run = Pipeline(FakeSource(frames(300)), SumEstimator(), [recorder]).run(max_frames=300)
    rec = read_recording(path)
    assert run.frames == 300 and recorder.frames_written == 300
    assert np.array_equal(rec.sensors.seq, np.arange(300))
    assert np.allclose(rec.sensors.values[:, 0], np.arange(300))
