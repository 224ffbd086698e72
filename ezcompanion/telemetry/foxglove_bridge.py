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

import logging
import sys
import threading
from typing import TextIO

import foxglove
import zenoh

from ezcompanion.config import GeoOrigin
from ezcompanion.errors import ConfigError
from ezcompanion.telemetry.exposure import is_loopback
from ezcompanion.telemetry.foxglove_cli import DEFAULT_HOST, DEFAULT_PORT
from ezcompanion.telemetry.foxglove_sink import FoxgloveTelemetry
from ezcompanion.telemetry.monitor import run_monitor

__all__ = ["exposure_warning", "run_bridge"]

_log = logging.getLogger("ezcompanion.telemetry.foxglove")

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
