"""The acquisition thread: one serial link → validated frames in a bounded buffer.

:class:`SerialFrameSource` implements :class:`~exohil.harness.frame_source.FrameSource` for
any pyserial URL (``serial.serial_for_url``: a pty path such as the emulator's, ``/dev/ttyACM0``,
``loop://``, ``socket://host:port``). The reader thread

* reads what is available in chunks (``read(max(1, in_waiting))`` with a 1 ms timeout) and
  stamps each chunk with ``time.perf_counter_ns()``;
* decodes with :class:`~exohil.harness.link_decoder.StreamDecoder` (COBS, length, CRC,
  resynchronisation, wrap-aware sequence/time unwrapping);
* hands frames to a :class:`~exohil.harness.frame_buffer.FrameBuffer` that never blocks it
  (when full the oldest frames go, counted as ``overflow``);
* treats EIO, a vanished device, or "readable but empty" (pyserial raises SerialException) as
  a disconnect: closes the port and re-opens it with exponential backoff (capped), counting
  ``reconnects``; the sequence numbering continues, so frames lost meanwhile count as dropped.

``stop()`` wakes any wait and joins within a bounded time, whatever the link is doing.
"""

from __future__ import annotations

import dataclasses
import threading
import time
from collections.abc import Callable

import serial

from exohil.harness.frame_buffer import FrameBuffer
from exohil.harness.frame_source import Frame, LinkStats
from exohil.harness.link_decoder import StreamDecoder
from exohil.realtime import request_realtime

Opener = Callable[[str, float], serial.Serial]


def open_serial_url(url: str, read_timeout_s: float) -> serial.Serial:
    """Open any pyserial URL with a read timeout (seconds)."""
    return serial.serial_for_url(url, timeout=read_timeout_s)


class SerialFrameSource:
    """Frames from a serial link (see module doc).

    Args:
        url: pyserial URL or device path.
        expected_sensors: reject frames with another sensor count (None: accept any).
        buffer_frames: buffer capacity; the oldest frames are discarded beyond it.
        read_timeout_s: longest single blocking read, s (bounds stop latency). Short on
            purpose: each return re-polls the tty, and polling makes the kernel move bytes
            still queued in its flip buffer, instead of waiting for a normal-priority kernel
            worker that a loaded machine delays by milliseconds (see docs/emulator.md).
        backoff_initial_s / backoff_max_s: reconnect delay, doubling up to the cap, s.
        opener: how to open ``url`` (tests inject fakes); default :func:`open_serial_url`.
        realtime: run the reader thread under SCHED_FIFO (needs CAP_SYS_NICE; when refused,
            :attr:`realtime_error` says why).
    """

    def __init__(
        self,
        url: str,
        *,
        expected_sensors: int | None = None,
        buffer_frames: int = 4096,
        read_timeout_s: float = 0.001,
        backoff_initial_s: float = 0.01,
        backoff_max_s: float = 0.5,
        opener: Opener = open_serial_url,
        realtime: bool = False,
    ) -> None:
        self.url = url
        self._read_timeout_s = read_timeout_s
        self._backoff_initial_s = backoff_initial_s
        self._backoff_max_s = backoff_max_s
        self._opener = opener
        self._stats = LinkStats()
        self._lock = threading.Lock()
        self._decoder = StreamDecoder(self._stats, expected_sensors)
        self._buffer = FrameBuffer(buffer_frames)
        self._stop = threading.Event()
        self._connected = threading.Event()
        self._thread: threading.Thread | None = None
        self.last_error: str | None = None
        self.realtime = realtime
        self.realtime_error: str | None = None

    # ---- FrameSource -----------------------------------------------------------------
    def start(self) -> None:
        if self._thread is not None:
            raise RuntimeError("already started")
        self._thread = threading.Thread(target=self._run, name=f"acquire {self.url}", daemon=True)
        self._thread.start()

    def stop(self, timeout_s: float = 2.0) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout_s)

    def get(self, timeout: float | None = None) -> Frame | None:
        return self._buffer.get(timeout)

    def stats(self) -> LinkStats:
        with self._lock:
            return dataclasses.replace(self._stats)

    # ---- extras ------------------------------------------------------------------------
    def __enter__(self) -> SerialFrameSource:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def alive(self) -> bool:
        """True while the reader thread runs."""
        return self._thread is not None and self._thread.is_alive()

    @property
    def connected(self) -> bool:
        return self._connected.is_set()

    def wait_connected(self, timeout: float | None = None) -> bool:
        """Block until the port is open (True) or ``timeout`` s pass (False)."""
        return self._connected.wait(timeout)

    # ---- reader thread -----------------------------------------------------------------
    def _run(self) -> None:
        if self.realtime:
            self.realtime_error = request_realtime()
        backoff = self._backoff_initial_s
        opened_before = False
        while not self._stop.is_set():
            try:
                port = self._opener(self.url, self._read_timeout_s)
            except (serial.SerialException, OSError, ValueError) as exc:
                self.last_error = str(exc)
                self._stop.wait(backoff)
                backoff = min(2.0 * backoff, self._backoff_max_s)
                continue
            backoff = self._backoff_initial_s
            if opened_before:
                with self._lock:
                    self._stats.reconnects += 1
            opened_before = True
            self._connected.set()
            try:
                self._read_until_disconnect(port)
            finally:
                self._connected.clear()
                with self._lock:
                    self._decoder.reset()
                try:
                    port.close()
                except (serial.SerialException, OSError):
                    pass

    def _read_until_disconnect(self, port: serial.Serial) -> None:
        while not self._stop.is_set():
            try:
                data = port.read(max(1, port.in_waiting))
            except (serial.SerialException, OSError) as exc:
                self.last_error = str(exc)
                return
            if not data:
                continue
            host_ns = time.perf_counter_ns()
            with self._lock:
                frames = self._decoder.feed(data, host_ns)
                self._stats.overflow += self._buffer.put(frames)
