"""MAVLink endpoints as users write them, checked, to the connection string pymavlink opens.

Both spellings robotics users already type are accepted: MAVProxy's and pymavlink's
(``udpin:0.0.0.0:14550``) and MAVSDK's URLs (``udpin://0.0.0.0:14550``, ``udp://:14540``):

======================================  ======================================  =================
MAVProxy / pymavlink                    MAVSDK                                  opened as
======================================  ======================================  =================
``udpin:0.0.0.0:14550``, ``udp:...``    ``udpin://0.0.0.0:14550``, ``udp://:``  ``udpin:H:P``
``udpout:127.0.0.1:14550``              ``udpout://127.0.0.1:14550``            ``udpout:H:P``
``tcp:127.0.0.1:5760``                  ``tcp://127.0.0.1:5760``, ``tcpout://`` ``tcp:H:P``
``tcpin:0.0.0.0:5760``                  ``tcpin://0.0.0.0:5760``                ``tcpin:H:P``
``/dev/ttyACM0,57600``, ``COM3,57600``  ``serial:///dev/ttyACM0:57600``         ``DEVICE,BAUD``
======================================  ======================================  =================

``udp`` listens (as in pymavlink, MAVProxy and MAVSDK). A listening endpoint may leave the
host out (``udp://:14540``, ``udpin::14550``): every interface, ``0.0.0.0``. An endpoint
that sends or connects needs a host. Ports are within [1, 65535]; a host is an IPv4 address
or a DNS name (pymavlink's URLs cannot carry IPv6 addresses); a serial port without a baud
rate runs at 57600. A listening endpoint may ask for port 0: any free port, as the tests
do. Errors name the setting and the text as given.
"""

from __future__ import annotations

import ipaddress
import re
from dataclasses import dataclass
from enum import StrEnum
from urllib.parse import urlsplit

from ezcompanion.errors import ConfigError

__all__ = [
    "DEFAULT_BAUD",
    "Endpoint",
    "EndpointKind",
    "is_loopback_host",
    "parse_endpoint",
    "pymavlink_url",
]

DEFAULT_BAUD = 57600
MAX_BAUD = 12_000_000  # above any UART a flight controller has

# (the loopback ones first: one on the network needs a signing key or --allow-unsigned, and a
# reviewer who took the first example was then refused it)
_EXAMPLES = (
    "udpin:127.0.0.1:14550, udpout:127.0.0.1:14550, tcp:127.0.0.1:5760, /dev/ttyACM0,57600, "
    "udp://127.0.0.1:14540, tcp://127.0.0.1:5760, serial:///dev/ttyACM0:57600 or, signed, "
    "udpin:0.0.0.0:14550"
)
_LABEL = re.compile(r"^(?!-)[A-Za-z0-9_-]{1,63}(?<!-)$")
_WINDOWS_PORT = re.compile(r"^COM[0-9]{1,3}$", re.IGNORECASE)


class EndpointKind(StrEnum):
    """The transport, named as pymavlink's URL scheme."""

    UDP_IN = "udpin"  # listen for UDP datagrams, answer the sender
    UDP_OUT = "udpout"  # send UDP datagrams to host:port
    TCP = "tcp"  # connect to a TCP server
    TCP_IN = "tcpin"  # accept one TCP connection
    SERIAL = "serial"  # a serial port

    @property
    def listens(self) -> bool:
        """True for the kinds that bind a local address (the host may be left out)."""
        return self in (EndpointKind.UDP_IN, EndpointKind.TCP_IN)


# every scheme a user may write, to the kind it opens
_PYMAVLINK_SCHEMES = {
    "udpin": EndpointKind.UDP_IN,
    "udp": EndpointKind.UDP_IN,
    "udpout": EndpointKind.UDP_OUT,
    "tcp": EndpointKind.TCP,
    "tcpin": EndpointKind.TCP_IN,
}
_URL_SCHEMES = {**_PYMAVLINK_SCHEMES, "tcpout": EndpointKind.TCP}


@dataclass(frozen=True, kw_only=True)
class Endpoint:
    """A checked MAVLink endpoint: a network ``host``/``port`` or a serial ``device``/``baud``."""

    kind: EndpointKind
    host: str = ""
    port: int = 0
    device: str = ""
    baud: int = 0

    @property
    def on_a_network(self) -> bool:
        """Reachable from other machines: a network endpoint not on the loopback (a serial
        port and 127.0.0.1 are not; a DNS name other than localhost is taken to be)."""
        return self.kind is not EndpointKind.SERIAL and not is_loopback_host(self.host)

    @property
    def pymavlink(self) -> str:
        """The connection string for ``pymavlink.mavutil.mavlink_connection``."""
        if self.kind is EndpointKind.SERIAL:
            return f"{self.device},{self.baud}"
        return f"{self.kind.value}:{self.host}:{self.port}"


