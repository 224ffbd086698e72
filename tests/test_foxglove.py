"""``ezcompanion foxglove``: a WebSocket client (the ``websockets`` package, speaking the
Foxglove protocol) on the bridge during a loopback engagement decodes the map, scene and
plots; the message builders against the law's geometry; bad samples and flags refused.

Real parts: a zenoh router, the service and the loopback vehicle as in
``test_telemetry_service.py`` (multicast off, fresh ports, 127.0.0.1 only), the
foxglove-sdk server, and protobuf decoding from the schemas the server advertises.
"""

from __future__ import annotations

import base64
import contextlib
import io
import json
import math
import socket
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import hypothesis.strategies as st
import numpy as np
import pytest
from foxglove.messages import LocationFix
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from hypothesis import given, settings
from test_service_loopback import CONFIG, fly  # type: ignore[import-not-found]
from test_telemetry import free_endpoint, wait_for  # type: ignore[import-not-found]
from websockets.sync.client import ClientConnection, connect

from ezcompanion.cli import main
from ezcompanion.config import GeoOrigin, load_scenario, scenario_to_dict
from ezcompanion.guidance import evaluate_law
from ezcompanion.service.demo import free_port
from ezcompanion.telemetry import telemetry_settings
from ezcompanion.telemetry.cli import monitor_config, router_config, run_router
from ezcompanion.telemetry.foxglove_bridge import run_bridge
from ezcompanion.telemetry.foxglove_messages import (
    OUTLINE_POINTS,
    Geometry,
    ez_outline_ne_m,
    location_fix,
)
from ezcompanion.telemetry.foxglove_sink import FoxgloveTelemetry, topics
from ezcompanion.wire import geodetic_to_ned

SCENARIO = CONFIG / "paper_scenario1.yaml"
PROTOCOL = "foxglove.sdk.v1"  # the foxglove-sdk server's WebSocket subprotocol


def protobuf_decoder(schema_name: str, descriptor_set: bytes) -> Callable[[bytes], Any]:
    """A parser of ``schema_name`` messages from the FileDescriptorSet Foxglove gives."""
    files = descriptor_pb2.FileDescriptorSet.FromString(descriptor_set)
    pool = descriptor_pool.DescriptorPool()
    pending = list(files.file)
    while pending:  # dependencies first, whatever order the set lists them in
        added = []
        for file in pending:
            try:
                pool.Add(file)
                added.append(file)
            except TypeError:
                continue
        assert added, "unresolvable descriptors"
        pending = [f for f in pending if f not in added]
    message = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema_name))
    return message.FromString  # type: ignore[no-any-return]


def decoder(encoding: str, schema_name: str, schema: bytes) -> Callable[[bytes], Any]:
    """How to read a channel's messages: protobuf from its schema, or JSON."""
    if encoding == "protobuf":
        return protobuf_decoder(schema_name, schema)
    assert encoding == "json"
    return json.loads


