"""A virtual serial port: a pseudo-terminal whose slave plays the device node.

The host opens ``path``, a stable symlink to the current pty slave (like udev's
``/dev/serial/by-id/...`` link to ``/dev/ttyACM0``). The emulator keeps only the master:

* host presence: while no process has the slave open, ``poll()`` on the master reports
  POLLHUP, so the emulator knows when nobody is listening (and does not write: a device's
  frames are lost when no host reads them, they do not pile up for a later reader);
* host readiness: the master is in packet mode (TIOCPKT), so when the host flushes its input
  queue (pyserial does so at the end of ``open()``) the master reads a TIOCPKT_FLUSHREAD
  status byte; frames written before that flush would be discarded by the host;
* never blocking: the master is non-blocking; a write that does not fit keeps its tail in a
  small pending buffer that is flushed first next time, and while it is not flushed new frames
  are refused (the caller logs them as "not read");
* disconnect: the symlink is removed and the master closed (the host's reads and ioctls fail
  with EIO, a new open fails with ENOENT), then :meth:`connect` makes a fresh pty and points the
  link at it (re-enumeration).
"""

from __future__ import annotations

import errno
import fcntl
import os
import pty
import select
import struct
import tempfile
import termios
import time
import tty
import weakref
from pathlib import Path

LINK_NAME = "ttyEXOHIL0"


