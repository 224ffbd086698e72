"""One MAVLink connection: non-blocking receive with the sender's address, a locked peer,
signing, and a tcp: client and a serial port that wait for their peer and come back to it
like MAVProxy (:mod:`ezcompanion.wire.streams`)."""

from __future__ import annotations

import logging
import math
import select
import time
from dataclasses import dataclass
from typing import Any

from ezcompanion.endpoint import is_loopback_host
from ezcompanion.errors import ConfigError, LinkError
from ezcompanion.wire.dialect import Address, Message, mavlink, mavutil
from ezcompanion.wire.signing import check_signature_first, signing_now_10us
from ezcompanion.wire.streams import SerialPort, Stream, TcpClient

URL_SCHEMES = ("udpin", "udpout", "udp", "tcpin", "tcp")
_DEFAULT_BAUD = 57600
# frames taken from one UDP datagram at most; the rest of it is dropped (counted bad). An
# autopilot's datagram holds one message or a few dozen (a serial buffer flushed); a
# stranger's 65 KB datagram of 3,000 heartbeats took 17 ms to parse, and 512 of them
# froze the service for 14 s
DATAGRAM_FRAMES_MAX = 256
# senders of valid frames answered on udpin: before a peer is locked (the vehicle, a
# router, a ground station sharing the port: a handful), the least recently heard given up
UDP_CLIENTS_MAX = 8
# a udpout: link's datagrams from other ports: said on the log at most this often
_FOREIGN_SAY_EVERY_S = 5.0

_log = logging.getLogger(__name__)


def is_serial_device(url: str) -> bool:
    """A serial device path (/dev/..., or COMn on Windows), not a network URL."""
    return url.startswith("/") or url.upper().startswith("COM")


@dataclass(frozen=True)
class LinkStats:
    """Counters of one link's receive side."""

    messages: int
    bad_frames: int  # bad CRC, length, id or signature; a datagram's frames beyond its bound
    rejected_unsigned: int
    bad_signatures: int = 0  # signed, but not with our key, or a replay
    foreign_datagrams: int = 0  # on udpout:, datagrams from any other port than its peer's


@dataclass(frozen=True)
class Frame:
    """One decoded message, the transport address it came from and its type (the
    message's ``get_type()``, read once when the frame was parsed)."""

    message: Message
    source: Address
    kind: str = ""

    def __post_init__(self) -> None:
        if not self.kind:
            object.__setattr__(self, "kind", str(self.message.get_type()))

    @property
    def mavlink1(self) -> bool:
        """The frame was MAVLink 1 (no signature, no extensions)."""
        buf = self.message.get_msgbuf()
        return bool(buf) and buf[0] == mavlink.PROTOCOL_MARKER_V1


