"""A ``tcp:`` client socket that waits for its server and comes back to it, as MAVProxy does.

pymavlink's ``mavtcp`` raises at once (after a few blocking, printed retries) when nothing
listens yet, and its ``recv`` returns b"" both for "nothing waiting" and for a closed socket.
ArduPilot SITL serves TCP 5760 and is often started after the companion, and a SITL restart
closes the socket: so the client here owns its socket, tries once a second until a server
accepts (one short, bounded attempt each time), and says so on the log in one line the first
time and then every few seconds, never with a traceback:

    WARNING ezcompanion.wire.tcp_client: tcp:127.0.0.1:5760: cannot connect (Connection
    refused); trying again every 1 s

Not thread-safe: the :class:`~ezcompanion.wire.link.Link` that owns it owns one thread.
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import socket
import time

__all__ = ["RECONNECT_PERIOD_S", "TcpClient"]

_log = logging.getLogger(__name__)

#: A tcp: client tries its server this often while it is not connected (MAVProxy: 1 s).
RECONNECT_PERIOD_S = 1.0
_CONNECT_TIMEOUT_S = 0.5  # one attempt blocks at most this long (an unreachable host)
_NOTICE_EVERY_S = 5.0  # while waiting, a notice this often after the first


class TcpClient:
    """The socket of one ``tcp:HOST:PORT`` client: connected, or waiting to try again.

    ``url`` names the endpoint in the notices. The first attempt is made here; later ones
    by :meth:`poll` (called by every read) once :attr:`retry_in_s` has run out.
    """

    def __init__(self, address: tuple[str, int], *, url: str) -> None:
        self.address = address
        self.url = url
        self.attempts = 0  # connection attempts so far
        self.connections = 0  # of which succeeded
        self.down_reason: str | None = "not connected yet"  # why it is down (None: up)
        self._sock: socket.socket | None = None
        self._pending = b""  # the rest of a frame the kernel took in part
        self._next_attempt_s = -math.inf
        self._down_since_s = time.monotonic()
        self._next_notice_s = -math.inf
        self._noticed = False
        # a disconnected client waits on a pipe that never becomes readable
        self._idle_r, self._idle_w = os.pipe()
        self.poll()

    # state
    @property
    def connected(self) -> bool:
        """True while a server holds the connection."""
        return self._sock is not None

    @property
    def socket(self) -> socket.socket | None:
        """The connected socket (None while waiting)."""
        return self._sock

    def fileno(self) -> int:
        """The descriptor to wait on: the socket, or (down) one that is never readable."""
        return self._sock.fileno() if self._sock is not None else self._idle_r

    def retry_in_s(self) -> float:
        """Seconds until the next attempt (0: due now; inf: connected)."""
        if self._sock is not None:
            return math.inf
        return max(0.0, self._next_attempt_s - time.monotonic())

    # connecting
    def poll(self) -> bool:
        """Try the server once if an attempt is due; True if this call connected."""
        if self._sock is not None or time.monotonic() < self._next_attempt_s:
            return False
        self.attempts += 1
        try:
            sock = socket.create_connection(self.address, timeout=_CONNECT_TIMEOUT_S)
        except OSError as exc:  # refused, unreachable, timed out, a name that does not resolve
            self._next_attempt_s = time.monotonic() + RECONNECT_PERIOD_S
            self._waiting(exc.strerror or str(exc) or type(exc).__name__)
            return False
        sock.setblocking(False)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._sock = sock
        self.connections += 1
        if self._noticed:
            _log.warning(
                "%s: connected after %d attempts in %.1f s",
                self.url,
                self.attempts,
                time.monotonic() - self._down_since_s,
            )
        self.down_reason = None
        self._noticed = False
        self._next_notice_s = -math.inf
        return True

    def _waiting(self, reason: str) -> None:
        self.down_reason = f"no server accepted a connection ({reason}, {self.attempts} attempts)"
        now = time.monotonic()
        if now < self._next_notice_s:
            return
        self._next_notice_s = now + _NOTICE_EVERY_S
        if not self._noticed:
            _log.warning(
                "%s: cannot connect (%s); trying again every %g s",
                self.url,
                reason,
                RECONNECT_PERIOD_S,
            )
        else:
            _log.warning(
                "%s: still cannot connect after %.0f s (%s, %d attempts)",
                self.url,
                now - self._down_since_s,
                reason,
                self.attempts,
            )
        self._noticed = True

    def _lost(self, reason: str) -> None:
        """The server closed or reset the connection: back to waiting, an attempt in 1 s."""
        assert self._sock is not None
        with contextlib.suppress(OSError):
            self._sock.close()
        self._sock = None
        self._pending = b""
        now = time.monotonic()
        self._down_since_s = now
        self._next_attempt_s = now + RECONNECT_PERIOD_S
        self._next_notice_s = now + _NOTICE_EVERY_S
        self._noticed = True
        self.down_reason = f"the server {reason}"
        _log.warning("%s: the server %s; reconnecting every %g s", self.url, reason,
                     RECONNECT_PERIOD_S)  # fmt: skip

    # data
    def recv(self, size: int = 4096) -> bytes | None:
        """The bytes waiting now (None: nothing, or not connected). An idle socket is not a
        closed one: only an orderly close (b"") or an error takes the connection down."""
        if self._sock is None:
            self.poll()
            return None
        try:
            data = self._sock.recv(size)
        except (BlockingIOError, InterruptedError):
            return None
        except OSError as exc:
            self._lost(f"reset the connection ({exc.strerror or exc})")
            return None
        if not data:
            self._lost("closed the connection")
            return None
        return data

    def send(self, buf: bytes) -> bool:
        """Send ``buf``; False if it will not leave (down, or the kernel's buffer still full
        with an earlier frame: this one is dropped whole, never cut). A frame the kernel
        took in part goes out in full before the next."""
        if self._sock is None:
            return False
        try:
            if self._pending:
                self._pending = self._pending[self._sock.send(self._pending):]
                if self._pending:
                    return False
            sent = self._sock.send(buf)
        except (BlockingIOError, InterruptedError):
            return False  # a peer that does not read
        except OSError as exc:
            self._lost(f"reset the connection ({exc.strerror or exc})")
            return False
        self._pending = buf[sent:]
        return True

    def close(self) -> None:
        """Close the socket and the idle pipe (idempotent)."""
        if self._sock is not None:
            with contextlib.suppress(OSError):
                self._sock.close()
            self._sock = None
        for fd in (self._idle_r, self._idle_w):
            if fd >= 0:
                os.close(fd)
        self._idle_r = self._idle_w = -1
