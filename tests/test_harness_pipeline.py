"""The pipeline drives any FrameSource through an estimator into sinks (a fake device here)."""

import queue
import threading
import time

import numpy as np
import pytest

from exohil.harness.frame_source import Frame, FrameSource, LinkStats
from exohil.harness.pipeline import NOT_STAMPED, STAGES, Pipeline, Sample


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


class ListSink:
    def __init__(self, stage=None):
        self.seen = []
        self.stage = stage
        self.closed = False

    def accept(self, sample: Sample):
        self.seen.append((sample.frame.seq, sample.angles.copy(), dict(sample.stamps)))
        if self.stage:
            sample.stamps[self.stage] = time.perf_counter_ns()

    def close(self):
        self.closed = True


def test_every_frame_reaches_every_sink_in_order():
    first, second = ListSink(stage="commanded"), ListSink()
    run = Pipeline(FakeSource(frames(50)), SumEstimator(), [first, second]).run(max_frames=50)
    assert run.frames == 50 and [s for s, _, _ in first.seen] == list(range(50))
    assert np.array_equal(run.estimates[:, 0], 4.0 * np.arange(50))
    assert np.array_equal(run.estimates[:, 1], np.arange(1, 51))  # buffer reuse did not alias
    assert np.array_equal(run.seq, np.arange(50))
    assert all("commanded" in stamps for _, _, stamps in second.seen)  # sinks run in order
    assert not first.closed  # the sinks' owner closes them


def test_every_frame_is_stamped_in_stage_order():
    writes = {k: time.perf_counter_ns() - 1000 for k in range(0, 20, 2)}  # odd frames unknown
    run = Pipeline(FakeSource(frames(20)), SumEstimator(), [ListSink(stage="commanded")],
                   device_clock=writes.get).run(max_frames=20)
    stamps = run.stamps
    device = stamps[:, STAGES.index("device_write")]
    assert np.all(device[::2] != NOT_STAMPED) and np.all(device[1::2] == NOT_STAMPED)
    later = stamps[:, STAGES.index("host_receive"):]
    later = later[:, [i for i, s in enumerate(STAGES[1:]) if s != "decoded"]]  # fake: no decode
    assert np.all(np.diff(later, axis=1) >= 0)
    assert run.interval_ms("device_write", "done").shape == (10,)
    assert np.all(run.interval_ms("host_receive", "done") >= 0)
    assert np.all(np.isnan(run.commands))  # ListSink issues no robot command


def test_run_ends_when_the_source_goes_quiet_or_stop_is_set():
    run = Pipeline(FakeSource(frames(5)), SumEstimator()).run(idle_timeout_s=0.2)
    assert run.frames == 5
    stop = threading.Event()
    stop.set()
    assert Pipeline(FakeSource(frames(5)), SumEstimator()).run(stop=stop).frames == 0


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


def test_progress_reports_the_frames_since_the_previous_status():
    statuses = []

    class SlowSource(FakeSource):
        def get(self, timeout=None):
            time.sleep(0.002)
            return super().get(timeout)

    Pipeline(SlowSource(frames(100)), SumEstimator()).run(
        max_frames=100, progress=statuses.append, progress_every_s=0.05)
    assert len(statuses) >= 2
    assert sum(s.recent_estimates.shape[0] for s in statuses) <= 100
    assert statuses[-1].frames >= statuses[0].frames
    for s in statuses:
        assert s.recent_latency_ms.shape[0] == s.recent_device_time_s.shape[0]
        assert np.all(s.recent_latency_ms >= 0) and s.error_deg is None


def test_a_run_longer_than_one_log_block_keeps_every_frame_in_order():
    n = 9001  # more than two 4096-frame blocks
    statuses = []
    run = Pipeline(FakeSource(frames(n)), SumEstimator()).run(
        max_frames=n, progress=statuses.append, progress_every_s=0.0)
    assert run.frames == n and np.array_equal(run.seq, np.arange(n))
    assert np.array_equal(run.estimates[:, 1], np.arange(1, n + 1))
    assert np.array_equal(run.values[:, 0], np.arange(n, dtype=float))
    assert run.stamps.shape == (n, len(STAGES)) and np.all(np.isnan(run.commands))
    seen = np.concatenate([s.recent_device_time_s for s in statuses])
    assert np.array_equal(seen, run.device_time_s[: seen.size])  # statuses tile the run


