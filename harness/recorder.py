"""Recorder sink: writes the frames the host received to a recording, off the hot path.

The MCAP writer compresses a 1 MiB chunk now and then (tens of ms), far longer than the 4 ms
frame period, so the pipeline only enqueues frames and a background thread writes them.
Nothing is dropped: the queue is unbounded, and :meth:`close` drains it before closing the file.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Mapping, Sequence
from pathlib import Path

from exohil.formats.recording_writer import RecordingWriter
from exohil.harness.pipeline import Sample

_STOP = object()


class RecorderSink:
    """A pipeline sink that records the sensor frames the host received to ``path``."""

    def __init__(self, path: str | Path, sensor_names: Sequence[str], *,
                 sensor_units: str = "mm", metadata: Mapping[str, str] | None = None) -> None:
        self._writer = RecordingWriter(path, sensor_names, sensor_units=sensor_units,
                                       metadata=metadata)
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self.frames_written = 0
        self.error: BaseException | None = None
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
            except Exception as err:  # keep draining; close() re-raises
                self.error = err

    def close(self) -> None:
        """Write everything queued, close the file; re-raises a write error."""
        self._queue.put(_STOP)
        self._thread.join()
        self._writer.close()
        if self.error is not None:
            raise self.error

    def __enter__(self) -> RecorderSink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
