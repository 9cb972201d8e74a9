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
  a disconnect (counted ``disconnects``): closes the port and re-opens it with exponential
  backoff (capped), counting ``reconnects``; the sequence numbering continues, so frames lost
  meanwhile count as dropped (and ``dropped_in_disconnects``);
* re-opens a device path only if it still leads to the same device (:func:`same_device`):
  a path that now leads elsewhere (a stale link to a pty that another process got after the
  emulator died, another USB device) is not opened, counted ``wrong_device``, and retried;
* with ``device_timeout_s``, ends when no frame has arrived for that long (a device that never
  returns): :attr:`SerialFrameSource.alive` goes False, :attr:`~SerialFrameSource.device_timed_out`
  True, and ``last_error`` says why.

``stop()`` wakes any wait and joins within a bounded time, whatever the link is doing.
"""

from __future__ import annotations

import dataclasses
import math
import os
import stat
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import serial
from serial.tools.list_ports_linux import SysFS

from exohil.harness.frame_buffer import FrameBuffer
from exohil.harness.frame_source import Frame, LinkStats
from exohil.harness.link_decoder import StreamDecoder
from exohil.realtime import request_realtime

Opener = Callable[[str, float], serial.Serial]


def open_serial_url(url: str, read_timeout_s: float) -> serial.Serial:
    """Open any pyserial URL with a read timeout (seconds)."""
    return serial.serial_for_url(url, timeout=read_timeout_s)


@dataclass(frozen=True)
class DeviceIdentity:
    """What a device path leads to, to tell the same device from another one on re-open.

    Attributes:
        node: (st_rdev, st_ino, st_ctime_ns) of the device node the path resolves to; a
            node created anew (a new pty, even at the same /dev/pts number; a re-enumerated
            USB device) has a new ctime.
        link: (st_ino, st_ctime_ns) of the path itself when it is a symlink (the emulator's
            stable link, udev's /dev/serial/by-*/ links): a new value means whoever manages the
            link re-pointed it; None for a plain device path.
        usb: (vid, pid, serial number, or the USB port path when the device has none) for a
            USB serial device (from sysfs, as pyserial's list_ports reads it); None otherwise.
    """

    node: tuple[int, int, int]
    link: tuple[int, int] | None
    usb: tuple[int, int, str] | None


def device_identity(url: str) -> DeviceIdentity | None:
    """The identity of the device ``url`` leads to now; None for a URL that is not a local
    path (``loop://``, ``socket://``: nothing to check) or a path that does not exist."""
    if "://" in url:
        return None
    try:
        node = os.stat(url)
        path = os.lstat(url)
    except OSError:
        return None
    link = (path.st_ino, path.st_ctime_ns) if stat.S_ISLNK(path.st_mode) else None
    info = SysFS(os.path.realpath(url))
    usb = None
    if info.vid is not None and info.pid is not None:
        usb = (info.vid, info.pid, info.serial_number or info.location or "")
    return DeviceIdentity((node.st_rdev, node.st_ino, node.st_ctime_ns), link, usb)


def same_device(known: DeviceIdentity, now: DeviceIdentity) -> bool:
    """Whether ``now`` is still the device first opened as ``known``.

    USB devices are the same when vendor, product and serial number (or port) match; otherwise
    the same node is the same device, and a new node is accepted only behind a symlink that was
    re-pointed since (re-enumeration, as udev and the emulator do it). A stale link (unchanged,
    its target re-created for someone else) and a plain path to a new node are refused.
    """
    if known.usb is not None or now.usb is not None:
        return known.usb == now.usb
    if known.node == now.node:
        return True
    return known.link is not None and now.link is not None and known.link != now.link


def _opened_node(port: serial.SerialBase) -> tuple[int, int, int] | None:
    """(st_rdev, st_ino, st_ctime_ns) of the node an opened port reads, when it has an fd."""
    fd = getattr(port, "fd", None)
    if not isinstance(fd, int):
        return None
    try:
        node = os.fstat(fd)
    except OSError:
        return None
    return node.st_rdev, node.st_ino, node.st_ctime_ns


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
        device_timeout_s: end the reader when no frame has been delivered for this long, s,
            since the last one (or since ``start()``), connected or not; None: retry forever.
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
        device_timeout_s: float | None = None,
    ) -> None:
        if not isinstance(url, str) or not url:
            raise ValueError(f"url must be a device path or a pyserial URL, got {url!r}")
        if device_timeout_s is not None and not device_timeout_s > 0:
            raise ValueError("device_timeout_s must be > 0 s")
        for what, seconds in (("read_timeout_s", read_timeout_s),
                              ("backoff_initial_s", backoff_initial_s),
                              ("backoff_max_s", backoff_max_s)):
            # a read without timeout would block stop(); a zero backoff would spin
            if seconds is None or not 0 < seconds < math.inf:
                raise ValueError(f"{what} must be a finite number of seconds > 0, got {seconds!r}")
        self.url = url
        self.device_timeout_s = device_timeout_s
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
        self._last_frame_ns = time.perf_counter_ns()
        self._bytes_without_frame = 0  # read since the last frame was delivered
        self._timed_out = False

    # ---- FrameSource -----------------------------------------------------------------
    def start(self) -> None:
        if self._thread is not None or self._stop.is_set():
            raise RuntimeError(f"the source of {self.url} was started before: a source runs "
                               "once; make a new one")
        self._last_frame_ns = time.perf_counter_ns()
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
        """True while the reader thread runs (False after ``stop()`` or a device timeout)."""
        return self._thread is not None and self._thread.is_alive()

    @property
    def device_timed_out(self) -> bool:
        """True once the reader ended because no frame came for ``device_timeout_s``."""
        return self._timed_out

    def seconds_since_last_frame(self) -> float:
        """Host time since the last frame was delivered (or since ``start()``), s."""
        return (time.perf_counter_ns() - self._last_frame_ns) / 1e9

    @property
    def connected(self) -> bool:
        return self._connected.is_set()

    def wait_connected(self, timeout: float | None = None) -> bool:
        """Block until the port is open (True) or ``timeout`` s pass (False)."""
        return self._connected.wait(timeout)

    # ---- reader thread -----------------------------------------------------------------
    def _expired(self) -> bool:
        """Check the device timeout; on expiry record why and return True."""
        if self.device_timeout_s is None or self._timed_out:
            return self._timed_out
        silent_s = self.seconds_since_last_frame()
        if silent_s < self.device_timeout_s:
            return False
        if not self.connected:
            state = "not connected"
        elif self._bytes_without_frame:
            state = (f"connected; {self._bytes_without_frame} bytes arrived since the last "
                     "frame and none was a wire-protocol v1 frame")
        else:
            state = "connected but silent"
        cause = f"; last error: {self.last_error}" if self.last_error else ""
        self.last_error = (f"no frame from {self.url} for {silent_s:.1f} s (device timeout "
                           f"{self.device_timeout_s:g} s, {state}){cause}")
        self._timed_out = True
        return True

    def _wait(self, seconds: float) -> None:
        """Sleep up to ``seconds``, waking for stop() or the device timeout."""
        if self.device_timeout_s is not None:
            left = self.device_timeout_s - self.seconds_since_last_frame()
            seconds = max(0.0, min(seconds, left))
        self._stop.wait(seconds)

    def _run(self) -> None:
        if self.realtime:
            self.realtime_error = request_realtime()
        backoff = self._backoff_initial_s
        opened_before = False
        known: DeviceIdentity | None = None
        while not self._stop.is_set() and not self._expired():
            identity = device_identity(self.url)
            if known is not None and (identity is None or not same_device(known, identity)):
                if identity is not None:
                    with self._lock:
                        self._stats.wrong_device += 1
                    self.last_error = (f"{self.url} now leads to another device than the one "
                                       "opened first; not opening it")
                else:
                    self.last_error = f"{self.url} does not exist"
                self._wait(backoff)
                backoff = min(2.0 * backoff, self._backoff_max_s)
                continue
            try:
                port = self._opener(self.url, self._read_timeout_s)
            except ValueError as exc:  # pyserial: a URL it cannot open, ever ('bogus://x')
                self.last_error = str(exc)
                return
            except (serial.SerialException, OSError) as exc:
                self.last_error = str(exc)
                self._wait(backoff)
                backoff = min(2.0 * backoff, self._backoff_max_s)
                continue
            opened = _opened_node(port)
            if identity is not None and opened is not None and opened != identity.node:
                _close(port)  # the path changed between stat and open: look again
                continue
            known = identity
            backoff = self._backoff_initial_s
            if opened_before:
                with self._lock:
                    self._stats.reconnects += 1
            opened_before = True
            self._connected.set()
            try:
                lost = self._read_until_disconnect(port)
            finally:
                self._connected.clear()
                with self._lock:
                    self._decoder.reset()
                _close(port)
            if lost:
                with self._lock:
                    self._stats.disconnects += 1

    def _read_until_disconnect(self, port: serial.Serial) -> bool:
        """Read and decode until the link fails (True), stop() or the device timeout."""
        while not self._stop.is_set():
            try:
                data = port.read(max(1, port.in_waiting))
            except (serial.SerialException, OSError) as exc:
                self.last_error = str(exc)
                return True
            if not data:
                if self._expired():
                    return False
                continue
            host_ns = time.perf_counter_ns()
            with self._lock:
                frames = self._decoder.feed(data, host_ns)
                self._stats.overflow += self._buffer.put(frames)
            if frames:
                self._last_frame_ns = host_ns
                self._bytes_without_frame = 0
            else:
                self._bytes_without_frame += len(data)
            if not frames and self._expired():
                return False
        return False


def _close(port: serial.SerialBase) -> None:
    """Close ``port``, ignoring errors from a device that is already gone."""
    try:
        port.close()
    except (serial.SerialException, OSError):
        pass