class CountingSource(FakeSource):
    """Frames made on demand (seq 0, 1, ...), so a long run holds no list of them."""

    def __init__(self, n):
        super().__init__([])
        self.n, self.next = n, 0

    def get(self, timeout=None):
        if self.next >= self.n:
            return None
        k, self.next = self.next, self.next + 1
        return Frame(seq=k, device_time_s=k / 250, values_mm=np.full(4, float(k)),
                     host_ns=time.perf_counter_ns())


def test_a_long_run_holds_its_memory_steady_and_still_counts_every_frame(monkeypatch):
    from exohil.harness import pipeline

    sizes = []

    class SmallLog(pipeline._Log):
        BLOCK, FOLD = 64, 16  # the real sizes, scaled down

        def add(self, *args):
            super().add(*args)
            if self.n % self.BLOCK == 0:
                sizes.append(self.nbytes)

    monkeypatch.setattr(pipeline, "_Log", SmallLog)
    n = 64 * 60
    folded = []
    writes = {k: time.perf_counter_ns() - 1000 for k in range(n)}
    run = Pipeline(CountingSource(n), SumEstimator(), [ListSink(stage="commanded")],
                   device_clock=writes.get, keep_first=128, keep_last=100,
                   observers=[lambda rows: folded.append(rows.seq.copy())]).run(max_frames=n)
    # the window is 2 blocks at the start and 2 + the one being filled at the end: once it is
    # full, the kept rows and the totals take the same bytes frame after frame
    full = 2 + 3
    assert len(sizes) == 60 and sizes[full] > sizes[0]
    assert sizes[full - 1:] == [sizes[full - 1]] * (60 - full + 1)
    # the rows: the first 128 frames and the last 192 (>= 100), in order
    assert run.frames == n and run.retained == 128 + 192 and run.head == 128
    assert not run.complete
    assert np.array_equal(run.seq, np.r_[0:128, n - 192:n])
    assert np.array_equal(run.estimates[:, 1], run.seq + 1)
    # every frame was folded exactly once, in order, into the totals and the observers
    assert np.array_equal(np.concatenate(folded), np.arange(n))
    assert all(len(chunk) <= 16 for chunk in folded)
    assert run.compute_ms.count == n and run.commanded == 0 and run.clamped_commands == 0
    assert run.stamped == {"device_write": n, "host_receive": n, "decoded": 0, "estimated": n,
                           "commanded": n, "done": n}
    assert run.interval_histogram("device_write", "commanded").count == n
    assert run.interval_histogram("host_receive", "decoded").count == 0
    assert (run.first_seq, run.last_seq) == (0, n - 1)
    assert run.last_device_time_s == (n - 1) / 250


def test_latency_totals_agree_with_the_rows_of_a_run_that_fits():
    n = 600
    writes = {k: time.perf_counter_ns() - 1000 * (k % 7 + 1) for k in range(n)}
    run = Pipeline(FakeSource(frames(n)), SumEstimator(), [ListSink(stage="commanded")],
                   device_clock=writes.get).run(max_frames=n)
    assert run.complete and run.head == run.retained == n
    width = 10 ** (1 / 200)  # one histogram bin
    for i, start in enumerate(STAGES):
        for end in STAGES[i + 1:]:
            exact = np.maximum(run.interval_ms(start, end), 0.0)
            hist = run.interval_histogram(start, end)
            assert hist.count == exact.size
            if exact.size:
                assert hist.max == exact.max()
                for q in (0.5, 0.99):
                    value = float(np.quantile(exact, q, method="inverted_cdf"))
                    assert value <= hist.quantile(q) <= max(value, 1e-3) * width * (1 + 1e-9)
    with pytest.raises(ValueError, match="does not come before"):
        run.interval_histogram("done", "host_receive")
