"""Byte streams that come back: a ``tcp:`` client and a serial port, reopened like MAVProxy.

pymavlink's ``mavtcp`` raises at once (after a few blocking, printed retries) when nothing
listens yet, and its ``recv`` returns b"" both for "nothing waiting" and for a closed
socket; its ``mavserial`` leaves a port that went away (a USB cable pulled, a pseudo-terminal
whose program ended) readable for ever with nothing to read. ArduPilot SITL serves TCP 5760
and is often started after the companion, and restarts close the socket; a flight
controller on USB vanishes when it reboots. So the streams here own their socket or port:
when it is not there (yet, or any more) they try again once a second (one short, bounded
attempt each time), and say so on the log in one line the first time and then every few
seconds, never with a traceback:

    WARNING ezcompanion.wire.streams: tcp:127.0.0.1:5760: cannot connect (Connection
    refused); trying again every 1 s

A ``tcp:`` client starts waiting when nothing listens; a serial device that cannot be opened
at the start is an error (``open`` raises: a wrong path is likelier than a late device).
Not thread-safe: the :class:`~ezcompanion.wire.link.Link` that owns one owns one thread.
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import socket
import time
from typing import Any

__all__ = ["RECONNECT_PERIOD_S", "SerialPort", "Stream", "TcpClient"]

_log = logging.getLogger(__name__)

#: A stream that is down tries again this often (MAVProxy: 1 s).
RECONNECT_PERIOD_S = 1.0
_CONNECT_TIMEOUT_S = 0.5  # one tcp: attempt blocks at most this long (an unreachable host)
_NOTICE_EVERY_S = 5.0  # while down, a notice this often after the first


def _why(exc: OSError) -> str:
    return str(exc.strerror or exc) or type(exc).__name__


class Stream:
    """A byte stream that is either up or waiting to try again; subclasses open it."""

    _verb = "open"  # "cannot open" / "cannot connect" in the notices

    def __init__(self, *, url: str) -> None:
        self.url = url
        self.attempts = 0  # attempts to open since it was last up
        self.connections = 0  # of which succeeded (a new one: a fresh byte stream)
        self.down_reason: str | None = "not open yet"  # why it is down (None: up)
        self._up = False
        self._pending = b""  # the rest of a frame the kernel took in part
        self._next_attempt_s = -math.inf
        self._down_since_s = time.monotonic()
        self._next_notice_s = -math.inf
        self._noticed = False
        # a stream that is down waits on a pipe that never becomes readable
        self._idle_r, self._idle_w = os.pipe()

    # --- what a subclass provides
    def _open(self) -> None:
        """Open the socket or port (OSError if it cannot be)."""
        raise NotImplementedError

    def _close(self) -> None:
        raise NotImplementedError

    def _fd(self) -> int:
        raise NotImplementedError

    def _read(self) -> bytes | None:
        """The bytes waiting (None: none); ConnectionError(how) when the peer went away."""
        raise NotImplementedError

    # --- state
    @property
    def connected(self) -> bool:
        """True while the socket or port is up."""
        return self._up

    def fileno(self) -> int:
        """The descriptor to wait on: the stream's, or (down) one that is never readable."""
        return self._fd() if self._up else self._idle_r

    def retry_in_s(self) -> float:
        """Seconds until the next attempt (0: due now; inf: up)."""
        if self._up:
            return math.inf
        return max(0.0, self._next_attempt_s - time.monotonic())

    # --- opening
    def poll(self) -> bool:
        """Try once if down and an attempt is due; True if this call opened it."""
        if self._up or time.monotonic() < self._next_attempt_s:
            return False
        self.attempts += 1
        try:
            self._open()
        except (OSError, ValueError) as exc:  # refused, unreachable, no such device (yet)
            self._next_attempt_s = time.monotonic() + RECONNECT_PERIOD_S
            self._waiting(_why(exc) if isinstance(exc, OSError) else str(exc))
            return False
        self._up = True
        self._pending = b""
        self.connections += 1
        if self._noticed:
            _log.warning(
                "%s: %s after %d attempt%s in %.1f s",
                self.url,
                "connected" if self._verb == "connect" else "open again",
                self.attempts,
                "" if self.attempts == 1 else "s",
                time.monotonic() - self._down_since_s,
            )
        self.down_reason = None
        self._noticed = False
        self._next_notice_s = -math.inf
        return True

    def _waiting(self, reason: str) -> None:
        tries = f"{self.attempts} attempt{'' if self.attempts == 1 else 's'}"
        self.down_reason = f"{self._failed} ({reason}, {tries})"
        now = time.monotonic()
        if now < self._next_notice_s:
            return
        self._next_notice_s = now + _NOTICE_EVERY_S
        if not self._noticed:
            _log.warning(
                "%s: cannot %s (%s); trying again every %g s",
                self.url,
                self._verb,
                reason,
                RECONNECT_PERIOD_S,
            )
        else:
            _log.warning(
                "%s: still cannot %s after %.0f s (%s, %d attempts)",
                self.url,
                self._verb,
                now - self._down_since_s,
                reason,
                self.attempts,
            )
        self._noticed = True

    @property
    def _failed(self) -> str:
        return "could not be opened"

    def _lost(self, reason: str) -> None:
        """The peer or device went away: back to waiting, the next attempt in a second."""
        with contextlib.suppress(OSError):
            self._close()
        self._up = False
        self._pending = b""
        self.attempts = 0
        now = time.monotonic()
        self._down_since_s = now
        self._next_attempt_s = now + RECONNECT_PERIOD_S
        self._next_notice_s = now + _NOTICE_EVERY_S
        self._noticed = True
        self.down_reason = reason
        _log.warning("%s: %s; trying again every %g s", self.url, reason, RECONNECT_PERIOD_S)

    # --- data
    def recv(self) -> bytes | None:
        """The bytes waiting now (None: nothing, or down; a due attempt is made then)."""
        if not self._up:
            self.poll()
            return None
        try:
            return self._read()
        except ConnectionError as gone:  # raised by _read with how it went (one line)
            self._lost(str(gone))
            return None

    def send(self, buf: bytes) -> bool:
        """Send ``buf``; False if it will not leave (down, or the kernel's buffer still full
        with an earlier frame: this one is dropped whole, never cut). A frame the kernel
        took in part goes out in full before the next."""
        if not self._up:
            return False
        fd = self._fd()
        try:
            if self._pending:
                self._pending = self._pending[os.write(fd, self._pending) :]
                if self._pending:
                    return False
            self._pending = buf[os.write(fd, buf) :]
        except (BlockingIOError, InterruptedError):
            return False  # a peer that does not read
        except OSError as exc:
            self._lost(f"the peer went away ({_why(exc)})")
            return False
        return True

    def close(self) -> None:
        """Close the stream and the idle pipe (idempotent)."""
        if self._up:
            with contextlib.suppress(OSError):
                self._close()
            self._up = False
        for fd in (self._idle_r, self._idle_w):
            if fd >= 0:
                os.close(fd)
        self._idle_r = self._idle_w = -1


