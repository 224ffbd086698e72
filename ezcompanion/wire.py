"""The MAVLink wire: the one module of the project that imports pymavlink.

Everything that touches MAVLink bytes goes through here: opening a connection from a
pymavlink URL (``udpout:127.0.0.1:14550``, ``udpin:0.0.0.0:14550``, ``tcpin:...``,
``tcp:...``), MAVLink 2 signing, the wire units (degE7, mm, cm/s, cdeg, ms, us), geodetic
positions to and from local NED (pymap3d) and the encoding of the guidance setpoints a
companion sends. The rest of the project works in SI
units and radians (see :mod:`ezcompanion.frames`) and converts only here.

The dialect is ArduPilot's ``ardupilotmega`` (a superset of ``common``) over MAVLink 2;
importing this module sets ``MAVLINK20=1`` for the process before pymavlink is loaded, as
pymavlink chooses its wire version from that variable.
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

from ezcompanion.errors import ConfigError

os.environ.setdefault("MAVLINK20", "1")
os.environ.setdefault("MAVLINK_DIALECT", "ardupilotmega")

import contextlib

from pymavlink import mavutil

if mavutil.mavlink.WIRE_PROTOCOL_VERSION != "2.0" or mavutil.current_dialect != "ardupilotmega":
    os.environ["MAVLINK20"] = "1"
    mavutil.set_dialect("ardupilotmega")

__all__ = [
    "ATTITUDE_TARGET_IGNORE_ALL_BUT_ROLL",
    "POSITION_TARGET_VELOCITY",
    "POSITION_TARGET_VELOCITY_YAW_RATE",
    "URL_SCHEMES",
    "Address",
    "Frame",
    "Link",
    "LinkStats",
    "Message",
    "cdeg_to_rad",
    "cm_s_to_m_s",
    "course_command",
    "deg_to_e7",
    "e7_to_deg",
    "euler_from_quaternion",
    "geodetic_to_ned",
    "heading_cdeg",
    "heading_deg_0_360",
    "is_finite",
    "is_fixed_wing",
    "is_ground_vehicle",
    "is_serial_device",
    "m_s_to_cm_s",
    "m_to_mm",
    "mavlink",
    "mm_to_m",
    "ms_to_s",
    "ned_to_geodetic",
    "open_link",
    "quaternion_from_euler",
    "roll_setpoint",
    "s_to_ms",
    "s_to_us",
    "signing_key_from_hex",
    "signing_key_from_passphrase",
    "us_to_s",
    "velocity_setpoint",
]

#: The generated dialect module: message classes and every MAVLink enum value as a constant.
mavlink: Any = mavutil.mavlink

#: A decoded MAVLink message (a pymavlink message object; fields are attributes).
Message = Any

#: A transport address: ``(host, port)`` of a UDP peer; None where the link has one peer
#: only (TCP, serial).
Address = tuple[str, int] | None

URL_SCHEMES = ("udpin", "udpout", "udp", "tcpin", "tcp")
_DEFAULT_BAUD = 57600


def is_serial_device(url: str) -> bool:
    """A serial device path (/dev/..., or COMn on Windows), not a network URL."""
    return url.startswith("/") or url.upper().startswith("COM")


# SET_POSITION_TARGET_*: bits set mean "ignore" (POSITION_TARGET_TYPEMASK).
_PT = mavlink
POSITION_TARGET_VELOCITY = (
    _PT.POSITION_TARGET_TYPEMASK_X_IGNORE
    | _PT.POSITION_TARGET_TYPEMASK_Y_IGNORE
    | _PT.POSITION_TARGET_TYPEMASK_Z_IGNORE
    | _PT.POSITION_TARGET_TYPEMASK_AX_IGNORE
    | _PT.POSITION_TARGET_TYPEMASK_AY_IGNORE
    | _PT.POSITION_TARGET_TYPEMASK_AZ_IGNORE
    | _PT.POSITION_TARGET_TYPEMASK_YAW_IGNORE
    | _PT.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
)  # 0x0DC7 = 3527: velocity only
POSITION_TARGET_VELOCITY_YAW_RATE = (
    POSITION_TARGET_VELOCITY & ~_PT.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
)  # 0x05C7 = 1479: velocity and yaw rate
#: SET_ATTITUDE_TARGET type_mask ArduPlane reads as "roll angle from q only" (198).
ATTITUDE_TARGET_IGNORE_ALL_BUT_ROLL = (
    _PT.ATTITUDE_TARGET_TYPEMASK_BODY_PITCH_RATE_IGNORE
    | _PT.ATTITUDE_TARGET_TYPEMASK_BODY_YAW_RATE_IGNORE
    | _PT.ATTITUDE_TARGET_TYPEMASK_THROTTLE_IGNORE
    | _PT.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE
)

_UINT32 = 1 << 32
_SIGNING_EPOCH_S = 1420070400  # 2015-01-01T00:00:00Z, MAVLink 2 signing's time origin
_NEW_STREAM_BEHIND_10US = 60 * 100_000  # a new signed stream may be a minute behind ours
_TCP_KINDS = ("tcpin", "tcp")
_TCP_RECONNECT_S = 1.0  # a tcp: client tries its server again this often (MAVProxy: 1 s)
_TCP_CONNECT_TIMEOUT_S = 0.2


# --- unit conversions (SI <-> wire) -------------------------------------------------------


def deg_to_e7(angle_deg: float) -> int:
    """Degrees to the integer 1e-7 degrees of GLOBAL_POSITION_INT lat/lon."""
    return round(angle_deg * 1e7)


def e7_to_deg(angle_e7: int) -> float:
    """Integer 1e-7 degrees to degrees."""
    return angle_e7 * 1e-7


def m_to_mm(length_m: float) -> int:
    """Metres to integer millimetres (GLOBAL_POSITION_INT alt, relative_alt)."""
    return round(length_m * 1000.0)


def mm_to_m(length_mm: int) -> float:
    """Integer millimetres to metres."""
    return length_mm / 1000.0


def m_s_to_cm_s(speed_m_s: float) -> int:
    """Metres per second to integer centimetres per second (GLOBAL_POSITION_INT vx/vy/vz)."""
    return round(speed_m_s * 100.0)


def cm_s_to_m_s(speed_cm_s: int) -> float:
    """Integer centimetres per second to metres per second."""
    return speed_cm_s / 100.0


def heading_cdeg(heading_rad: float) -> int:
    """A heading (rad, clockwise from north) as GLOBAL_POSITION_INT.hdg: cdeg in [0, 35999]."""
    return round(math.degrees(heading_rad) * 100.0) % 36000


def heading_deg_0_360(heading_rad: float) -> float:
    """A heading (rad) in degrees within [0, 360), as VFR_HUD and GUIDED_CHANGE_HEADING use."""
    deg = math.degrees(heading_rad) % 360.0
    return 0.0 if deg >= 360.0 else deg  # -1e-300 % 360 rounds to 360.0


def cdeg_to_rad(angle_cdeg: int) -> float:
    """Centidegrees to radians."""
    return math.radians(angle_cdeg / 100.0)


def s_to_ms(time_s: float) -> int:
    """Seconds to a uint32 millisecond stamp (``time_boot_ms``), wrapping as the wire does."""
    return int(time_s * 1000.0) % _UINT32


def ms_to_s(time_ms: int) -> float:
    """A millisecond stamp to seconds."""
    return time_ms / 1000.0


def s_to_us(time_s: float) -> int:
    """Seconds to an integer microsecond stamp (``time_usec``, message intervals)."""
    return round(time_s * 1e6)


def us_to_s(time_us: float) -> float:
    """Microseconds to seconds."""
    return time_us / 1e6


def ned_to_geodetic(
    north_m: float,
    east_m: float,
    down_m: float,
    *,
    origin_lat_deg: float,
    origin_lon_deg: float,
    origin_alt_m: float,
) -> tuple[float, float, float]:
    """Local NED of an origin to WGS84 ``(lat_deg, lon_deg, alt_m)`` (pymap3d)."""
    lat, lon, alt = pymap3d.ned2geodetic(
        north_m, east_m, down_m, origin_lat_deg, origin_lon_deg, origin_alt_m
    )
    return float(lat), float(lon), float(alt)


def geodetic_to_ned(
    lat_deg: float,
    lon_deg: float,
    alt_m: float,
    *,
    origin_lat_deg: float,
    origin_lon_deg: float,
    origin_alt_m: float,
) -> tuple[float, float, float]:
    """WGS84 position to ``(north_m, east_m, down_m)`` from an origin (pymap3d)."""
    north, east, down = pymap3d.geodetic2ned(
        lat_deg, lon_deg, alt_m, origin_lat_deg, origin_lon_deg, origin_alt_m
    )
    return float(north), float(east), float(down)


def is_finite(*values: float) -> bool:
    """True when every value is a finite number (wire floats may be NaN or infinite)."""
    return all(math.isfinite(v) for v in values)


def quaternion_from_euler(roll_rad: float, pitch_rad: float, yaw_rad: float) -> list[float]:
    """Body-to-NED attitude quaternion ``[w, x, y, z]`` from ZYX Euler angles."""
    cr, sr = math.cos(roll_rad / 2.0), math.sin(roll_rad / 2.0)
    cp, sp = math.cos(pitch_rad / 2.0), math.sin(pitch_rad / 2.0)
    cy, sy = math.cos(yaw_rad / 2.0), math.sin(yaw_rad / 2.0)
    return [
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    ]


def euler_from_quaternion(q: list[float]) -> tuple[float, float, float]:
    """ZYX Euler angles ``(roll_rad, pitch_rad, yaw_rad)`` of a quaternion ``[w, x, y, z]``."""
    w, x, y, z = q
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return roll, pitch, yaw


# --- signing --------------------------------------------------------------------------------


def signing_key_from_hex(key_hex: str, *, field: str = "signing_key_hex") -> bytes:
    """A 32-byte MAVLink 2 signing key from 64 hex digits; ConfigError names ``field``."""
    try:
        key = bytes.fromhex(key_hex)
    except (TypeError, ValueError):
        raise ConfigError(field, key_hex, "must be 64 hexadecimal digits") from None
    if len(key) != 32:
        raise ConfigError(field, key_hex, "must be 64 hexadecimal digits (32 bytes)")
    return key


def signing_key_from_passphrase(passphrase: str) -> bytes:
    """The key MAVProxy's ``signing setup PASSPHRASE`` derives: SHA-256 of the UTF-8 text."""
    return hashlib.sha256(passphrase.encode("utf-8")).digest()


