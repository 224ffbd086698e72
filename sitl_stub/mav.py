"""The stub's own MAVLink wire: pymavlink's dialect, a link, signing and the wire units.

The stub is the vehicle the companion's tests fly against, so it must not share the
companion's wire code (``ezcompanion.wire``): a wrong unit or a wrong frame there would be
made on both sides and cancel out. Everything MAVLink the stub speaks is written here, on
pymavlink directly: the ``ardupilotmega`` dialect over MAVLink 2 (as ArduPilot and PX4
speak it), a non-blocking link on a pymavlink URL (``udpout:``, ``udpin:``, ``tcpin:``,
``tcp:``, a serial device ``/dev/ttyX,BAUD``, or ``pty``/``pty:PATH``: a pseudo-terminal the
stub serves as its serial port; :mod:`sitl_stub.transport`), MAVLink 2 signing that verifies
before it stores a timestamp, and the conversions from the stub's SI state to wire integers.
"""

from __future__ import annotations

import hashlib
import hmac
import math
import os
import select
import socket
import time
from dataclasses import dataclass
from typing import Any

import pymap3d

from ezcompanion.errors import ConfigError, LinkError
from sitl_stub.transport import PtyStream, TcpClientStream, is_pty_url

os.environ.setdefault("MAVLINK20", "1")
os.environ.setdefault("MAVLINK_DIALECT", "ardupilotmega")

from pymavlink import mavutil

if mavutil.mavlink.WIRE_PROTOCOL_VERSION != "2.0" or mavutil.current_dialect != "ardupilotmega":
    os.environ["MAVLINK20"] = "1"
    mavutil.set_dialect("ardupilotmega")

__all__ = [
    "Message",
    "StubLink",
    "StubLinkStats",
    "cm_s",
    "e7",
    "finite",
    "hdg_cdeg",
    "hdg_deg",
    "key_from_hex",
    "key_from_passphrase",
    "mav",
    "mm",
    "ms",
    "ned_to_lla",
    "roll_of_quaternion",
]

#: The generated dialect: message classes and enum constants.
mav: Any = mavutil.mavlink

#: A decoded pymavlink message.
Message = Any

_SIGNING_EPOCH_S = 1420070400  # 2015-01-01T00:00:00Z
_NEW_STREAM_BEHIND_10US = 60 * 100_000  # a new signed stream may be a minute behind
_DEFAULT_BAUD = 57600


# --- wire units ------------------------------------------------------------------------------


def e7(angle_deg: float) -> int:
    """Degrees as int32 degE7."""
    return round(angle_deg * 10_000_000.0)


def mm(length_m: float) -> int:
    """Metres as integer mm."""
    return round(length_m * 1000.0)


def cm_s(speed_m_s: float) -> int:
    """Metres per second as integer cm/s."""
    return round(speed_m_s * 100.0)


def hdg_cdeg(heading_rad: float) -> int:
    """A heading (rad, clockwise from north) as cdeg in [0, 35999]."""
    return round(heading_rad * 18000.0 / math.pi) % 36000


def hdg_deg(heading_rad: float) -> int:
    """A heading (rad) as integer degrees in [0, 359] (VFR_HUD.heading)."""
    return round(heading_rad * 180.0 / math.pi) % 360


def ms(time_s: float) -> int:
    """Simulated seconds as a wrapping uint32 ``time_boot_ms``."""
    return int(time_s * 1000.0) & 0xFFFFFFFF


def finite(*values: float) -> bool:
    """Every value a finite number."""
    return all(math.isfinite(v) for v in values)


def roll_of_quaternion(q: list[float]) -> float:
    """The ZYX roll angle (rad) of a unit quaternion ``[w, x, y, z]``."""
    w, x, y, z = q
    return math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))


# ArduPilot's flat earth: metres per degree (LATLON_TO_M, libraries/AP_Math/definitions.h)
_ARDUPILOT_M_PER_DEG = 111318.84502145034
_PX4_RADIUS_M = 6371000.0  # CONSTANTS_RADIUS_OF_EARTH (src/lib/geo/geo.h)


