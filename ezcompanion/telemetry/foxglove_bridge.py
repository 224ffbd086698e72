"""``ezcompanion foxglove``: the zenoh telemetry live in Foxglove, over its WebSocket server.

The bridge is a monitor (``run_monitor``: it connects, never listens, and queries each
vehicle's status) that draws no table and hands every sample to a
:class:`~ezcompanion.telemetry.foxglove_sink.FoxgloveTelemetry` on the context of a
foxglove-sdk WebSocket server: Foxglove (app or desktop) opens
``ws://127.0.0.1:8765`` and sees the map, scene, plot and event channels of every vehicle.
The server binds loopback unless ``host`` says otherwise (one warning line then: anyone who
reaches the port watches every vehicle; the server takes no input from its clients).
"""

from __future__ import annotations

import argparse
import logging
import sys
import threading
from typing import TextIO

import foxglove
import zenoh

from ezcompanion.config import GeoOrigin
from ezcompanion.errors import ConfigError, shown
from ezcompanion.telemetry.exposure import is_loopback
from ezcompanion.telemetry.foxglove_sink import FoxgloveTelemetry
from ezcompanion.telemetry.monitor import run_monitor

__all__ = [
    "DEFAULT_PORT",
    "add_foxglove_parser",
    "exposure_warning",
    "origin_flag",
    "port_flag",
    "run_bridge",
]

_log = logging.getLogger("ezcompanion.telemetry.foxglove")

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765


def exposure_warning(host: str) -> str | None:
    """The warning for a server bound beyond loopback, or None."""
    if is_loopback(f"tcp/{host}:{DEFAULT_PORT}"):
        return None
    return (
        f"foxglove: serving on {host}, beyond loopback: anyone who reaches the port can "
        "watch every vehicle (the bridge takes no input from its clients)"
    )


def run_bridge(
    conf: zenoh.Config,
    *,
    host: str = DEFAULT_HOST,
    port: int = DEFAULT_PORT,
    origin: GeoOrigin | None = None,
    vehicle: str = "*",
    duration_s: float | None = None,
    stop: threading.Event | None = None,
    out: TextIO | None = None,
    started: threading.Event | None = None,
) -> FoxgloveTelemetry:
    """Serve ``vehicle``'s (``*``: every vehicle's) telemetry to Foxglove clients on
    ``host:port`` (0: any free port) until ``stop`` is set or ``duration_s`` has passed;
    returns the telemetry translator (its counts). ``started`` is set once the server
    listens (``out`` has its address then)."""
    out = out if out is not None else sys.stdout
    warning = exposure_warning(host)
    if warning is not None:
        _log.warning("%s", warning)
    context = foxglove.Context()
    try:
        server = foxglove.start_server(name="ezcompanion", host=host, port=port, context=context)
    except RuntimeError as exc:  # foxglove's FoxgloveError: the port is taken, no such host
        raise ConfigError("--port", f"{host}:{port}", str(exc).split(": ", 1)[-1]) from None
    try:
        telemetry = FoxgloveTelemetry(context=context, origin=origin)
        address = f"ws://{host}:{server.port}"
        print(f"foxglove: serving {address} (in Foxglove: Open connection, Foxglove "
              f"WebSocket, {address}); Ctrl-C to stop", file=out, flush=True)  # fmt: skip
        if origin is None:
            print("foxglove: no --origin: a vehicle is on the map once its status gives "
                  "its scenario's origin", file=out, flush=True)  # fmt: skip
        if started is not None:
            started.set()
        run_monitor(
            conf, vehicle=vehicle, duration_s=duration_s, stop=stop, sink=telemetry, show=False
        )
    finally:
        server.stop()
    return telemetry


def port_flag(text: str) -> int:
    """A flag reader for ``--port``: 0 (any free port) to 65535."""
    try:
        value = int(text)
    except ValueError:
        value = -1
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"must be a port, 0 to 65535 (got {shown(text)})")
    return value


def origin_flag(text: str) -> GeoOrigin:
    """A flag reader for ``--origin LAT,LON,ALT`` (degrees, degrees, metres above MSL)."""
    parts = text.split(",")
    try:
        if len(parts) != 3:
            raise ValueError
        lat, lon, alt = (float(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"must be LAT,LON,ALT: degrees, degrees, metres (got {shown(text)})"
        ) from None
    try:
        return GeoOrigin(lat_deg=lat, lon_deg=lon, alt_m=alt)
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(f"{exc} (in {shown(text)})") from None


def add_foxglove_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:  # type: ignore[type-arg]
    """Add ``foxglove`` to ``ezcompanion``'s subcommands (the zenoh flags as ``monitor``'s)."""
    fox: argparse.ArgumentParser = subparsers.add_parser(
        "foxglove", help="serve the live telemetry to Foxglove (a WebSocket server)"
    )
    fox.add_argument(
        "--host",
        default=DEFAULT_HOST,
        help=f"address the server binds (default {DEFAULT_HOST}; 0.0.0.0 for the network)",
    )
    fox.add_argument(
        "--port",
        type=port_flag,
        default=DEFAULT_PORT,
        help=f"WebSocket port (default {DEFAULT_PORT}; 0: any free port)",
    )
    fox.add_argument(
        "--origin",
        type=origin_flag,
        metavar="LAT,LON,ALT",
        help="geodetic origin of the local NED frame, for vehicles whose status gives none "
        "(their scenario's origin is used when it does)",
    )
    return fox