def _check_signature_first(
    mav: Any, msgbuf: bytearray, src_system: int, src_component: int
) -> bool:
    """MAVLink 2 signature check that verifies before it stores anything.

    pymavlink 2.4.x stores the stream's timestamp before it compares the signature, so one
    frame with a wrong key and timestamp 2^48 makes every later genuine frame of that
    stream "old" for good. Here the signature is checked first; only a genuine frame can
    move a stream's timestamp (or the link's own). The timestamp rules are the spec's: a
    known stream must advance (no replay), a new stream may be at most a minute behind.
    """
    signing = mav.signing
    key = signing.secret_key
    if key is None or len(msgbuf) < 13:
        return False
    digest = hashlib.sha256(bytes(key) + bytes(msgbuf[:-6])).digest()[:6]
    if not hmac.compare_digest(digest, bytes(msgbuf[-6:])):
        return False
    tlow, thigh = mav.mav_sign_unpacker.unpack(msgbuf[-12:-6])
    timestamp = tlow + (thigh << 32)
    stream = (msgbuf[-13], src_system, src_component)
    last = signing.stream_timestamps.get(stream)
    if last is not None and timestamp <= last:
        return False  # a replay, or reordered
    if last is None and timestamp + _NEW_STREAM_BEHIND_10US < signing.timestamp:
        return False  # a new stream more than a minute behind
    signing.stream_timestamps[stream] = timestamp
    signing.timestamp = max(signing.timestamp, timestamp)
    return True