class FoxgloveClient:
    """A Foxglove WebSocket client: subscribes to every channel advertised and keeps each
    message decoded, as (log_time_ns, message), by topic.

    foxglove-sdk (0.30.3) queues a channel's advertisement before it adds the channel to
    the client's own map, so a subscription that arrives in between is refused ("Unknown
    channel ID", seen under two CPU burners); the client subscribes again, as a robust
    client must."""

    def __init__(self, port: int) -> None:
        self._stack = contextlib.ExitStack()
        self.ws: ClientConnection = self._stack.enter_context(
            connect(f"ws://127.0.0.1:{port}", subprotocols=[PROTOCOL], open_timeout=10)  # type: ignore[list-item]
        )
        self.server_info: dict[str, Any] = {}
        self.channels: dict[int, dict[str, Any]] = {}  # by channel id
        self.topic_of: dict[int, str] = {}  # by subscription id
        self.decode: dict[int, Callable[[bytes], Any]] = {}
        self.subscription_of: dict[int, int] = {}  # by channel id
        self.messages: dict[str, list[tuple[int, Any]]] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def of(self, topic: str) -> list[tuple[int, Any]]:
        return list(self.messages.get(topic, []))

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                frame = self.ws.recv(timeout=0.2)
            except TimeoutError:
                continue
            except Exception:  # closed
                return
            if isinstance(frame, str):
                self._on_text(json.loads(frame))
            else:
                self._on_binary(frame)

    def _on_text(self, op: dict[str, Any]) -> None:
        if op["op"] == "serverInfo":
            self.server_info = op
        elif op["op"] == "status" and op["message"].startswith("Unknown channel ID: "):
            channel_id = int(op["message"].rsplit(" ", 1)[1])
            sub_id = self.subscription_of[channel_id]
            time.sleep(0.05)  # past the server's window
            self.ws.send(json.dumps({"op": "subscribe",
                                     "subscriptions": [{"id": sub_id, "channelId": channel_id}]}))
        elif op["op"] == "advertise":
            subscriptions = []
            for channel in op["channels"]:
                sub_id = len(self.topic_of) + 1
                self.channels[channel["id"]] = channel
                self.topic_of[sub_id] = channel["topic"]
                self.subscription_of[channel["id"]] = sub_id
                schema = channel["schema"]
                raw = (
                    base64.b64decode(schema)
                    if channel["schemaEncoding"] == "protobuf"
                    else schema.encode()
                )
                self.decode[sub_id] = decoder(channel["encoding"], channel["schemaName"], raw)
                subscriptions.append({"id": sub_id, "channelId": channel["id"]})
            self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subscriptions}))

    def _on_binary(self, frame: bytes) -> None:
        assert frame[0] == 0x01  # message data
        sub_id = int.from_bytes(frame[1:5], "little")
        log_time = int.from_bytes(frame[5:13], "little")
        topic = self.topic_of[sub_id]
        self.messages.setdefault(topic, []).append((log_time, self.decode[sub_id](frame[13:])))

    def close(self) -> None:
        self._stop.set()
        self._stack.close()
        self._thread.join(5.0)


@contextlib.contextmanager
def router(endpoint: str) -> Iterator[None]:
    stop = threading.Event()
    thread = threading.Thread(
        target=run_router, args=(router_config(listen=[endpoint]),), kwargs={"stop": stop}
    )
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join(10.0)


@contextlib.contextmanager
def bridge(endpoint: str, port: int, **options: Any) -> Iterator[list[FoxgloveTelemetry]]:
    stop, started = threading.Event(), threading.Event()
    result: list[FoxgloveTelemetry] = []
    out = io.StringIO()

    def run() -> None:
        conf = monitor_config(connect=[endpoint])
        result.append(run_bridge(conf, port=port, stop=stop, started=started, out=out, **options))

    thread = threading.Thread(target=run)
    thread.start()
    try:
        assert started.wait(20.0), out.getvalue()
        yield result
    finally:
        stop.set()
        thread.join(10.0)


