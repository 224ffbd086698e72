"""The ``monitor``, ``foxglove`` and ``router`` commands: argparse here, typed functions
underneath.

``ezcompanion.cli`` adds them with ``add_telemetry_parsers(subparsers)`` and dispatches with
``run_telemetry_command(args)`` (None when the command is not one of these). ``foxglove``'s
own flags are in :mod:`ezcompanion.telemetry.foxglove_cli`, the bridge in
:mod:`ezcompanion.telemetry.foxglove_bridge` (imported only to run it).
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
from collections.abc import Sequence
from pathlib import Path

import zenoh

from ezcompanion.cli_args import number_within, stop_on_signals, zenoh_endpoint
from ezcompanion.config import load_scenario
from ezcompanion.errors import ConfigError
from ezcompanion.telemetry.monitor import MonitorView, run_monitor
from ezcompanion.telemetry.recording import iter_recording, plot_recording, read_recording
from ezcompanion.telemetry.schema import vehicle_of
from ezcompanion.telemetry.settings import (
    DEFAULT_ENDPOINT,
    open_session,
    session_config,
    telemetry_settings,
)

__all__ = [
    "add_telemetry_parsers",
    "monitor_config",
    "replay",
    "router_config",
    "run_router",
    "run_telemetry_command",
]


def monitor_config(
    *, connect: Sequence[str], mode: str = "peer", config_file: str | None = None,
    multicast_scouting: bool = False,
) -> zenoh.Config:  # fmt: skip
    """A monitor's session: it connects and never listens (the vehicle owns the port)."""
    settings = telemetry_settings(
        {},
        mode=mode,
        listen=(),
        connect=tuple(connect),
        config_file=config_file,
        multicast_scouting=multicast_scouting,
    )
    return session_config(settings)


def router_config(
    *, listen: Sequence[str], connect: Sequence[str] = (), config_file: str | None = None,
    multicast_scouting: bool = False,
) -> zenoh.Config:  # fmt: skip
    """A router's session: listens on ``listen``, joins other routers on ``connect``."""
    settings = telemetry_settings(
        {},
        mode="router",
        listen=tuple(listen),
        connect=tuple(connect),
        config_file=config_file,
        multicast_scouting=multicast_scouting,
    )
    return session_config(settings)


def run_router(
    conf: zenoh.Config, *, stop: threading.Event | None = None, duration_s: float | None = None
) -> int:
    """Route until ``stop`` is set (or SIGINT/SIGTERM, or ``duration_s``); returns 0."""
    stop = stop if stop is not None else threading.Event()
    with open_session(conf, what="router") as session, stop_on_signals(stop):
        listen = conf.get_json("listen/endpoints")
        print(f"zenoh router {session.zid()} listening on {listen}; Ctrl-C to stop", flush=True)
        stop.wait(duration_s)
    return 0


def replay(
    path: Path, *, scenario_yaml: Path | None, plot_png: Path | None, track_csv: Path | None,
    vehicle: str | None, json_lines: bool = False,
) -> int:  # fmt: skip
    """Show the end of a recording (``json_lines``: print its lines, as ``monitor --json``
    does live); with ``plot_png``/``track_csv``, draw or convert it."""
    view = MonitorView()
    seen: set[str] = set()
    for line in iter_recording(path):
        seen.add(vehicle_of(line["key"])[0])
        if vehicle is None or vehicle_of(line["key"])[0] == vehicle:
            if json_lines:
                print(json.dumps(line, separators=(",", ":")))
            else:
                view.update(line["key"], line["payload"])
    if vehicle is not None and vehicle not in seen:  # (a reviewer's had printed "no vehicle
        # yet: waiting ..." from a file, and exit 0)
        raise ConfigError("--vehicle", vehicle, f"not in the recording {str(path)!r}, which "
                          f"holds {', '.join(sorted(seen)) or 'no vehicle'}")
    if not json_lines:
        print(view.render())
    notes = sys.stderr if json_lines else sys.stdout  # JSON lines stay JSON lines
    scenario = load_scenario(scenario_yaml) if scenario_yaml is not None else None
    if track_csv is not None:
        run = read_recording(path, scenario, vehicle=vehicle, track_csv=track_csv)
        print(f"  wrote {track_csv} ({run.t_s.size} rows)", file=notes)
    if plot_png is not None:
        print(f"  wrote {plot_recording(path, plot_png, scenario, vehicle=vehicle)}", file=notes)
    return 0


