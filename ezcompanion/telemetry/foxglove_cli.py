"""The ``foxglove`` subcommand's flags (no foxglove import here: ``ezcompanion run`` builds
the same parser, and should not load the SDK). The bridge is
:mod:`ezcompanion.telemetry.foxglove_bridge`."""

from __future__ import annotations

import argparse

from ezcompanion.config import GeoOrigin
from ezcompanion.errors import ConfigError, shown

__all__ = ["DEFAULT_HOST", "DEFAULT_PORT", "add_foxglove_parser", "origin_flag", "port_flag"]

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765


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