def test_a_foxglove_client_decodes_map_scene_and_plots_of_a_loopback_engagement(
    tmp_path: Path,
) -> None:
    endpoint, port = free_endpoint(), free_port()
    scenario = load_scenario(SCENARIO)
    with router(endpoint), bridge(endpoint, port) as translated:
        client = FoxgloveClient(port)
        try:
            # the service joins the router as a client: the bridge and its client are
            # already watching when the engagement starts
            flight = fly(
                SCENARIO,
                tmp_path,
                telemetry=telemetry_settings({"mode": "client", "connect": [endpoint]}),
                max_time_s=150.0,  # from the companion's start: room for a slow stub
            )
            vehicle = topics("vehicle1")
            assert wait_for(lambda: bool(client.of(vehicle["events"])), 10.0)
            assert wait_for(
                lambda: any(m.message.startswith("ended") for _, m in client.of(vehicle["events"])),
                10.0,
            )
        finally:
            client.close()
    # (whether it intercepted is the loopback tests' business; the events say what happened)
    kinds = [m.message.split(":")[0] for _, m in client.of(vehicle["events"])]
    assert ("intercepted" in kinds) == flight.outcome.intercepted and "ended" in kinds
    # after the end, only the end mode: asked for, the vehicle's reports of it, the answer
    assert set(kinds[kinds.index("ended") + 1:]) <= {"on_exit", "mode", "statustext"}
    assert client.server_info["op"] == "serverInfo"
    advertised = {c["topic"]: c for c in client.channels.values()}
    assert advertised[vehicle["map_vehicle"]]["schemaName"] == "foxglove.LocationFix"
    assert advertised[vehicle["map_target"]]["schemaName"] == "foxglove.LocationFix"
    assert advertised[vehicle["scene"]]["schemaName"] == "foxglove.SceneUpdate"
    assert advertised[vehicle["plots"]]["schemaName"] == "ezcompanion.plots.v1"
    assert advertised[vehicle["plots"]]["schemaEncoding"] == "jsonschema"
    assert advertised[vehicle["events"]]["schemaName"] == "foxglove.Log"

    plots, scenes = client.of(vehicle["plots"]), client.of(vehicle["scene"])
    fixes, targets = client.of(vehicle["map_vehicle"]), client.of(vehicle["map_target"])
    assert len(plots) >= 10 and len(fixes) >= 10
    # one of each per guidance sample, from the first sample both subscriptions saw (the
    # client subscribes to each channel as it is advertised, and the first sample is
    # logged as the channels are made: it beat the plots' subscription once in CI; at 20
    # samples a second, three are 150 ms of a subscription's round trip) ...
    scene_times, plot_times = [t for t, _ in scenes], [t for t, _ in plots]
    both = max(scene_times[0], plot_times[0])
    assert [t for t in scene_times if t >= both] == [t for t in plot_times if t >= both]
    assert sum(t < both for t in scene_times + plot_times) <= 3
    # ... and a target on the map for each from the first sample after the vehicle's status
    # gave the bridge its origin (guidance may arrive before it: no map until then)
    target_times = [t for t, _ in targets]
    assert target_times and target_times == plot_times[plot_times.index(target_times[0]):]
    assert translated[0].refused == 0

    # the map: the target where the scenario puts it, from the scenario's origin
    origin = scenario.origin
    _, target = targets[-1]
    north, east, _ = geodetic_to_ned(
        target.latitude, target.longitude, target.altitude, origin_lat_deg=origin.lat_deg,
        origin_lon_deg=origin.lon_deg, origin_alt_m=origin.alt_m,
    )  # fmt: skip
    np.testing.assert_allclose(
        (north, east), (scenario.target.north_m, scenario.target.east_m), atol=1e-6
    )
    # ... and the vehicle's fix of a tick is as far from the target as that tick's range
    range_at = {t: p["range_to_target_m"] for t, p in plots}
    paired = 0
    for log_time, fix in fixes:
        if log_time in range_at:
            n, e, _ = geodetic_to_ned(
                fix.latitude, fix.longitude, fix.altitude, origin_lat_deg=origin.lat_deg,
                origin_lon_deg=origin.lon_deg, origin_alt_m=origin.alt_m,
            )  # fmt: skip
            distance = math.hypot(n - scenario.target.north_m, e - scenario.target.east_m)
            assert distance == pytest.approx(range_at[log_time], abs=1e-5)
            paired += 1
    assert paired >= 10
    # the plots: h, alpha, the accelerations and their bound, each zone's clearance
    _, last = plots[-1]
    assert last["accel_max_m_s2"] == scenario.guidance.accel_max_m_s2
    assert last["accel_min_m_s2"] == -scenario.guidance.accel_max_m_s2
    assert set(last["clearance_m"]) == {"D1", "D2", "D3"} == set(last["margin_m"])
    for _, p in plots:
        for name, clearance in p["clearance_m"].items():
            assert p["margin_m"][name] == pytest.approx(clearance - scenario.guidance.margin_m)
        assert 0.0 <= p["alpha"] <= 1.0
    # the scene: three zones, the target and the track that grows to the vehicle
    _, scene = scenes[-1]
    ids = {entity.id for entity in scene.entities}
    assert ids == {"zone/D1", "zone/D2", "zone/D3", "target", "track", "vehicle"}
    zone = next(e for e in scene.entities if e.id == "zone/D1")
    reach = scenario.defenders[0].range_m + scenario.defenders[0].capture_radius_m
    assert zone.cylinders[0].size.x == pytest.approx(2.0 * reach)
    assert len(zone.lines) == 2  # the boundary for the current course, and with the margin
    track = next(e for e in scene.entities if e.id == "track").lines[0].points
    assert len(track) >= len(plots)  # every guidance sample the bridge got, from the start
    assert math.hypot(track[-1].y - scenario.target.north_m, track[-1].x - scenario.target.east_m) \
        == pytest.approx(last["range_to_target_m"], abs=1e-9)  # fmt: skip