# --- the connection -------------------------------------------------------------------------


@dataclass(frozen=True)
class LinkStats:
    """Counters of one link's receive side."""

    messages: int
    bad_frames: int  # bad CRC, length, id or signature
    rejected_unsigned: int
    bad_signatures: int = 0  # signed, but not with our key, or a replay


@dataclass(frozen=True)
class Frame:
    """One decoded message and the transport address it came from."""

    message: Message
    source: Address

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
    """

    def __init__(self, url: str, *, system_id: int, component_id: int) -> None:
        for name, value in (("system_id", system_id), ("component_id", component_id)):
            if not 1 <= value <= 255:
                raise ConfigError(name, value, "must be within [1, 255]")
        self.url = url
        scheme = url.split(":", 1)[0]
        self._tcp = scheme in _TCP_KINDS
        options: dict[str, Any] = {}
        if is_serial_device(url):
            # a serial device, as MAVProxy writes it: /dev/ttyACM0,57600 (or COM3,115200)
            url, _, baud = url.partition(",")
            if baud and not (baud.isdigit() and int(baud) > 0):
                raise ConfigError("connect", self.url, "the baud rate after ',' must be a number")
            options["baud"] = int(baud) if baud else _DEFAULT_BAUD
        elif scheme not in URL_SCHEMES or url.count(":") != 2:
            raise ConfigError(
                "connect",
                url,
                f"must be SCHEME:HOST:PORT with SCHEME one of {', '.join(URL_SCHEMES)}, "
                "or a serial device such as /dev/ttyACM0,57600",
            )
        try:
            self._conn: Any = mavutil.mavlink_connection(
                url,
                source_system=system_id,
                source_component=component_id,
                dialect="ardupilotmega",
                autoreconnect=False,
                **options,
            )
        except (OSError, ValueError, ImportError) as exc:
            raise ConfigError("connect", self.url, f"cannot be opened: {exc}") from exc
        self._conn.mav.robust_parsing = True
        self._udp = isinstance(self._conn, mavutil.mavudp)
        # a tcp: client reads its socket itself and reconnects like MAVProxy (pymavlink's
        # recv returns b"" both for "nothing yet" and for a closed socket)
        self._tcp_client = isinstance(self._conn, mavutil.mavtcp)
        self._tcp_address: tuple[str, int] | None = (
            getattr(self._conn, "destination_addr", None) if self._tcp_client else None
        )
        self._reconnect_at_s = math.inf
        self._idle_r, self._idle_w = os.pipe() if self._tcp_client else (-1, -1)
        self._peer: tuple[str, int] | None = None
        self._messages = 0
        self._bad = 0

    # lifecycle
    def close(self) -> None:
        """Close the socket(s)."""
        if self._tcp_client and self._conn.port is None:
            self._conn.port = socket.socket()  # pymavlink's close() expects one
        self._conn.close()
        for fd in (self._idle_r, self._idle_w):
            if fd >= 0:
                os.close(fd)
        self._idle_r = self._idle_w = -1

    @property
    def connected(self) -> bool:
        """False while a tcp: client waits to reconnect; True otherwise."""
        return not (self._tcp_client and self._conn.port is None)

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
        return LinkStats(
            self._messages, self._bad, int(signing.reject_count), int(signing.badsig_count)
        )

    @property
    def local_address(self) -> tuple[str, int] | None:
        """Host and port this link's socket is bound to (useful after ``udpin:HOST:0``)."""
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
        if self._tcp_client:
            port = self._conn.port
            return int(port.fileno()) if port is not None else self._idle_r
        return int(self._conn.fd)

    # signing
    def enable_signing(self, key: bytes, *, link_id: int = 0, allow_unsigned: bool = False) -> None:
        """Sign every outgoing frame with ``key``; refuse unsigned or badly signed input
        unless ``allow_unsigned``."""
        if len(key) != 32:
            raise ConfigError("signing_key", key.hex(), "must be 32 bytes")
        callback = (lambda _mav, _msg_id: True) if allow_unsigned else None
        epoch_10us = int(max(time.time() - _SIGNING_EPOCH_S, 0.0) * 1e5)
        self._conn.setup_signing(
            key,
            sign_outgoing=True,
            allow_unsigned_callback=callback,
            initial_timestamp=epoch_10us,
            link_id=link_id,
        )
        mav = self._conn.mav
        mav.check_signature = lambda buf, system, component: _check_signature_first(
            mav, buf, system, component
        )

    def disable_signing(self) -> None:
        """Back to unsigned frames, accepting unsigned input."""
        self._conn.disable_signing()

    # receive
    def wait_readable(self, timeout_s: float, *extra_fds: int) -> list[int]:
        """Wait until this link (or one of ``extra_fds``) is readable; the readable fds."""
        fds = [self.fileno(), *extra_fds]
        readable, _, _ = select.select(fds, [], [], max(timeout_s, 0.0))
        return list(readable)

    def recv_messages(self, max_reads: int = 64) -> list[Message]:
        """Every complete, valid message available now, without blocking (see :meth:`recv`)."""
        return [frame.message for frame in self.recv(max_reads)]

    def recv(self, max_reads: int = 64) -> list[Frame]:
        """Every complete, valid message available now with its source, without blocking.

        Frames with bad CRC, bad length, bad signature or unknown ids are dropped and
        counted; nothing raises for what a peer sends. A UDP datagram is parsed on its own
        (a frame never spans two senders' datagrams).
        """
        out: list[Frame] = []
        for _ in range(max_reads):
            chunk = self._read_chunk()
            if chunk is None:
                break
            data, source = chunk
            out.extend(Frame(msg, source) for msg in self._parse(data))
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

    def _read_tcp_client(self) -> tuple[bytes, Address] | None:
        conn = self._conn
        if conn.port is None:
            if time.monotonic() >= self._reconnect_at_s:
                self._reconnect()
            return None
        try:
            data = conn.port.recv(4096)
        except (BlockingIOError, InterruptedError):
            return None  # nothing waiting: an idle socket is not a closed one
        except OSError:
            data = b""
        if not data:  # closed or reset by the peer: reconnect in a second
            with contextlib.suppress(OSError):
                conn.port.close()
            conn.port = None
            self._reconnect_at_s = time.monotonic() + _TCP_RECONNECT_S
            return None
        return bytes(data), None

    def _reconnect(self) -> None:
        """One short, non-blocking-enough attempt to reach the tcp: server again."""
        assert self._tcp_address is not None
        try:
            sock = socket.create_connection(self._tcp_address, timeout=_TCP_CONNECT_TIMEOUT_S)
        except OSError:
            self._reconnect_at_s = time.monotonic() + _TCP_RECONNECT_S
            return
        sock.setblocking(False)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._conn.port = sock
        self._conn.fd = sock.fileno()
        self._reset_parser(count_partial=False)
        self._reconnect_at_s = math.inf

    def _read_chunk(self) -> tuple[bytes, Address] | None:
        conn = self._conn
        if self._tcp_client:
            return self._read_tcp_client()
        if self._udp:
            try:
                data, source = conn.port.recvfrom(65535)
            except OSError:
                return None
            if not data:
                return None
            address = (str(source[0]), int(source[1]))
            if self._peer is None:  # pymavlink's own bookkeeping of whom to answer
                if conn.udp_server:
                    conn.clients.add(address)
                    conn.clients_last_alive[address] = time.time()
                elif conn.broadcast:
                    conn.last_address = address
            # never mix bytes of two datagrams in the parser
            self._reset_parser()
            return bytes(data), address
        try:
            data = conn.recv(4096)
        except OSError:
            return None
        if isinstance(data, bytes) and not data and self._tcp and conn.port is not None:
            # orderly close by the peer: go back to waiting for a connection
            conn.port.close()
            conn.port = None
            if hasattr(conn, "listen"):
                conn.fd = conn.listen.fileno()
            return None
        if not data:
            return None
        return bytes(data), None

    def _parse(self, chunk: bytes) -> list[Message]:
        out: list[Message] = []
        mav = self._conn.mav
        try:
            msg = mav.parse_char(chunk)
            while msg is not None:
                self._keep(msg, out)
                msg = mav.parse_char(b"")
        except Exception:
            self._bad += 1
            self._reset_parser(count_partial=False)
        return out

    def _reset_parser(self, *, count_partial: bool = True) -> None:
        mav = self._conn.mav
        if count_partial and len(mav.buf) - mav.buf_index > 0:
            self._bad += 1  # a partial frame left over
        mav.buf = bytearray()
        mav.buf_index = 0
        mav.expected_length = mavlink.HEADER_LEN_V1 + 2

    def _keep(self, msg: Message, out: list[Message]) -> None:
        kind = msg.get_type()
        if kind in ("BAD_DATA", "UNKNOWN") or kind.startswith("UNKNOWN_"):
            self._bad += 1
            return
        self._messages += 1
        out.append(msg)

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
            elif self._tcp_client:
                if self._conn.port is None:
                    return False
                self._conn.port.send(buf)
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