def ned_to_lla(north_m: float, east_m: float, down_m: float, origin: tuple[float, float, float],
               autopilot: int | None = None) -> tuple[float, float, float]:
    """Local NED of ``origin = (lat_deg, lon_deg, alt_m)`` to latitude, longitude and
    altitude as ``autopilot`` (a MAV_AUTOPILOT) makes its global position from its local one:
    ArduPilot offsets the origin on a flat earth (``Location::offset_latlng``: north over
    LATLON_TO_M, east also over the cosine of the mean latitude), PX4 reprojects on a sphere
    of 6,371 km (``MapProjection::reproject``, azimuthal equidistant); any other, WGS84
    (pymap3d). Measured on ArduPlane 4.5.1 SITL: its flat earth reproduces its local position
    from its global one to 0.01 m where WGS84 is 0.8 m off at 241 m north."""
    lat0, lon0, alt0 = origin
    if autopilot == mav.MAV_AUTOPILOT_ARDUPILOTMEGA:
        dlat = north_m / _ARDUPILOT_M_PER_DEG
        scale = max(math.cos(math.radians(lat0 + 0.5 * dlat)), 0.01)
        lon = lon0 + east_m / (_ARDUPILOT_M_PER_DEG * scale)
        return lat0 + dlat, (lon + 180.0) % 360.0 - 180.0, alt0 - down_m
    if autopilot == mav.MAV_AUTOPILOT_PX4:
        x, y = north_m / _PX4_RADIUS_M, east_m / _PX4_RADIUS_M
        c = math.hypot(x, y)
        if c == 0.0:
            return lat0, lon0, alt0 - down_m
        ref_lat, ref_lon = math.radians(lat0), math.radians(lon0)
        lat = math.asin(math.cos(c) * math.sin(ref_lat) + x * math.sin(c) * math.cos(ref_lat) / c)
        lon = ref_lon + math.atan2(y * math.sin(c), c * math.cos(ref_lat) * math.cos(c)
                                   - x * math.sin(ref_lat) * math.sin(c))
        return math.degrees(lat), math.degrees(lon), alt0 - down_m
    lat, lon, alt = pymap3d.ned2geodetic(north_m, east_m, down_m, *origin)
    return float(lat), float(lon), float(alt)


def lla_to_ne(lat_deg: float, lon_deg: float, origin: tuple[float, float, float],
              autopilot: int | None = None) -> tuple[float, float]:
    """North and east about ``origin`` of a latitude and longitude, as ``autopilot`` maps
    them: the inverse of :func:`ned_to_lla` (Newton's method on it, from WGS84's answer;
    to a micrometre in a few steps). A vehicle at that latitude and longitude reports this
    local position."""
    n0, e0, _ = pymap3d.geodetic2ned(lat_deg, lon_deg, origin[2], *origin)
    north, east = float(n0), float(e0)
    for _ in range(20):
        lat, lon, _ = ned_to_lla(north, east, 0.0, origin, autopilot)
        d_lat, d_lon = lat_deg - lat, (lon_deg - lon + 180.0) % 360.0 - 180.0
        # metres per degree here, by a step of a metre each way
        lat_n, lon_n, _ = ned_to_lla(north + 1.0, east, 0.0, origin, autopilot)
        lat_e, lon_e, _ = ned_to_lla(north, east + 1.0, 0.0, origin, autopilot)
        a, b, c, d = lat_n - lat, lat_e - lat, lon_n - lon, lon_e - lon
        det = a * d - b * c
        step_n, step_e = (d * d_lat - b * d_lon) / det, (a * d_lon - c * d_lat) / det
        north, east = north + step_n, east + step_e
        if math.hypot(step_n, step_e) < 1e-7:
            break
    return north, east


# --- signing ---------------------------------------------------------------------------------


def key_from_hex(key_hex: str, *, field: str = "signing_key_hex") -> bytes:
    """A 32-byte signing key from 64 hex digits; ConfigError naming ``field`` otherwise."""
    try:
        key = bytes.fromhex(key_hex)
    except (TypeError, ValueError):
        raise ConfigError(field, key_hex, "must be 64 hexadecimal digits") from None
    if len(key) != 32:
        raise ConfigError(field, key_hex, "must be 64 hexadecimal digits (32 bytes)")
    return key


def key_from_passphrase(passphrase: str) -> bytes:
    """MAVProxy's ``signing setup PASSPHRASE`` key: SHA-256 of the UTF-8 text."""
    return hashlib.sha256(passphrase.encode("utf-8")).digest()