class VirtualSerialPort:
    """One emulated device node; see the module docstring. Not thread-safe: one owner."""

    def __init__(self, link_dir: Path | None = None) -> None:
        self._dir = Path(link_dir) if link_dir else Path(tempfile.mkdtemp(prefix="exohil-emu-"))
        self._own_dir = link_dir is None
        if self._own_dir:  # a port never closed (never started, say) leaves no folder behind
            weakref.finalize(self, _remove_link_dir, self._dir)
        self.path = str(self._dir / LINK_NAME)
        self._master: int | None = None
        self._slave_name = ""
        self._poll = select.poll()
        self._pending = bytearray()
        self._pending_tag: int | None = None

    @property
    def connected(self) -> bool:
        """True while the port exists (between connect and disconnect)."""
        return self._master is not None

    def connect(self) -> None:
        """Create a fresh pty (slave in raw mode) and point ``path`` at its slave."""
        master, slave = pty.openpty()
        tty.setraw(slave)
        self._slave_name = os.ttyname(slave)
        os.close(slave)  # only the host holds the slave: POLLHUP on the master means "no host"
        os.set_blocking(master, False)
        fcntl.ioctl(master, termios.TIOCPKT, struct.pack("i", 1))
        self._master = master
        self._poll = select.poll()
        self._poll.register(master, select.POLLHUP)
        tmp_link = self._dir / f".{LINK_NAME}.tmp"
        tmp_link.unlink(missing_ok=True)
        os.symlink(self._slave_name, tmp_link)
        os.replace(tmp_link, self.path)

    def host_attached(self) -> bool:
        """True when some process has the slave open."""
        if self._master is None:
            return False
        return not any(ev & select.POLLHUP for _, ev in self._poll.poll(0))

    def host_flushed(self) -> bool:
        """Consume what the host sent (packet mode); True when it flushed its input queue
        since the last call. Bytes the host wrote to the device are discarded."""
        flushed = False
        for _ in range(64):
            try:
                packet = os.read(self._master, 4096) if self._master is not None else b""
            except (BlockingIOError, OSError):  # EAGAIN: nothing; EIO: no host
                break
            if not packet:
                break
            flushed = flushed or bool(packet[0] & termios.TIOCPKT_FLUSHREAD)
        return flushed

    def _open_slave_again(self) -> int | None:
        """A second, non-blocking fd on the slave the host holds (the caller closes it);
        None where it cannot be opened again (a host that made its open exclusive with
        TIOCEXCL)."""
        try:
            return os.open(self._slave_name, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        except OSError:
            return None

    def unread_bytes(self) -> int:
        """Bytes written that the host has not read yet, 0 without a host.

        Polling the slave first makes the kernel move bytes still waiting in the tty flip
        buffer into the line discipline (n_tty_poll flushes the buffer work), so FIONREAD
        counts them too (up to the line discipline's 4 KiB; more than that is "not drained"
        anyway)."""
        if self._master is None or not self.host_attached():
            return 0
        fd = self._open_slave_again()
        if fd is None:
            return 0
        try:
            select.select([fd], [], [], 0)
            buf = fcntl.ioctl(fd, termios.FIONREAD, b"\0\0\0\0")
            return int(struct.unpack("I", buf)[0])
        finally:
            os.close(fd)

    @property
    def pending_bytes(self) -> int:
        """Bytes of the last frame accepted that are not written to the pty yet."""
        return len(self._pending)

    def take_unread(self, settle_s: float = 0.002) -> list[bytes] | None:
        """Read out every byte written that the host has not read yet: the pieces read, in
        order ([] without a host); None when the slave cannot be opened a second time.

        For a port about to vanish, whose unread bytes the host loses anyway: unlike
        :meth:`unread_bytes`, this sees them all however far behind the host is (the tty
        flip buffer holds tens of KiB beyond the line discipline's 4 KiB). Each ``poll()``
        moves bytes still in the flip buffer into the line discipline; reading stops once
        none has arrived for ``settle_s``. A host still reading meanwhile takes the bytes
        between two pieces (the caller finds each piece in what it wrote). The pending tail
        is not included (:attr:`pending_bytes`)."""
        if self._master is None or not self.host_attached():
            return []
        fd = self._open_slave_again()
        if fd is None:
            return None
        pieces: list[bytes] = []
        try:
            poller = select.poll()
            poller.register(fd, select.POLLIN)
            while poller.poll(settle_s * 1000.0):
                try:
                    piece = os.read(fd, 65536)
                except BlockingIOError:  # the host read it first
                    continue
                except OSError:  # EIO: the port is going
                    break
                if not piece:
                    break
                pieces.append(piece)
        finally:
            os.close(fd)
        return pieces

    def drain(self, timeout_s: float, settle_s: float = 0.005) -> bool:
        """Wait until the host has read everything written (no unread byte for ``settle_s``),
        at most ``timeout_s``; True when drained."""
        self.flush_pending()
        deadline = time.perf_counter() + timeout_s
        empty_since: float | None = None
        while time.perf_counter() < deadline:
            now = time.perf_counter()
            if self._pending or self.unread_bytes():
                empty_since = None
                self.flush_pending()
            elif empty_since is None:
                empty_since = now
            elif now - empty_since >= settle_s:
                return True
            time.sleep(0.0005)
        return False

    def flush_pending(self) -> None:
        """Write as much of the pending tail as fits (never blocks)."""
        if self._pending and self._master is not None:
            written = self._write_some(bytes(self._pending))
            del self._pending[:written]
            if not self._pending:
                self._pending_tag = None

    def send(self, data: bytes, tag: int) -> bool:
        """Hand ``data`` (one frame, identified by ``tag``) to the host side without blocking.

        Returns False when refused (the pending tail of an earlier frame still does not fit).
        """
        self.flush_pending()
        if self._pending or self._master is None:
            return False
        written = self._write_some(data)
        if written < len(data):
            self._pending += data[written:]
            self._pending_tag = tag
        return True

    def discard_pending(self) -> int | None:
        """Drop the unsent tail; returns the tag of the frame it destroyed, if any."""
        tag = self._pending_tag
        self._pending.clear()
        self._pending_tag = None
        return tag

    def disconnect(self) -> int | None:
        """Make the port vanish; returns the tag of a frame destroyed mid-write, if any."""
        tag = self.discard_pending()
        Path(self.path).unlink(missing_ok=True)
        if self._master is not None:
            os.close(self._master)
            self._master = None
        return tag

    def close(self) -> None:
        """Disconnect and remove the link directory if this port created it."""
        self.disconnect()
        if self._own_dir:
            _remove_link_dir(self._dir)

    def _write_some(self, data: bytes) -> int:
        assert self._master is not None
        try:
            return os.write(self._master, data)
        except BlockingIOError:
            return 0
        except OSError as exc:
            if exc.errno in (errno.EIO, errno.EAGAIN):
                return 0
            raise


def _remove_link_dir(folder: Path) -> None:
    """Remove a link folder this module made: its links, then the folder (kept if anything
    else is in it)."""
    for name in (LINK_NAME, f".{LINK_NAME}.tmp"):
        path = folder / name
        if path.is_symlink():
            path.unlink(missing_ok=True)
    try:
        folder.rmdir()
    except OSError:
        pass