# --- setpoints a companion sends --------------------------------------------------------------


def velocity_setpoint(
    link: Link,
    *,
    target_system: int,
    target_component: int,
    time_boot_ms: int,
    north_m_s: float,
    east_m_s: float,
    down_m_s: float = 0.0,
    yaw_rate_rad_s: float | None = None,
    body_frame: bool = False,
    horizontal_only: bool = False,
) -> Message:
    """SET_POSITION_TARGET_LOCAL_NED carrying a velocity (and optionally a yaw rate).

    With ``body_frame`` the first two components are forward and right (MAV_FRAME_BODY_NED).
    ``horizontal_only`` also marks vz as ignored, as ArduRover documents for ground vehicles
    (type_mask 1511 with a yaw rate, instead of 1479).
    """
    mask = POSITION_TARGET_VELOCITY if yaw_rate_rad_s is None else POSITION_TARGET_VELOCITY_YAW_RATE
    if horizontal_only:
        mask |= _PT.POSITION_TARGET_TYPEMASK_VZ_IGNORE
    frame = mavlink.MAV_FRAME_BODY_NED if body_frame else mavlink.MAV_FRAME_LOCAL_NED
    return link.mav.set_position_target_local_ned_encode(
        time_boot_ms,
        target_system,
        target_component,
        frame,
        mask,
        0.0,
        0.0,
        0.0,
        north_m_s,
        east_m_s,
        down_m_s,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0 if yaw_rate_rad_s is None else yaw_rate_rad_s,
    )


