"""Recorder sink: writes the frames the host received to a recording, off the hot path.

The MCAP writer compresses a 1 MiB chunk now and then (tens of ms), far longer than the 4 ms
frame period, so the pipeline only enqueues frames and a background thread writes them.
Nothing is dropped: the queue is unbounded, and :meth:`close` drains it before closing the file.

Nothing is lost either: the file is written as ``<path>.partial`` by a durable writer (metadata
first, a chunk closed and synced to disk at least every second) and renamed to ``path`` when
closed. A killed run leaves ``<path>.partial``, which the reader reads (noting it was cut
short, at most the last second lost) and ``exohil record recover`` turns into a clean file;
an existing file at ``path`` is only replaced by a complete recording.

The metadata's ``sensor_rate_hz`` is the configured (nominal) rate; the device's rate as its
frames show it (:mod:`~exohil.harness.device_rate`, over at least 1 s of device time) is written
beside it at close as ``measured_sensor_rate_hz``; given the link's counters
(:attr:`RecorderSink.link_stats`), the frames a device reboot missed count in it as in the run
summary's ``device_rate_hz``.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

from exohil.formats.recording_metadata import DEFAULT_SENSOR_RATE_HZ
from exohil.formats.recording_writer import RecordingWriter
from exohil.harness.device_rate import measured_rate_hz
from exohil.harness.frame_source import LinkStats
from exohil.harness.pipeline import Sample

_STOP = object()


def partial_path(path: Path) -> Path:
    """Where a recording to ``path`` is written until it is complete."""
    return path.with_name(path.name + ".partial")


class RecorderSink:
    """A pipeline sink that records the sensor frames the host received to ``path``."""

    def __init__(self, path: str | Path, sensor_names: Sequence[str], *,
                 sensor_units: str = "mm", metadata: Mapping[str, str] | None = None,
                 sensor_rate_hz: float = DEFAULT_SENSOR_RATE_HZ) -> None:
        self.path = Path(path)
        self.partial_path = partial_path(self.path)
        self._writer = RecordingWriter(self.partial_path, sensor_names,
                                       sensor_units=sensor_units, metadata=metadata,
                                       sensor_rate_hz=sensor_rate_hz, durable=True)
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self.frames_written = 0
        self.sensor_rate_hz = sensor_rate_hz
        self._first: tuple[int, float] | None = None
        self._last: tuple[int, float] | None = None
        self.error: BaseException | None = None
        #: the frame source's counters (its ``stats``), read at close for the frames a
        #: device reboot missed; None: no reboot is counted
        self.link_stats: Callable[[], LinkStats] | None = None
        self._thread = threading.Thread(target=self._run, name="recorder", daemon=True)
        self._thread.start()

    def accept(self, sample: Sample) -> None:
        self._queue.put(sample.frame)

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            if item is _STOP:
                return
            if self.error is not None:
                continue
            try:
                self._writer.add_sensor_frame(item.seq, item.device_time_s, item.values_mm)
                self.frames_written += 1
                self._last = (item.seq, item.device_time_s)
                if self._first is None:
                    self._first = self._last
            except Exception as err:  # keep draining; close() re-raises
                self.error = err

    def close(self) -> None:
        """Write everything queued, close the file and rename it into place; re-raises a
        write error (the ``.partial`` file then stays, readable up to the error). A session
        that recorded no frame (a device that never sent one) writes nothing: its empty
        ``.partial`` file is removed and a recording already at ``path`` stays as it was."""
        self._queue.put(_STOP)
        self._thread.join()
        measured = self.measured_rate_hz()
        if measured is not None and self.error is None:
            # beside the configured sensor_rate_hz, never instead of it (docs/recording-format.md)
            self._writer.add_metadata({"measured_sensor_rate_hz": f"{measured:.3f}"})
        self._writer.close()
        if self.error is not None:
            raise self.error
        if self.frames_written == 0:
            self.partial_path.unlink()
            return
        self.partial_path.replace(self.path)

    def measured_rate_hz(self) -> float | None:
        """The device's frame rate by its own seq and timestamps over the frames written
        (:func:`~exohil.harness.device_rate.measured_rate_hz`)."""
        if self._first is None or self._last is None:
            return None
        missed = 0 if self.link_stats is None else self.link_stats().dropped_in_resets
        return measured_rate_hz(self._first[0], self._last[0], self._first[1], self._last[1],
                                missed)

    def __enter__(self) -> RecorderSink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