def _add_watch_flags(parser: argparse.ArgumentParser) -> None:
    """The zenoh flags of a session that watches (``monitor``, ``foxglove``)."""
    parser.add_argument(
        "--connect",
        action="append",
        type=zenoh_endpoint,
        help=f"zenoh endpoint of a vehicle or router (repeatable; default {DEFAULT_ENDPOINT})",
    )
    parser.add_argument("--vehicle", default="*", help="only this vehicle id (default: all)")
    parser.add_argument(
        "--duration",
        type=number_within(0.0, 1e9, unit=" s"),
        metavar="SECONDS",
        help="stop after this many seconds",
    )
    parser.add_argument(
        "--mode",
        choices=["peer", "client"],
        default="peer",
        help="zenoh session mode: peer (default) or client (of a router)",
    )
    parser.add_argument("--zenoh-config", help="a zenoh json5 config file instead of the flags")
    parser.add_argument(
        "--multicast-scouting", action="store_true", help="find peers on the LAN"
    )


def _watch_config(args: argparse.Namespace) -> zenoh.Config:
    return monitor_config(
        connect=args.connect or [DEFAULT_ENDPOINT],
        mode=args.mode,
        config_file=args.zenoh_config,
        multicast_scouting=args.multicast_scouting,
    )


def add_telemetry_parsers(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add ``monitor``, ``foxglove`` and ``router`` to ``ezcompanion``'s subcommands."""
    from ezcompanion.telemetry.foxglove_cli import add_foxglove_parser

    mon = subparsers.add_parser("monitor", help="watch the engagements live over zenoh")
    _add_watch_flags(mon)
    mon.add_argument("--json", action="store_true", help="print raw JSON lines, no table")
    mon.add_argument(
        "--record",
        type=Path,
        help="append every sample to this JSON-lines file; FILE.mcap: write an MCAP "
        "recording of the Foxglove channels instead (a new file)",
    )
    mon.add_argument("--replay", type=Path, help="read this recording instead of listening")
    mon.add_argument("--scenario", type=Path, help="with --replay: the scenario YAML flown")
    mon.add_argument("--plot", type=Path, help="with --replay: write the figure to this PNG")
    mon.add_argument("--track", type=Path, help="with --replay: write the track CSV here")

    _add_watch_flags(add_foxglove_parser(subparsers))

    rtr = subparsers.add_parser("router", help="run a zenoh router for vehicles and monitors")
    rtr.add_argument(
        "--listen",
        action="append",
        type=zenoh_endpoint,
        help=f"endpoint to listen on (repeatable; default {DEFAULT_ENDPOINT}, "
        "e.g. tcp/0.0.0.0:7447 for the network)",
    )
    rtr.add_argument("--connect", action="append", default=[], type=zenoh_endpoint,
                     help="other routers to join")  # fmt: skip
    rtr.add_argument("--zenoh-config", help="a zenoh json5 config file instead of the flags")
    rtr.add_argument("--multicast-scouting", action="store_true", help="find peers on the LAN")
    rtr.add_argument("--duration", type=float, help="stop after this many seconds")


def run_telemetry_command(args: argparse.Namespace) -> int | None:
    """Run ``monitor``, ``foxglove`` or ``router``; None if ``args.command`` is none."""
    if args.command == "router":
        conf = router_config(
            listen=args.listen or [DEFAULT_ENDPOINT],
            connect=args.connect,
            config_file=args.zenoh_config,
            multicast_scouting=args.multicast_scouting,
        )
        return run_router(conf, duration_s=args.duration)
    if args.command == "foxglove":
        from ezcompanion.telemetry.foxglove_bridge import run_bridge

        stop = threading.Event()
        with stop_on_signals(stop):
            run_bridge(
                _watch_config(args),
                host=args.host,
                port=args.port,
                origin=args.origin,
                vehicle=args.vehicle,
                duration_s=args.duration,
                stop=stop,
            )
        return 0
    if args.command != "monitor":
        return None
    vehicle = None if args.vehicle == "*" else args.vehicle
    if args.replay is not None:
        return replay(
            args.replay,
            scenario_yaml=args.scenario,
            plot_png=args.plot,
            track_csv=args.track,
            vehicle=vehicle,
            json_lines=args.json,
        )
    stop = threading.Event()
    with stop_on_signals(stop):
        run_monitor(
            _watch_config(args),
            vehicle=args.vehicle,
            json_lines=args.json,
            record=args.record,
            duration_s=args.duration,
            stop=stop,
        )
    return 0