def course_command(
    link: Link,
    *,
    target_system: int,
    target_component: int,
    course_rad: float,
    accel_limit_m_s2: float,
    heading: bool = False,
) -> Message:
    """ArduPlane's MAV_CMD_GUIDED_CHANGE_HEADING as COMMAND_INT (course over ground or heading)."""
    kind = mavlink.HEADING_TYPE_HEADING if heading else mavlink.HEADING_TYPE_COURSE_OVER_GROUND
    return link.mav.command_int_encode(
        target_system,
        target_component,
        mavlink.MAV_FRAME_GLOBAL,
        mavlink.MAV_CMD_GUIDED_CHANGE_HEADING,
        0,
        0,
        float(kind),
        heading_deg_0_360(course_rad),
        accel_limit_m_s2,
        0.0,
        0,
        0,
        0.0,
    )


def roll_setpoint(
    link: Link,
    *,
    target_system: int,
    target_component: int,
    time_boot_ms: int,
    roll_rad: float,
) -> Message:
    """SET_ATTITUDE_TARGET with only the roll angle (type_mask 198, as ArduPlane reads it)."""
    return link.mav.set_attitude_target_encode(
        time_boot_ms,
        target_system,
        target_component,
        ATTITUDE_TARGET_IGNORE_ALL_BUT_ROLL,
        quaternion_from_euler(roll_rad, 0.0, 0.0),
        0.0,
        0.0,
        0.0,
        0.0,
    )