def _verify_then_store(parser: Any, buf: bytearray, system: int, component: int) -> bool:
    """Check the signature first; only a genuine frame may advance a stream's timestamp
    (pymavlink stores it before comparing, so one forged frame could lock a stream out)."""
    signing = parser.signing
    if signing.secret_key is None or len(buf) < 13:
        return False
    digest = hashlib.sha256(bytes(signing.secret_key) + bytes(buf[:-6])).digest()[:6]
    if not hmac.compare_digest(digest, bytes(buf[-6:])):
        return False
    low, high = parser.mav_sign_unpacker.unpack(buf[-12:-6])
    stamp = low + (high << 32)
    stream = (buf[-13], system, component)
    last = signing.stream_timestamps.get(stream)
    if last is not None and stamp <= last:
        return False
    if last is None and stamp + _NEW_STREAM_BEHIND_10US < signing.timestamp:
        return False
    signing.stream_timestamps[stream] = stamp
    signing.timestamp = max(signing.timestamp, stamp)
    return True


# --- the link --------------------------------------------------------------------------------


@dataclass(frozen=True)
class StubLinkStats:
    """Receive counters of the stub's link."""

    messages: int
    bad_frames: int  # bad CRC, length, unknown id, partial frames
    rejected_unsigned: int
    bad_signatures: int
    foreign_datagrams: int  # ``udpout:`` hearing only its peer: datagrams from any
    # address or port but its peer's, dropped unread