def test_the_cli_serves_foxglove_and_refuses_bad_flags(capsys: pytest.CaptureFixture[str]) -> None:
    endpoint, port = free_endpoint(), free_port()
    done: list[int] = []
    args = ["foxglove", "--connect", endpoint, "--port", str(port), "--duration", "2"]
    thread = threading.Thread(target=lambda: done.append(main(args)))
    thread.start()
    try:
        assert wait_for(lambda: _accepts(port), 10.0)
        with connect(f"ws://127.0.0.1:{port}", subprotocols=[PROTOCOL]) as ws:  # type: ignore[list-item]
            assert json.loads(ws.recv(timeout=5))["op"] == "serverInfo"
    finally:
        thread.join(15.0)
    assert done == [0]
    out = capsys.readouterr().out
    assert f"foxglove: serving ws://127.0.0.1:{port}" in out
    assert "no --origin" in out
    # a taken port, a bad port or origin: one line, exit 2
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        busy = str(taken.getsockname()[1])
        assert main(["foxglove", "--connect", endpoint, "--port", busy]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("ezcompanion: error: --port:") and "in use" in err[0]
    for bad, field in (
        (["--port", "65536"], "--port"),
        (["--origin", "91,0,0"], "lat_deg"),
        (["--origin", "1,2"], "LAT,LON,ALT"),
        (["--duration", "nan"], "--duration"),
    ):
        assert main(["foxglove", *bad]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and field in err[0], err


def _accepts(port: int) -> bool:
    with socket.socket() as sock:
        return sock.connect_ex(("127.0.0.1", port)) == 0


def test_a_server_beyond_loopback_is_warned_about() -> None:
    from ezcompanion.telemetry.foxglove_bridge import exposure_warning

    assert exposure_warning("127.0.0.1") is None and exposure_warning("localhost") is None
    warning = exposure_warning("0.0.0.0")
    assert warning is not None and "beyond loopback" in warning


# --- the builders ---------------------------------------------------------------------------

GEOMETRY = Geometry.of(load_scenario(SCENARIO))


@settings(max_examples=40, deadline=None)
@given(
    north_m=st.floats(-6.0, 8.0),
    east_m=st.floats(-6.0, 6.0),
    course_rad=st.floats(-math.pi, math.pi),
)
def test_the_drawn_zone_boundary_is_where_the_law_s_clearance_is_zero(
    north_m: float, east_m: float, course_rad: float
) -> None:
    # the outline's point k is where a vehicle on this course, at that bearing from the
    # defender, has clearance 0: a vehicle at bearing k and any distance has clearance
    # distance - rho_k (and the margin's outline is rho_k + margin out)
    scenario = load_scenario(SCENARIO)
    for index, zone in enumerate(GEOMETRY.zones):
        dn, de = north_m - zone.north_m, east_m - zone.east_m
        distance = math.hypot(dn, de)
        k = round(math.atan2(de, dn) / (2 * math.pi) * OUTLINE_POINTS) % OUTLINE_POINTS
        grid = 2 * math.pi * k / OUTLINE_POINTS
        n2, e2 = zone.north_m + distance * math.cos(grid), zone.east_m + distance * math.sin(grid)
        law = evaluate_law(
            scenario.law, scenario.guidance, scenario.zones(),
            target_north_m=scenario.target.north_m, target_east_m=scenario.target.east_m,
            north_m=n2, east_m=e2, course_rad=course_rad, speed_m_s=1.0, accel_m_s2=0.0,
        )  # fmt: skip
        outline = ez_outline_ne_m(zone, course_rad)
        rho = math.hypot(outline[k, 0] - zone.north_m, outline[k, 1] - zone.east_m)
        assert distance - rho == pytest.approx(float(law.clearance_m.reshape(-1)[index]), abs=1e-9)
        with_margin = ez_outline_ne_m(zone, course_rad, GEOMETRY.margin_m)
        pushed = math.hypot(with_margin[k, 0] - zone.north_m, with_margin[k, 1] - zone.east_m)
        assert pushed - rho == pytest.approx(GEOMETRY.margin_m)


READ_FIX = protobuf_decoder("foxglove.LocationFix", LocationFix.get_schema().data)


@settings(max_examples=30, deadline=None)
@given(
    north_m=st.floats(-5e3, 5e3), east_m=st.floats(-5e3, 5e3), down_m=st.floats(-500, 50)
)
def test_a_map_fix_converts_back_to_its_local_position(
    north_m: float, east_m: float, down_m: float
) -> None:
    origin = GeoOrigin(lat_deg=47.3977, lon_deg=8.5456, alt_m=488.0)
    sent = location_fix(
        origin, north_m=north_m, east_m=east_m, down_m=down_m, unix_s=1.7e9, frame_id="v",
        heading_rad=0.5,
    )  # fmt: skip
    fix = READ_FIX(sent.encode())
    back = geodetic_to_ned(
        fix.latitude, fix.longitude, fix.altitude, origin_lat_deg=origin.lat_deg,
        origin_lon_deg=origin.lon_deg, origin_alt_m=origin.alt_m,
    )  # fmt: skip
    np.testing.assert_allclose(back, (north_m, east_m, down_m), atol=1e-6)
    assert fix.heading == 0.5 and fix.frame_id == "v"
    assert fix.timestamp.seconds == 1_700_000_000


SCALAR = st.none() | st.booleans() | st.floats(allow_nan=True) | st.integers() | st.text(max_size=4)
JUNK = (
    SCALAR
    | st.lists(SCALAR, max_size=3)
    | st.dictionaries(st.text(max_size=6), SCALAR, max_size=3)
)
FIELDS = ("north_m", "east_m", "down_m", "course_rad", "time_s", "h_m", "alpha", "zones",
          "wall_time_unix_s", "yaw_rad", "scenario", "kind")  # fmt: skip


@settings(max_examples=80, deadline=None)
@given(
    leaf=st.sampled_from(["guidance", "state", "event", "status"]),
    payload=JUNK | st.dictionaries(st.sampled_from(FIELDS), JUNK),
)
def test_a_malformed_sample_is_refused_whole_never_raised(leaf: str, payload: Any) -> None:
    import foxglove

    telemetry = FoxgloveTelemetry(context=foxglove.Context(), origin=GEOMETRY.origin)
    telemetry.take(f"ezcompanion/v/{leaf}", payload, time.time())
    if not isinstance(payload, dict):
        assert telemetry.refused == 1 and telemetry.logged == 0
    # a sample is either turned into messages or refused before any is logged
    assert telemetry.refused + (telemetry.logged > 0) <= 1
    telemetry.take("not/a/telemetry/key", {}, time.time())
    assert telemetry.refused + (telemetry.logged > 0) <= 2


def test_a_scenario_from_the_status_draws_its_zones_and_a_bad_one_is_refused() -> None:
    import foxglove

    telemetry = FoxgloveTelemetry(context=foxglove.Context())
    good = scenario_to_dict(load_scenario(SCENARIO))
    telemetry.take("ezcompanion/v/status", {"scenario": good}, time.time())
    assert telemetry.vehicles["v"].geometry == GEOMETRY
    assert telemetry.vehicles["v"].map_vehicle is not None  # the origin came with it
    bad = json.loads(json.dumps(good))
    bad["defenders"][0]["speed_ratio"] = 1.5
    telemetry.take("ezcompanion/v/status", {"scenario": bad}, time.time())
    assert telemetry.refused == 1 and telemetry.vehicles["v"].geometry == GEOMETRY


# --- the documented commands -------------------------------------------------------------

ROOT = Path(__file__).resolve().parents[1]


def documented_commands() -> list[list[str]]:
    """The Foxglove and MCAP command lines in docs/telemetry.md's and README.md's shell
    blocks (continuations joined, comments dropped), as argv."""
    import shlex

    commands = []
    for doc in (ROOT / "docs" / "telemetry.md", ROOT / "README.md"):
        blocks = doc.read_text().split("```")[1::2]
        for block in blocks:
            text = block.replace("\\\n", " ")
            for line in text.splitlines():
                argv = shlex.split(line, comments=True)
                if argv[:1] == ["ezcompanion"] and ("foxglove" in argv or "run.mcap" in argv):
                    commands.append(argv[1:])
    return commands


def test_the_documented_foxglove_and_mcap_commands_parse_as_documented(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    # the commands themselves run in the tests above (with test ports) and in test_mcap.py;
    # here: every one shown still parses, with the defaults the docs give
    from ezcompanion.cli import _parser

    commands = documented_commands()
    assert {c[0] for c in commands} == {"foxglove", "monitor", "run"}
    for argv in commands:
        args = _parser().parse_args(argv)
        if args.command == "foxglove":
            assert (args.host, args.port, args.origin) == ("127.0.0.1", 8765, None)
            assert args.connect in (None, ["tcp/127.0.0.1:7447"])
        else:
            assert args.record == Path("run.mcap")
    # run --record refuses, before flying, telemetry it cannot record
    monkeypatch.setenv("EZCOMPANION_JIT", "0")
    for flags, said in (
        (["--no-telemetry"], "--no-telemetry"),
        (["--zenoh-listen", "tls/127.0.0.1:7000"], "needs a tcp/ endpoint"),
    ):
        argv = ["run", "--config", str(SCENARIO), *flags, "--record", "unused.mcap"]
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and said in err[0]
        assert err[0].startswith("ezcompanion: error: --record:")
    assert not Path("unused.mcap").exists()


def test_a_new_session_or_new_zones_clear_the_scene_and_restart_the_track() -> None:
    import foxglove
    from mcap.reader import make_reader

    buffer = io.BytesIO()
    context = foxglove.Context()
    writer = foxglove.open_mcap(buffer, context=context)
    telemetry = FoxgloveTelemetry(context=context)
    scenario = scenario_to_dict(load_scenario(SCENARIO))
    moved = json.loads(json.dumps(scenario))
    moved["defenders"] = moved["defenders"][:2]

    def guidance(k: int) -> dict[str, Any]:
        zones = [{"name": d["name"] or f"D{i + 1}", "clearance_m": 1.0, "margin_m": 0.8}
                 for i, d in enumerate(scenario["defenders"])]  # fmt: skip
        return {"time_s": 0.1 * k, "mode": "intercept", "north_m": 0.1 * k, "east_m": 0.0,
                "course_rad": 0.0, "h_m": 0.5, "alpha": 0.0, "zones": zones,
                "accel_safety_m_s2": 0.0, "accel_intercept_m_s2": 0.1, "accel_desired_m_s2": 0.1,
                "accel_command_m_s2": 0.1, "accel_lat_m_s2": 0.1}  # fmt: skip

    sent = [
        ("alive", True), ("status", {"scenario": scenario}),
        *[("guidance", guidance(k)) for k in range(3)],
        ("alive", False), ("alive", True), *[("guidance", guidance(k)) for k in range(2)],
        ("status", {"scenario": moved}), ("guidance", guidance(5)),
    ]  # fmt: skip
    for leaf, payload in sent:
        telemetry.take(f"ezcompanion/v/{leaf}", payload, time.time())
    writer.close()
    assert telemetry.refused == 0
    buffer.seek(0)
    scenes = [
        protobuf_decoder(schema.name, schema.data)(message.data)
        for schema, channel, message in make_reader(buffer).iter_messages()
        if channel.topic == topics("v")["scene"] and schema is not None
    ]
    assert [len(s.deletions) for s in scenes] == [1, 0, 0, 1, 0, 1]
    tracks = [len(next(e for e in s.entities if e.id == "track").lines[0].points) for s in scenes]
    assert tracks == [1, 2, 3, 1, 2, 3]
    zones = [sorted(e.id for e in s.entities if e.id.startswith("zone/")) for s in scenes]
    assert zones[0] == ["zone/D1", "zone/D2", "zone/D3"] and zones[-1] == ["zone/D1", "zone/D2"]
