"""A bounded frame buffer that never blocks its producer: when full, the oldest frame goes."""

from __future__ import annotations

import threading
from collections import deque

from exohil.harness.frame_source import Frame


class FrameBuffer:
    """FIFO of at most ``capacity`` frames; :meth:`put` returns how many old frames it evicted."""

    def __init__(self, capacity: int) -> None:
        if capacity < 1:
            raise ValueError("capacity must be >= 1")
        self._frames: deque[Frame] = deque()
        self._capacity = capacity
        self._ready = threading.Condition()

    def put(self, frames: list[Frame]) -> int:
        """Append ``frames`` (never waits on readers); returns the number evicted."""
        if not frames:
            return 0
        with self._ready:
            self._frames.extend(frames)
            evicted = max(0, len(self._frames) - self._capacity)
            for _ in range(evicted):
                self._frames.popleft()
            self._ready.notify_all()
        return evicted

    def get(self, timeout: float | None = None) -> Frame | None:
        """The oldest frame, waiting up to ``timeout`` s (None: forever); None on timeout."""
        with self._ready:
            if not self._frames and not self._ready.wait_for(lambda: self._frames, timeout):
                return None
            return self._frames.popleft()

    def __len__(self) -> int:
        return len(self._frames)