class StubLink:
    """One MAVLink connection of the stub (one thread owns it); never raises on input.

    A ``tcp:`` client and a pseudo-terminal are the stub's own streams
    (:mod:`sitl_stub.transport`) under pymavlink's plain parser; :attr:`serial_device` is
    the pseudo-terminal's device for the companion to open.
    """

    def __init__(self, url: str, *, system_id: int, component_id: int,
                 hear_only_peer: bool = False) -> None:
        options: dict[str, Any] = {}
        self._stream: TcpClientStream | PtyStream | None = None
        given = url
        if url.startswith("/") or url.upper().startswith("COM"):
            url, _, baud = url.partition(",")
            options["baud"] = int(baud) if baud.isdigit() else _DEFAULT_BAUD
        try:
            if is_pty_url(url) or url.startswith("tcp:"):
                self._conn: Any = mavutil.mavfile(
                    None, url, source_system=system_id, source_component=component_id)
                if url.startswith("tcp:"):
                    host, _, port = url[len("tcp:"):].rpartition(":")
                    self._stream = TcpClientStream((host, int(port)), url=url)
                else:
                    self._stream = PtyStream(url[len("pty:"):])
            else:
                self._conn = mavutil.mavlink_connection(
                    url, source_system=system_id, source_component=component_id,
                    dialect="ardupilotmega", autoreconnect=False, **options)
        except (ValueError, ImportError) as exc:
            raise ConfigError("connect", given, f"cannot be opened: {exc}") from exc
        except OSError as exc:
            raise LinkError("connect", given, f"cannot be opened: {exc}") from exc
        self._conn.mav.robust_parsing = True
        self._udp = isinstance(self._conn, mavutil.mavudp)
        # ``udpout:``: its host resolved now (pymavlink would drop every frame unsent, without
        # a word); with ``hear_only_peer`` (ArduPilot's UDP client, ``ProfileSpec``) the
        # datagrams of any other address or port are dropped unread and counted
        self._peer: tuple[str, int] | None = None
        if self._udp and not (self._conn.udp_server or self._conn.broadcast):
            host, port = self._conn.destination_addr
            try:
                peer = (socket.gethostbyname(host), port)
            except OSError as exc:
                raise LinkError("connect", given, f"cannot be resolved: {exc}") from exc
            self._peer = peer if hear_only_peer else None
        self._foreign = 0
        self._connections = getattr(self._stream, "connections", 0)
        self._messages = 0
        self._bad = 0

    @property
    def mav(self) -> Any:
        """pymavlink's encoder for this link (``*_encode`` methods)."""
        return self._conn.mav

    @property
    def stats(self) -> StubLinkStats:
        signing = self._conn.mav.signing
        return StubLinkStats(self._messages, self._bad, int(signing.reject_count),
                             int(signing.badsig_count), self._foreign)

    @property
    def serial_device(self) -> str | None:
        """The pseudo-terminal's device (``pty`` links), for the companion to open."""
        return self._stream.device if isinstance(self._stream, PtyStream) else None

    @property
    def local_address(self) -> tuple[str, int] | None:
        """Where the socket is bound (after ``udpin:127.0.0.1:0``)."""
        if self._stream is not None:
            return self._stream.local_address
        sock: Any = getattr(self._conn, "listen", None) or getattr(self._conn, "port", None)
        try:
            host, port = sock.getsockname()[:2]
        except (AttributeError, OSError):
            return None
        return str(host), int(port)

    def fileno(self) -> int:
        if self._stream is not None:
            return self._stream.fileno()
        return int(self._conn.fd)

    def close(self) -> None:
        if self._stream is not None:
            self._stream.close()
        else:
            self._conn.close()

    def enable_signing(self, key: bytes, *, timestamp_10us: int | None = None,
                       unsigned_ids: frozenset[int] = frozenset()) -> None:
        """Sign every frame sent (from ``timestamp_10us``, default now); drop unsigned or
        badly signed input but the message ids ``unsigned_ids``."""
        if timestamp_10us is None:
            timestamp_10us = int(max(time.time() - _SIGNING_EPOCH_S, 0.0) * 1e5)
        self._conn.setup_signing(
            key, sign_outgoing=True, initial_timestamp=timestamp_10us,
            allow_unsigned_callback=lambda _parser, msg_id: msg_id in unsigned_ids)
        parser = self._conn.mav
        parser.check_signature = lambda buf, s, c: _verify_then_store(parser, buf, s, c)

    def disable_signing(self) -> None:
        """Send unsigned frames; take unsigned input."""
        self._conn.disable_signing()

    def wait_readable(self, timeout_s: float, *extra_fds: int) -> list[int]:
        if self._stream is not None:
            self._stream.poll()  # a tcp: client that is down tries its server when due
        readable, _, _ = select.select([self.fileno(), *extra_fds], [], [], max(timeout_s, 0.0))
        return list(readable)

    def recv_messages(self, max_reads: int = 64) -> list[Message]:
        """Every valid message available now (bad frames dropped and counted). A datagram
        dropped unread takes one of ``max_reads`` (a flood of them delays the peer's, where
        the kernel's filter would not: harmless for a test vehicle)."""
        out: list[Message] = []
        for _ in range(max_reads):
            data = self._read()
            if data is None:
                break
            if data:  # (b"": a datagram dropped unread, or empty)
                out.extend(self._parse(data))
        return out

    def _read(self) -> bytes | None:
        """Bytes read now: b"" for a datagram dropped unread (another sender's, where only
        the peer is heard) or empty; None where nothing is read (nothing waits, an error,
        a ``tcpin`` peer gone)."""
        conn = self._conn
        if self._stream is not None:
            data = self._stream.read()
            connections = getattr(self._stream, "connections", 0)
            if connections != self._connections:  # a new connection: a fresh stream
                self._connections = connections
                self._drop_partial(count=False)
            return data
        try:
            if self._udp:
                data, source = conn.port.recvfrom(65535)
                if self._peer is not None and tuple(source[:2]) != self._peer:
                    self._foreign += 1
                    return b""
                if conn.udp_server:  # answer whoever talked last, as ArduPilot SITL
                    conn.clients.add(source)
                    conn.clients_last_alive[source] = time.time()
                elif conn.broadcast:
                    conn.last_address = source
                self._drop_partial()  # a frame never spans two datagrams
                return bytes(data)
            data = conn.recv(4096)
        except OSError:
            return None
        if isinstance(data, bytes) and not data and hasattr(conn, "listen") and conn.port:
            conn.port.close()  # a tcpin peer closed: wait for the next one
            conn.port = None
            conn.fd = conn.listen.fileno()
            return None
        return bytes(data) if data else None

    def _parse(self, data: bytes) -> list[Message]:
        out: list[Message] = []
        parser = self._conn.mav
        try:
            msg = parser.parse_char(data)
            while msg is not None:
                kind = msg.get_type()
                if kind in ("BAD_DATA", "UNKNOWN") or kind.startswith("UNKNOWN_"):
                    self._bad += 1
                else:
                    self._messages += 1
                    out.append(msg)
                msg = parser.parse_char(b"")
        except Exception:  # a peer's bytes never raise out of the stub
            self._bad += 1
            self._drop_partial(count=False)
        return out

    def _drop_partial(self, *, count: bool = True) -> None:
        parser = self._conn.mav
        if count and len(parser.buf) - parser.buf_index > 0:
            self._bad += 1
        parser.buf = bytearray()
        parser.buf_index = 0
        parser.expected_length = mav.HEADER_LEN_V1 + 2

    def pack(self, msg: Message) -> bytes:
        """``msg`` as bytes with the next sequence number (and a signature)."""
        parser = self._conn.mav
        buf = bytes(msg.pack(parser))
        parser.seq = (parser.seq + 1) % 256
        return buf

    def write(self, buf: bytes) -> bool:
        if self._stream is not None:
            return self._stream.write(buf)
        try:
            self._conn.write(buf)
        except OSError:
            return False
        return True

    def send(self, msg: Message) -> bool:
        return self.write(self.pack(msg))