class TcpClient(Stream):
    """A ``tcp:HOST:PORT`` client; the first attempt is made here (nothing listening is no
    error: it waits), the next ones by :meth:`poll` (every read) each second."""

    _verb = "connect"

    def __init__(self, address: tuple[str, int], *, url: str) -> None:
        super().__init__(url=url)
        self.address = address
        self.socket: socket.socket | None = None
        self.poll()

    @property
    def _failed(self) -> str:
        return "no server accepted a connection"

    def _open(self) -> None:
        sock = socket.create_connection(self.address, timeout=_CONNECT_TIMEOUT_S)
        sock.setblocking(False)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.socket = sock

    def _close(self) -> None:
        if self.socket is not None:
            sock, self.socket = self.socket, None
            sock.close()

    def _fd(self) -> int:
        assert self.socket is not None
        return self.socket.fileno()

    def _read(self) -> bytes | None:
        assert self.socket is not None
        try:
            data = self.socket.recv(4096)
        except (BlockingIOError, InterruptedError):
            return None  # an idle socket is not a closed one
        except OSError as exc:
            raise ConnectionError(f"the server reset the connection ({_why(exc)})") from None
        if not data:
            raise ConnectionError("the server closed the connection")
        return data


class SerialPort(Stream):
    """A serial device (pyserial, raw, non-blocking): opened here, or OSError; when it goes
    away (unplugged, its program ended), opened again from the same path each second.

    Bytes the kernel kept from before an open are dropped: they are not this session's.
    """

    def __init__(self, device: str, baud: int, *, url: str) -> None:
        super().__init__(url=url)
        self.device = device
        self.baud = baud
        self.port: Any = None
        self.attempts = 1
        try:
            self._open()  # OSError (pyserial's SerialException) if it is not there
        except BaseException:
            self.close()
            raise
        self._up = True
        self.connections = 1
        self.down_reason = None

    def _open(self) -> None:
        import serial  # type: ignore[import-untyped]  # pyserial (serial links only)

        port = serial.Serial(
            self.device, self.baud, timeout=0, dsrdtr=False, rtscts=False, xonxoff=False
        )
        port.reset_input_buffer()
        self.port = port

    def _close(self) -> None:
        if self.port is not None:
            port, self.port = self.port, None
            port.close()

    def _fd(self) -> int:
        assert self.port is not None
        return int(self.port.fileno())

    def _read(self) -> bytes | None:
        assert self.port is not None
        try:
            data = self.port.read(4096)
        except OSError as exc:  # pyserial's SerialException: readable, yet nothing to read
            raise ConnectionError(f"the device went away ({exc})") from None
        return bytes(data) if data else None