def is_loopback_host(host: str) -> bool:
    """``host`` is ``localhost`` or a loopback address (127.0.0.0/8, ::1); any other name
    is taken to reach other machines."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def pymavlink_url(text: object, *, field: str = "connect") -> str:
    """``text`` (either spelling) as the pymavlink connection string; ConfigError if bad."""
    return parse_endpoint(text, field=field).pymavlink


def parse_endpoint(text: object, *, field: str = "connect") -> Endpoint:
    """Read and check one endpoint; errors are ConfigError naming ``field`` and ``text``."""
    if not isinstance(text, str) or not text:
        raise ConfigError(field, text, f"must be a MAVLink endpoint such as {_EXAMPLES}")
    if text != text.strip() or any(c.isspace() or not c.isprintable() for c in text):
        raise ConfigError(field, text, "must not contain spaces or control characters")
    scheme, sep, rest = text.partition("://")
    if sep:
        return _from_url(field, text, scheme.lower())
    if text.startswith("/") or _WINDOWS_PORT.match(text.partition(",")[0]):
        device, comma, baud = text.partition(",")
        return _serial(field, text, device, baud if comma else None)
    scheme, sep, rest = text.partition(":")
    kind = _PYMAVLINK_SCHEMES.get(scheme.lower()) if sep else None
    if kind is None:
        raise ConfigError(field, text, f"must be a MAVLink endpoint such as {_EXAMPLES}")
    host, sep, port = rest.rpartition(":")
    if not sep:
        raise ConfigError(field, text, f"must be {scheme}:HOST:PORT")
    return _network(field, text, kind, host, port)


def _from_url(field: str, text: str, scheme: str) -> Endpoint:
    if scheme == "serial":
        rest = text.partition("://")[2]
        device, colon, baud = rest.rpartition(":")
        if not colon or not baud.isdigit():  # no baud rate given
            device, baud = rest, ""
        return _serial(field, text, device, baud or None)
    kind = _URL_SCHEMES.get(scheme)
    if kind is None:
        raise ConfigError(field, text, f"must be a MAVLink endpoint such as {_EXAMPLES}")
    parts = urlsplit(text)
    if parts.path not in ("", "/") or parts.query or parts.fragment or "@" in parts.netloc:
        raise ConfigError(field, text, f"must be {scheme}://HOST:PORT and nothing more")
    host, sep, port = parts.netloc.rpartition(":")
    if not sep:
        raise ConfigError(field, text, f"must give a port: {scheme}://HOST:PORT")
    return _network(field, text, kind, host, port)


def _network(field: str, text: str, kind: EndpointKind, host: str, port_text: str) -> Endpoint:
    lowest = 0 if kind.listens else 1  # a listener may ask for any free port (0)
    digits = port_text.isascii() and port_text.isdigit()
    if not digits or not lowest <= int(port_text) <= 65535:
        raise ConfigError(field, text, f"the port must be an integer within [{lowest}, 65535]")
    if not host:
        if not kind.listens:
            raise ConfigError(field, text, f"{kind.value} needs a host to send to or connect to")
        host = "0.0.0.0"
    _check_host(field, text, host)
    return Endpoint(kind=kind, host=host, port=int(port_text))


def _check_host(field: str, text: str, host: str) -> None:
    if ":" in host or "[" in host or "]" in host:
        raise ConfigError(field, text, "IPv6 addresses cannot be used: pymavlink's URLs are IPv4")
    if re.fullmatch(r"[0-9.]+", host):
        try:
            ipaddress.IPv4Address(host)
        except ValueError:
            raise ConfigError(field, text, f"{host!r} is not an IPv4 address") from None
        return
    labels = host.rstrip(".").split(".")
    if len(host) > 253 or not all(_LABEL.match(label) for label in labels):
        raise ConfigError(field, text, f"{host!r} is not a host name or an IPv4 address")


def _serial(field: str, text: str, device: str, baud_text: str | None) -> Endpoint:
    if not (device.startswith("/") and len(device) > 1) and not _WINDOWS_PORT.match(device):
        raise ConfigError(field, text, "the serial device must be a path such as /dev/ttyACM0")
    if baud_text is None:
        baud = DEFAULT_BAUD
    elif baud_text.isascii() and baud_text.isdigit() and 1 <= int(baud_text) <= MAX_BAUD:
        baud = int(baud_text)
    else:
        raise ConfigError(field, text, f"the baud rate must be an integer within [1, {MAX_BAUD}]")
    return Endpoint(kind=EndpointKind.SERIAL, device=device, baud=baud)
