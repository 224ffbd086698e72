"""The stub's byte streams where pymavlink does not behave as a vehicle's link does.

- ``tcp:HOST:PORT``: a client that waits for its server and comes back to it. pymavlink's
  ``mavtcp`` gives up when nothing listens yet and takes an idle socket for a closed one; a
  companion listening with ``tcpin:`` may start after the stub, or restart.
- ``pty`` or ``pty:PATH``: the vehicle's serial port, as a flight controller's USB port
  appears to the computer beside it. The stub opens a pseudo-terminal (``os.openpty``),
  serves MAVLink on the master side and leaves the slave device (``/dev/pts/N``, linked
  from ``PATH`` if given) for the companion, which opens it as a serial device
  (``--connect /dev/pts/N,115200``; pyserial sets it raw, the baud rate is ignored).

The companion's own code for these is not used here (``ezcompanion.wire``): the stub is
the other side of what it tests. Not thread-safe: the stub's thread owns its stream.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import math
import os
import socket
import time
import tty
from pathlib import Path

from ezcompanion.endpoint import pymavlink_url
from ezcompanion.errors import ConfigError

__all__ = ["PtyStream", "TcpClientStream", "check_stub_url", "is_pty_url"]

_log = logging.getLogger(__name__)

_RECONNECT_S = 1.0  # as MAVProxy, and as ArduPilot's own TCP client
_CONNECT_TIMEOUT_S = 0.5


def is_pty_url(url: str) -> bool:
    """``pty`` or ``pty:PATH``: the stub serves a pseudo-terminal."""
    return url == "pty" or url.startswith("pty:")


def check_stub_url(text: object, *, field: str = "connect") -> str:
    """A stub endpoint: what the companion accepts (either spelling, as pymavlink's string),
    or ``pty`` / ``pty:PATH`` (PATH absolute, in a directory that exists)."""
    if isinstance(text, str) and is_pty_url(text):
        path = text[len("pty:") :] if text != "pty" else ""
        if path:
            link = Path(path)
            if not link.is_absolute() or not link.parent.is_dir():
                raise ConfigError(field, text, "pty:PATH needs an absolute PATH in a directory "
                                  "that exists")  # fmt: skip
        return text
    return pymavlink_url(text, field=field)


class TcpClientStream:
    """A ``tcp:`` client: connected, or trying its server again every second."""

    def __init__(self, address: tuple[str, int], *, url: str) -> None:
        self.address = address
        self.url = url
        self.connections = 0
        self._sock: socket.socket | None = None
        self._pending = b""
        self._next_attempt_s = -math.inf
        self._told = False
        self._idle_r, self._idle_w = os.pipe()  # never readable: a down client waits on it
        self.poll()

    @property
    def connected(self) -> bool:
        return self._sock is not None

    @property
    def local_address(self) -> tuple[str, int] | None:
        if self._sock is None:
            return None
        host, port = self._sock.getsockname()[:2]
        return str(host), int(port)

    def fileno(self) -> int:
        return self._sock.fileno() if self._sock is not None else self._idle_r

    def poll(self) -> None:
        """Try the server once if down and an attempt is due."""
        if self._sock is not None or time.monotonic() < self._next_attempt_s:
            return
        try:
            sock = socket.create_connection(self.address, timeout=_CONNECT_TIMEOUT_S)
        except OSError as exc:
            self._next_attempt_s = time.monotonic() + _RECONNECT_S
            if not self._told:
                self._told = True
                _log.warning("%s: cannot connect (%s); trying every %g s", self.url,
                             exc.strerror or exc, _RECONNECT_S)  # fmt: skip
            return
        sock.setblocking(False)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._sock, self._told = sock, False
        self.connections += 1

    def _drop(self, why: str) -> None:
        assert self._sock is not None
        with contextlib.suppress(OSError):
            self._sock.close()
        self._sock, self._pending = None, b""
        self._next_attempt_s = time.monotonic() + _RECONNECT_S
        _log.warning("%s: %s; reconnecting every %g s", self.url, why, _RECONNECT_S)
        self._told = True

    def read(self) -> bytes | None:
        """Bytes waiting now, or None (nothing yet, or down). Only b"" is a close."""
        if self._sock is None:
            self.poll()
            return None
        try:
            data = self._sock.recv(4096)
        except (BlockingIOError, InterruptedError):
            return None
        except OSError as exc:
            self._drop(f"connection lost ({exc.strerror or exc})")
            return None
        if not data:
            self._drop("the server closed the connection")
            return None
        return data

    def write(self, buf: bytes) -> bool:
        """Send a whole frame, or none of it (False) while an earlier one is still queued."""
        if self._sock is None:
            return False
        try:
            if self._pending:
                self._pending = self._pending[self._sock.send(self._pending):]
                if self._pending:
                    return False
            self._pending = buf[self._sock.send(buf):]
        except (BlockingIOError, InterruptedError):
            return False
        except OSError as exc:
            self._drop(f"connection lost ({exc.strerror or exc})")
            return False
        return True

    def close(self) -> None:
        if self._sock is not None:
            with contextlib.suppress(OSError):
                self._sock.close()
            self._sock = None
        for fd in (self._idle_r, self._idle_w):
            if fd >= 0:
                os.close(fd)
        self._idle_r = self._idle_w = -1


class PtyStream:
    """A pseudo-terminal: the stub on the master side, the slave device for the companion.

    The slave is set raw at once (no echo, no line discipline: the bytes are MAVLink) and
    kept open by the stub, so that the device stays and reads do not fail while no companion
    has it open; what the stub sends meanwhile waits in the terminal's buffer (about 4 KB),
    and beyond that is dropped, frame by frame.
    """

    def __init__(self, link_path: str = "") -> None:
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        os.set_blocking(self._master, False)
        self.device = os.ttyname(self._slave)
        self.link_path = link_path
        self._pending = b""
        if link_path:
            try:
                os.symlink(self.device, link_path)
            except OSError:
                self.close()
                raise

    @property
    def local_address(self) -> None:
        return None

    def fileno(self) -> int:
        return self._master

    def poll(self) -> None:
        """Nothing to do: a pseudo-terminal is always there."""

    def read(self) -> bytes | None:
        try:
            data = os.read(self._master, 4096)
        except (BlockingIOError, InterruptedError):
            return None
        except OSError as exc:
            if exc.errno == errno.EIO:  # no slave open (cannot happen while we hold it)
                return None
            raise
        return data or None

    def write(self, buf: bytes) -> bool:
        try:
            if self._pending:
                self._pending = self._pending[os.write(self._master, self._pending):]
                if self._pending:
                    return False
            self._pending = buf[os.write(self._master, buf):]
        except (BlockingIOError, InterruptedError):
            return False  # the companion does not read: the buffer is full
        return True

    def close(self) -> None:
        for fd in (self._master, self._slave):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._master = self._slave = -1
        if self.link_path:
            with contextlib.suppress(OSError):
                os.unlink(self.link_path)
            self.link_path = ""