# --- flight modes, from pymavlink's own tables -------------------------------------------------


def mode_name(heartbeat: Message) -> str:
    """The flight mode a HEARTBEAT reports, as the autopilot names it ("GUIDED", "OFFBOARD")."""
    return str(mavutil.mode_string_v10(heartbeat))


def guided_mode(heartbeat: Message) -> tuple[str, float, float, float] | None:
    """The mode in which this autopilot follows a companion's setpoints, with the parameters
    of MAV_CMD_DO_SET_MODE that ask for it: ``(name, param1, param2, param3)``.

    ArduPilot: GUIDED, (MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, custom_mode, 0). PX4: OFFBOARD,
    (base mode, main mode, sub mode), as PX4's commander reads the command. None if the
    vehicle type has no such mode.
    """
    if heartbeat.autopilot == mavlink.MAV_AUTOPILOT_PX4:
        base_mode, main_mode, sub_mode = mavutil.px4_map["OFFBOARD"]
        return "OFFBOARD", float(base_mode), float(main_mode), float(sub_mode)
    mapping = mavutil.mode_mapping_byname(heartbeat.type) or {}
    if "GUIDED" not in mapping:
        return None
    return "GUIDED", float(mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED), float(mapping["GUIDED"]), 0.0


def is_ground_vehicle(heartbeat: Message) -> bool:
    """The vehicle drives or sails on a surface (no vertical velocity to command)."""
    return bool(heartbeat.type in (mavlink.MAV_TYPE_GROUND_ROVER, mavlink.MAV_TYPE_SURFACE_BOAT))


def is_fixed_wing(heartbeat: Message) -> bool:
    """The vehicle flies on wings (it cannot stop, and turns by banking)."""
    return bool(heartbeat.type in (mavlink.MAV_TYPE_FIXED_WING, mavlink.MAV_TYPE_FLAPPING_WING))