class Link:
    """One MAVLink connection (a context manager): non-blocking receive, raw and encoded send.

    Not thread-safe: one thread owns a link. ``mav`` is pymavlink's encoder (its
    ``*_encode`` methods build messages); :meth:`pack` turns a message into bytes with this
    link's sequence number and signature, :meth:`write` sends bytes, :meth:`send` does both.

    A ``tcp:`` client opens even when nothing listens yet: it tries again every second
    (:mod:`ezcompanion.wire.streams`), as it does after its server went away; a serial port
    that goes away is opened again each second from the same path. :attr:`connected` and
    :attr:`down_reason` say where they stand. An endpoint that cannot be opened at all (a
    port taken, a missing serial device) is a :class:`LinkError`.
    """

    def __init__(self, url: str, *, system_id: int, component_id: int) -> None:
        for name, value in (("system_id", system_id), ("component_id", component_id)):
            if not 1 <= value <= 255:
                raise ConfigError(name, value, "must be within [1, 255]")
        self.url = url
        scheme = url.split(":", 1)[0]
        self._only_port: int | None = None  # the one port heard from (udpout:)
        self._foreign = 0  # datagrams from other ports, dropped
        self._foreign_said_s = -math.inf
        self._tcpin = scheme == "tcpin"
        device, baud_rate = "", 0
        if is_serial_device(url):
            # a serial device, as MAVProxy writes it: /dev/ttyACM0,57600 (or COM3,115200)
            device, _, baud = url.partition(",")
            if baud and not (baud.isdigit() and int(baud) > 0):
                raise ConfigError("connect", self.url, "the baud rate after ',' must be a number")
            baud_rate = int(baud) if baud else _DEFAULT_BAUD
        elif scheme not in URL_SCHEMES or url.count(":") != 2:
            raise ConfigError(
                "connect",
                url,
                f"must be SCHEME:HOST:PORT with SCHEME one of {', '.join(URL_SCHEMES)}, "
                "or a serial device such as /dev/ttyACM0,57600",
            )
        # a tcp: client and a serial port own their socket or port (pymavlink's tcp: gives
        # up when nothing listens and takes an idle socket for a closed one; its serial
        # port stays readable for ever once unplugged); pymavlink's plain mavfile holds
        # their parser, encoder and signing
        self._stream: Stream | None = None
        try:
            if scheme == "tcp" or device:
                self._conn: Any = mavutil.mavfile(
                    None, url, source_system=system_id, source_component=component_id
                )
            if device:
                self._stream = SerialPort(device, baud_rate, url=url)
            elif scheme == "tcp":
                host, _, port = url[len("tcp:") :].rpartition(":")
                if not port.isdigit():
                    raise ValueError(f"the port must be a number, not {port!r}")
                self._stream = TcpClient((host, int(port)), url=url)
            else:
                self._conn = mavutil.mavlink_connection(
                    url,
                    source_system=system_id,
                    source_component=component_id,
                    dialect="ardupilotmega",
                    autoreconnect=False,
                )
                if scheme == "udpout" and is_loopback_host(url.split(":")[1]):
                    # pymavlink leaves a udpout: socket unbound, so the kernel binds it to
                    # every interface at its first send: anyone who finds the port could
                    # send to it (a reviewer). To a loopback address, it listens there only.
                    self._conn.port.bind(("127.0.0.1", 0))
                if scheme == "udpout":
                    # it hears only the port it sends to: a UDP server answers from the
                    # port it listens on (from another of its machine's addresses, where
                    # it listens on every interface). A datagram from any other port is
                    # dropped unread and counted (a loopback vehicle of another test, still
                    # sending to a closed socket's port, reached a new link given that port
                    # and was taken for a second autopilot, CI). No authentication: anyone
                    # may send from that port, and only signing tells the vehicle apart.
                    self._only_port = int(self._conn.destination_addr[1])
        except (ValueError, ImportError) as exc:
            raise ConfigError("connect", self.url, f"cannot be opened: {exc}") from exc
        except OSError as exc:  # the port is taken, the device is missing or not ours
            raise LinkError("connect", self.url, f"cannot be opened: {exc}") from exc
        self._conn.mav.robust_parsing = True
        self._udp = isinstance(self._conn, mavutil.mavudp)
        self._connections = self._stream.connections if self._stream is not None else 0
        self._peer: tuple[str, int] | None = None
        self._messages = 0
        self._bad = 0

    # lifecycle
    def close(self) -> None:
        """Close the socket(s) or the device."""
        if self._stream is not None:
            self._stream.close()
        else:
            self._conn.close()

    @property
    def connected(self) -> bool:
        """False while a tcp: client or a serial port waits for its peer; True otherwise."""
        return self._stream is None or self._stream.connected

    @property
    def down_reason(self) -> str | None:
        """Why a tcp: client or a serial port is down (None when up, and for the others)."""
        return self._stream.down_reason if self._stream is not None else None

    def __enter__(self) -> Link:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

    @property
    def mav(self) -> Any:
        """pymavlink's encoder/parser for this link (``link.mav.heartbeat_encode(...)``)."""
        return self._conn.mav

    @property
    def stats(self) -> LinkStats:
        """Receive counters so far."""
        signing = self._conn.mav.signing
        return LinkStats(self._messages, self._bad, int(signing.reject_count),
                         int(signing.badsig_count), self._foreign)  # fmt: skip

    @property
    def local_address(self) -> tuple[str, int] | None:
        """Host and port this link's socket is bound to (useful after ``udpin:HOST:0``)."""
        if isinstance(self._stream, SerialPort):
            return None
        if isinstance(self._stream, TcpClient):
            sock: Any = self._stream.socket
        else:
            sock = getattr(self._conn, "listen", None) or getattr(self._conn, "port", None)
        if sock is None:
            return None
        try:
            host, port = sock.getsockname()[:2]
        except OSError:
            return None
        return str(host), int(port)

    def fileno(self) -> int:
        """The descriptor to wait on (for ``tcpin`` it changes once a client connects; a
        disconnected tcp: client waits on a pipe that never becomes readable)."""
        if self._stream is not None:
            return self._stream.fileno()
        return int(self._conn.fd)

    # signing
    def enable_signing(self, key: bytes, *, link_id: int = 0, allow_unsigned: bool = False) -> None:
        """Sign every outgoing frame with ``key``; refuse unsigned or badly signed input
        unless ``allow_unsigned``."""
        if len(key) != 32:
            raise ConfigError("signing_key", key.hex(), "must be 32 bytes")
        callback = (lambda _mav, _msg_id: True) if allow_unsigned else None
        epoch_10us = signing_now_10us()
        self._conn.setup_signing(
            key,
            sign_outgoing=True,
            allow_unsigned_callback=callback,
            initial_timestamp=epoch_10us,
            link_id=link_id,
        )
        mav = self._conn.mav
        mav.check_signature = lambda buf, system, component: check_signature_first(
            mav, buf, system, component
        )

    def disable_signing(self) -> None:
        """Back to unsigned frames, accepting unsigned input."""
        self._conn.disable_signing()

    @property
    def authenticated(self) -> bool:
        """Every frame taken is signed with the key (signing on, unsigned input refused):
        the sender is known by the key, not by its address."""
        signing = self._conn.mav.signing
        return signing.secret_key is not None and signing.allow_unsigned_callback is None

    # receive
    def wait_readable(self, timeout_s: float, *extra_fds: int) -> list[int]:
        """Wait until this link (or one of ``extra_fds``) is readable; the readable fds. A
        tcp: client or serial port that is down waits no longer than its next attempt."""
        if self._stream is not None:
            timeout_s = min(timeout_s, self._stream.retry_in_s())
        fds = [self.fileno(), *extra_fds]
        readable, _, _ = select.select(fds, [], [], max(timeout_s, 0.0))
        return list(readable)

    def recv_messages(self, max_reads: int = 64) -> list[Message]:
        """Every complete, valid message available now, without blocking (see :meth:`recv`)."""
        return [frame.message for frame in self.recv(max_reads)]

    def recv(
        self, max_reads: int = 64, *, max_frames: int | None = None, budget_s: float | None = None
    ) -> list[Frame]:
        """Every complete, valid message available now with its source, without blocking:
        at most ``max_reads`` reads, and no read begun once ``max_frames`` frames are in
        or ``budget_s`` of wall time has passed (what is left waits in the socket for the
        next call; a flood then delays the vehicle's frames, and the stale budget fails
        closed, rather than freezing the caller).

        Frames with bad CRC, bad length, bad signature or unknown ids are dropped and
        counted; nothing raises for what a peer sends. A UDP datagram is parsed on its own
        (a frame never spans two senders' datagrams), and at most ``DATAGRAM_FRAMES_MAX``
        frames of it are taken.
        """
        out: list[Frame] = []
        deadline = time.monotonic() + budget_s if budget_s is not None else None
        for _ in range(max_reads):
            if (max_frames is not None and len(out) >= max_frames) or (
                deadline is not None and time.monotonic() > deadline
            ):
                break
            chunk = self._read_chunk()
            if chunk is None:
                break
            data, source = chunk
            taken = len(out)
            if data:  # (empty: a datagram from another port, dropped)
                self._parse(data, source, out)
            if source is not None and len(out) > taken:
                self._heard(source)
        return out

    # the peer
    def lock_peer(self, address: Address) -> None:
        """Send only to ``address`` from now on (UDP; pymavlink's ``udpin`` would answer
        every sender it has heard). None unlocks."""
        self._peer = address

    @property
    def peer(self) -> Address:
        """The locked peer, if any."""
        return self._peer

    def _read_stream(self, stream: Stream) -> tuple[bytes, Address] | None:
        data = stream.recv()
        if stream.connections != self._connections:  # connected again: a fresh byte stream
            self._connections = stream.connections
            self._reset_parser(count_partial=False)
        return (data, None) if data else None

    def _read_chunk(self) -> tuple[bytes, Address] | None:
        conn = self._conn
        if self._stream is not None:
            return self._read_stream(self._stream)
        if self._udp:
            try:
                data, source = conn.port.recvfrom(65535)
            except OSError:
                return None
            if not data:
                return None
            address = (str(source[0]), int(source[1]))
            if self._only_port is not None and address[1] != self._only_port:
                self._foreign_datagram(address)
                return b"", address
            # never mix bytes of two datagrams in the parser
            self._reset_parser()
            return bytes(data), address
        try:
            data = conn.recv(4096)
        except OSError:
            return None
        if isinstance(data, bytes) and not data and self._tcpin and conn.port is not None:
            # orderly close by the peer: go back to waiting for a connection
            conn.port.close()
            conn.port = None
            if hasattr(conn, "listen"):
                conn.fd = conn.listen.fileno()
            return None
        if not data:
            return None
        return bytes(data), None

    def _foreign_datagram(self, address: tuple[str, int]) -> None:
        """Counted, and said on the log the first time and then at most every 5 s."""
        self._foreign += 1
        now = time.monotonic()
        if now - self._foreign_said_s >= _FOREIGN_SAY_EVERY_S:
            self._foreign_said_s = now
            _log.warning("%s: datagrams from %s:%d ignored: this link hears port %d only "
                         "(%d so far)", self.url, address[0], address[1], self._only_port,
                         self._foreign)  # fmt: skip

    def _heard(self, address: tuple[str, int]) -> None:
        """pymavlink's own bookkeeping of whom to answer, before a peer is locked: only a
        sender of a valid frame (signed, where signing is on), and on ``udpin:`` at most
        ``UDP_CLIENTS_MAX`` of them, the least recently heard given up. (Every source
        address was kept, before anything of its datagram was read: a reviewer's million
        spoofed one-byte datagrams held a core answering each with a heartbeat a second,
        and 42 MB.)"""
        conn = self._conn
        if self._peer is not None:
            return
        if conn.udp_server:
            alive = conn.clients_last_alive
            if address not in conn.clients and len(conn.clients) >= UDP_CLIENTS_MAX:
                stalest = min(conn.clients, key=lambda known: alive.get(known, 0.0))
                conn.clients.discard(stalest)
                alive.pop(stalest, None)
            conn.clients.add(address)
            alive[address] = time.time()
        elif conn.broadcast:
            conn.last_address = address

    def _parse(self, chunk: bytes, source: Address, out: list[Frame]) -> None:
        mav = self._conn.mav
        # a datagram's frames are bounded (a byte stream's are by the 4 KB read)
        room = DATAGRAM_FRAMES_MAX if self._udp and self._stream is None else -1
        try:
            msg = mav.parse_char(chunk)
            while msg is not None:
                self._keep(msg, source, out)
                room -= 1
                if room == 0:
                    self._reset_parser()  # the rest of the datagram: dropped, counted bad
                    return
                msg = mav.parse_char(b"")
        except Exception:
            self._bad += 1
            self._reset_parser(count_partial=False)

    def _reset_parser(self, *, count_partial: bool = True) -> None:
        mav = self._conn.mav
        if count_partial and len(mav.buf) - mav.buf_index > 0:
            self._bad += 1  # a partial frame left over
        mav.buf = bytearray()
        mav.buf_index = 0
        mav.expected_length = mavlink.HEADER_LEN_V1 + 2

    def _keep(self, msg: Message, source: Address, out: list[Frame]) -> None:
        kind = msg.get_type()
        if kind in ("BAD_DATA", "UNKNOWN") or kind.startswith("UNKNOWN_"):
            self._bad += 1
            return
        self._messages += 1
        out.append(Frame(msg, source, kind))

    # send
    def pack(self, msg: Message) -> bytes:
        """Serialise ``msg`` with this link's next sequence number (and signature)."""
        mav = self._conn.mav
        buf = bytes(msg.pack(mav))
        mav.seq = (mav.seq + 1) % 256
        mav.total_packets_sent += 1
        mav.total_bytes_sent += len(buf)
        return buf

    def write(self, buf: bytes) -> bool:
        """Send already packed bytes (to the locked peer only, once there is one). False
        when they did not leave: the socket refused them, or a tcp: client is down. (Never
        raises: a peer that is not there yet is not an error, but it is not a send.)"""
        try:
            if self._udp and self._peer is not None:
                self._conn.port.sendto(buf, self._peer)
            elif self._stream is not None:
                return self._stream.send(buf)
            elif self._tcpin and self._conn.port is None:
                return False  # no client connected: nothing leaves
            else:
                self._conn.write(buf)
        except OSError:
            return False
        return True

    def send(self, msg: Message) -> bool:
        """Pack and send ``msg`` now; False if it did not leave (see :meth:`write`)."""
        return self.write(self.pack(msg))


def open_link(url: str, *, system_id: int, component_id: int) -> Link:
    """Open a MAVLink connection from a pymavlink URL (``udpout:127.0.0.1:14550`` ...)."""
    return Link(url, system_id=system_id, component_id=component_id)
