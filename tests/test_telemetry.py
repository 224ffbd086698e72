"""Zenoh telemetry over real sessions on loopback (a fresh port each, no multicast scouting).

The engagements are driven by the guidance loop itself on synthetic vehicle states: each
tick's ``TickCommand`` is published and the test compares what a subscriber receives with
the command's own numbers.
"""

from __future__ import annotations

import atexit
import copy
import json
import math
import os
import socket
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import yaml
import zenoh

from ezcompanion.config import Scenario, load_scenario, scenario_from_dict, scenario_update
from ezcompanion.errors import ConfigError
from ezcompanion.service.demo import free_port
from ezcompanion.service.events import Event, EventKind
from ezcompanion.service.inbox import ScenarioInbox
from ezcompanion.service.loop import GuidanceLoop, TickCommand
from ezcompanion.service.state import VehicleState
from ezcompanion.telemetry import (
    SCHEMAS,
    TelemetryPublisher,
    TelemetrySettings,
    key,
    session_config,
    telemetry_settings,
)
from ezcompanion.telemetry.schema import decode
from ezcompanion.telemetry.settings import release

CONFIG = Path(__file__).resolve().parents[1] / "config" / "paper_scenario1.yaml"
SCENARIO_RAW: dict[str, Any] = yaml.safe_load(CONFIG.read_text())
NAMES = ("D1", "D2", "D3")


# --- helpers ------------------------------------------------------------------------------


def free_endpoint() -> str:
    return f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"


def peer(connect: str) -> zenoh.Config:
    """A subscriber's session: connects to ``connect``, never listens, no multicast."""
    return session_config(TelemetrySettings(listen=(), connect=(connect,)))


def wait_for(condition: Callable[[], bool], timeout_s: float = 30.0) -> bool:
    """Until ``condition()`` holds (True) or ``timeout_s`` of wall time have passed (False):
    it returns as soon as it holds, so the default is generous for a loaded machine."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.005)
    return True


def engagement(ticks: int, scenario_raw: dict[str, Any] | None = None) -> Iterator[TickCommand]:
    """The loop's commands along a straight flight from the scenario's start (50 Hz)."""
    scenario = scenario_from_dict(scenario_raw or SCENARIO_RAW)
    loop = GuidanceLoop(scenario, loop_rate_hz=50.0, stale_after_s=0.25)
    vn, ve = math.cos(scenario.start.course_rad), math.sin(scenario.start.course_rad)
    for k in range(ticks):
        t = 1.0 + 0.02 * k
        state = VehicleState(
            north_m=scenario.start.north_m + vn * 0.02 * k,
            east_m=scenario.start.east_m + ve * 0.02 * k,
            down_m=-20.0,
            velocity_north_m_s=vn,
            velocity_east_m_s=ve,
            yaw_rad=0.3,
            position_time_s=t - 0.005,
            attitude_time_s=t - 0.01,
            position_source="local",
        )
        command = loop.tick(state, t)
        assert isinstance(command, TickCommand)
        yield command


class Collector:
    """A subscriber callback that keeps (key, encoding, payload) of every sample."""

    def __init__(self, sleep_s: float = 0.0) -> None:
        self.samples: list[tuple[str, str, dict[str, Any]]] = []
        self.sleep_s = sleep_s

    def __call__(self, sample: zenoh.Sample) -> None:
        self.samples.append(
            (
                str(sample.key_expr),
                str(sample.encoding),
                decode(sample.payload.to_bytes(), str(sample.encoding)),
            )
        )
        if self.sleep_s:
            time.sleep(self.sleep_s)  # a deliberately slow subscriber

    def of(self, leaf: str) -> list[dict[str, Any]]:
        return [p for k, _, p in self.samples if k.endswith("/" + leaf)]


@pytest.fixture
def endpoint() -> str:
    return free_endpoint()


def patient_config(settings: dict[str, Any]) -> str:
    """A zenoh configuration file (the ``config_file`` users give) for ``settings``' mode and
    endpoints, in which a put waits up to 0.2 s for room in the transmit queue before it
    drops (zenoh's default: 1 ms, two batches a priority). For the tests that check every
    tick arrives: on a machine loaded by other processes zenoh's transmit thread can be off
    the CPU for longer than 1 ms, and a paced tick is then dropped by design."""
    conf = {
        "mode": settings.get("mode", "peer"),
        "listen": {"endpoints": list(settings.get("listen", ()))},
        "connect": {"endpoints": list(settings.get("connect", ()))},
        "scouting": {"multicast": {"enabled": False}},
        "transport": {"link": {"tx": {"queue": {"congestion_control": {
            "drop": {"wait_before_drop": 200_000}}}}}},  # microseconds
    }
    handle, path = tempfile.mkstemp(prefix="ezcompanion-zenoh-", suffix=".json5")
    with os.fdopen(handle, "w") as out:
        json.dump(conf, out)
    atexit.register(os.remove, path)
    return path


def publisher(
    endpoint: str,
    *,
    vehicle_id: str = "vehicle1",
    status: Callable[[], dict[str, Any]] | None = None,
    on_scenario: Callable[[dict[str, Any]], str | None] | None = None,
    patient: bool = False,
    **settings: Any,
) -> TelemetryPublisher:
    """A publisher on ``endpoint`` (listening, unless ``connect`` is given); ``patient``:
    zenoh waits for room rather than drop (:func:`patient_config`)."""
    if "connect" not in settings:
        settings["listen"] = (endpoint,)
    if patient:
        settings["config_file"] = patient_config(settings)
        for name in ("mode", "listen", "connect"):
            settings.pop(name, None)
    return TelemetryPublisher(
        telemetry_settings({"vehicle_id": vehicle_id}, **settings),
        status=status or (lambda: {"phase": "guiding"}),
        on_scenario=on_scenario or (lambda data: None),
        zone_names=NAMES,
    )


# --- settings -----------------------------------------------------------------------------


def test_settings_default_to_a_loopback_peer_without_multicast() -> None:
    s = telemetry_settings({})
    assert (s.mode, s.listen, s.connect, s.multicast_scouting) == (
        "peer",
        ("tcp/127.0.0.1:7447",),
        (),
        False,
    )
    conf = session_config(s)
    assert json.loads(conf.get_json("scouting/multicast/enabled")) is False
    assert json.loads(conf.get_json("listen/endpoints")) == ["tcp/127.0.0.1:7447"]
    # shared memory off (its watchdog woke a thread every 50 ms once a peer connected)
    assert json.loads(conf.get_json("transport/shared_memory/enabled")) is False
    # an endpoint not up yet tried again within 0.5 s (zenoh's 1 to 4 s: a monitor started
    # before its vehicle missed the engagement's start, docs/telemetry.md)
    retry = json.loads(conf.get_json("connect/retry"))
    assert (retry["period_init_ms"], retry["period_max_ms"]) == (250, 500)
    client = telemetry_settings({"mode": "client", "connect": "tcp/10.0.0.2:7447"})
    assert client.listen == () and client.connect == ("tcp/10.0.0.2:7447",)


@pytest.mark.parametrize(
    ("raw", "field"),
    [
        ({"mode": "server"}, "telemetry.mode"),
        ({"listen": ["127.0.0.1:7447"]}, "telemetry.listen"),
        ({"mode": "client", "connect": ["tcp/h:1"], "listen": ["tcp/h:2"]}, "telemetry.listen"),
        ({"mode": "client"}, "telemetry.connect"),
        ({"vehicle_id": "a/b"}, "telemetry.vehicle_id"),
        ({"vehicle_id": "*"}, "telemetry.vehicle_id"),
        ({"config_file": "/nonexistent.json5"}, "telemetry.config_file"),
        ({"enabled": "yes"}, "telemetry.enabled"),
        ({"listn": []}, "telemetry.listn"),
    ],
)
def test_bad_settings_name_the_key(raw: dict[str, Any], field: str) -> None:
    with pytest.raises(ConfigError) as info:
        telemetry_settings(raw)
    assert info.value.field == field


def test_a_port_in_use_is_a_clear_error(endpoint: str) -> None:
    with publisher(endpoint), pytest.raises(ConfigError, match="cannot open a zenoh") as info:
        publisher(endpoint)
    # one line that says what to do, without the Rust sources zenoh names ("... at
    # /root/.cargo/.../tcp.rs:61.", a reviewer's)
    message = str(info.value)
    assert "Address already in use" in message and ".rs:" not in message and "\n" not in message
    assert "--zenoh-listen" in message and "--no-telemetry" in message


# --- samples ------------------------------------------------------------------------------


def test_a_subscriber_sees_every_tick_as_the_loop_computed_it(endpoint: str) -> None:
    commands = list(engagement(60))
    got = Collector()
    # at 1000 Hz a tick handed over when the last went out a millisecond ago leaves at once
    with (
        publisher(endpoint, publish_rate_hz=1000.0, patient=True) as pub,
        zenoh.open(peer(endpoint)) as session,
    ):
        sub = session.declare_subscriber(key("*", "*"), got)
        assert wait_for(lambda: pub.has_subscribers("guidance") and pub.has_subscribers("state"))
        for sent, command in enumerate(commands, start=1):
            pub.publish_tick(command)  # at the loop's pace: each tick out before the next
            assert wait_for(lambda sent=sent: pub.samples_published == 2 * sent)  # type: ignore[misc]
        assert wait_for(lambda: len(got.samples) == 2 * len(commands))
        release(sub)
    assert pub.ticks_skipped == 0
    encodings = {k.rsplit("/", 1)[1]: e for k, e, _ in got.samples}
    assert encodings == {
        "state": "application/msgpack;ezcompanion.state.v1",
        "guidance": "application/msgpack;ezcompanion.guidance.v1",
    }
    states, guidance = got.of("state"), got.of("guidance")
    assert [g["seq"] for g in guidance] == [s["seq"] for s in states]
    assert [g["seq"] for g in guidance] == sorted({g["seq"] for g in guidance})  # in order
    for command, state, g in zip(commands, states, guidance, strict=True):
        law = command.step.law
        assert state["vehicle_id"] == g["vehicle_id"] == "vehicle1"
        assert state["north_m"] == command.state.north_m
        assert state["position_age_s"] == pytest.approx(0.005)
        assert state["course_rad"] == command.course_rad
        assert g["time_s"] == command.time_s
        assert g["h_m"] == float(law.h_m)
        assert g["alpha"] == float(law.alpha)
        assert g["accel_safety_m_s2"] == float(law.accel_safety_m_s2)
        assert g["accel_intercept_m_s2"] == float(law.accel_intercept_m_s2)
        assert g["accel_desired_m_s2"] == float(law.accel_desired_m_s2)
        assert g["accel_command_m_s2"] == float(law.accel_command_m_s2)
        assert g["accel_lat_m_s2"] == float(command.step.accel_lat_m_s2)
        assert g["accel_lat_cmd_m_s2"] == command.accel_lat_m_s2
        assert g["range_to_target_m"] == float(law.range_to_target_m)
        assert g["bearing_to_target_rad"] == float(law.bearing_to_target_rad)
        assert g["reference_saturated"] == bool(law.reference_saturated)
        assert [z["name"] for z in g["zones"]] == list(NAMES)
        assert [z["margin_m"] for z in g["zones"]] == law.margin_m.tolist()
        # b_i = clearance - eps: the margin is the clearance less the scenario's epsilon
        for zone in g["zones"]:
            assert zone["clearance_m"] - zone["margin_m"] == pytest.approx(0.2)
        assert sum(z["softmin_weight"] for z in g["zones"]) == pytest.approx(1.0)
    assert {g["mode"] for g in guidance} <= {"intercept", "blend", "safety", "captured"}


def test_each_sample_is_sent_only_while_someone_subscribes_to_it(endpoint: str) -> None:
    """A leaf's sample is built and put only while zenoh says someone subscribes to it:
    followed through a subscriber to the guidance that comes, a second one to the state,
    and both going, a tick sent each time, and the samples put counted."""
    commands = engagement(4)
    got = Collector()

    def sent(ticks: int) -> bool:
        return pub.ticks_published == ticks

    with (
        publisher(endpoint, publish_rate_hz=1000.0, patient=True) as pub,
        zenoh.open(peer(endpoint)) as s,
    ):
        pub.publish_tick(next(commands))
        assert wait_for(lambda: sent(1))
        assert pub.samples_published == 0  # no one asked: nothing built, nothing put
        guidance = s.declare_subscriber(key("vehicle1", "guidance"), got)
        assert wait_for(lambda: pub.has_subscribers("guidance"))
        assert not pub.has_subscribers("state") and not pub.has_subscribers("event")
        pub.publish_tick(next(commands))
        assert wait_for(lambda: sent(2)) and pub.samples_published == 1
        state = s.declare_subscriber(key("vehicle1", "state"), got)
        assert wait_for(lambda: pub.has_subscribers("state"))
        pub.publish_tick(next(commands))
        assert wait_for(lambda: sent(3)) and pub.samples_published == 3
        assert wait_for(lambda: len(got.samples) == 3)
        release(guidance, state)
        assert wait_for(lambda: not (pub.has_subscribers("guidance")
                                     or pub.has_subscribers("state")))  # fmt: skip
        pub.publish_tick(next(commands))
        assert wait_for(lambda: sent(4)) and pub.samples_published == 3
    # (two subscribers: their callbacks may run in either order)
    assert sorted(k.rsplit("/", 1)[1] for k, _, _ in got.samples) == ["guidance", "guidance",
                                                                       "state"]  # fmt: skip


def test_events_are_published_in_order_with_their_data(endpoint: str) -> None:
    got = Collector()
    with publisher(endpoint) as pub, zenoh.open(peer(endpoint)) as session:
        sub = session.declare_subscriber(key("vehicle1", "event"), got)
        assert wait_for(lambda: pub.has_subscribers("event"))
        pub.publish_event(Event(EventKind.ENGAGED, 3.0, "guiding in GUIDED", {"setpoints": 0}))
        pub.publish_event(Event(EventKind.INTERCEPTED, 9.5, "done", {"miss_distance_m": 0.07}))
        pub.publish_event(Event(EventKind.SCENARIO, 9.6, "new scenario " + "n" * 60_000))
        assert wait_for(lambda: len(got.samples) == 3)
        release(sub)
    first, second, long = got.of("event")
    assert long["message"].startswith("new scenario nnn") and len(long["message"]) <= 500
    assert got.samples[0][1] == "application/json;ezcompanion.event.v1"
    assert (first["kind"], first["time_s"], first["data"]) == ("engaged", 3.0, {"setpoints": 0})
    assert (second["kind"], second["data"]["miss_distance_m"]) == ("intercepted", 0.07)
    assert second["seq"] > first["seq"]


def test_ticks_faster_than_the_publish_rate_go_out_as_the_newest_at_that_rate(
    endpoint: str,
) -> None:
    """The loop hands over 200 ticks, one every 2 ms: once a period (20 Hz here) the
    publisher sends the newest tick it holds; the others are skipped and counted. Nothing
    queues: what is sent last is the loop's last tick."""
    commands = list(engagement(200))
    got = Collector()
    with publisher(endpoint) as pub, zenoh.open(peer(endpoint)) as session:
        sub = session.declare_subscriber(key("vehicle1", "guidance"), got)
        assert wait_for(lambda: pub.has_subscribers("guidance"))
        start = time.monotonic()
        for command in commands:
            pub.publish_tick(command)
            time.sleep(0.002)
        elapsed_s = time.monotonic() - start
        pub.close()  # sends the newest tick it holds
        assert wait_for(lambda: len(got.samples) == pub.ticks_published)
        release(sub)
    published = pub.ticks_published
    assert len(got.samples) == published  # only guidance is subscribed: state is not built
    assert published + pub.ticks_skipped == len(commands)
    # at most one a period, and the one close() sent
    assert 2 <= published <= elapsed_s * 20.0 + 2, (published, elapsed_s)
    assert published < len(commands) / 2
    times = [g["time_s"] for g in got.of("guidance")]
    assert times[-1] == commands[-1].time_s
    assert times == sorted(set(times))
    assert all(g["sent_unix_s"] >= g["wall_time_unix_s"] for g in got.of("guidance"))


def test_a_slow_subscriber_gets_the_newest_sample_not_a_backlog(endpoint: str) -> None:
    """zenoh's latest-sample handler, RingChannel(1), as docs/telemetry.md advises for slow
    consumers: the subscriber takes a sample only every 60 ms or more while the publisher
    sends at 200 Hz. Each sample it takes was published after its previous nap began (a
    queue would hand it the next old one instead), so it never falls behind; the publisher
    is never held back. A nap lasts until the publisher has gone on and two samples
    published since it began have reached the subscriber's session, seen by a callback
    beside the ring: on a loaded machine 60 ms of wall time could pass with none published
    or none delivered, and the ring then rightly held an older one (an audit's)."""
    commands = list(engagement(40))
    taken: list[tuple[int, int]] = []  # (seq taken, newest seq out when the nap began)
    seen = Collector()  # every sample as it reaches the subscriber's session, in order
    with publisher(endpoint, publish_rate_hz=200.0) as pub, zenoh.open(peer(endpoint)) as session:
        ring = session.declare_subscriber(
            key("vehicle1", "guidance"), zenoh.handlers.RingChannel(1)
        )
        watch = session.declare_subscriber(key("vehicle1", "guidance"), seen)
        assert wait_for(lambda: pub.has_subscribers("guidance"))
        stop = threading.Event()

        def loop() -> None:
            k = 0
            while not stop.is_set():
                pub.publish_tick(commands[k % len(commands)])
                k += 1
                time.sleep(0.002)

        def napped(newest: int) -> bool:
            """Six more sent since the nap began (the publisher goes on while the consumer
            takes none), and two of those since then arrived: the first of them reached
            the ring too before the second arrived at all (one session delivers in order)."""
            arrived = [g["seq"] for g in seen.of("guidance")]
            return pub.ticks_published >= newest + 6 and len(arrived) >= 2 and (
                arrived[-2] > newest
            )

        ticker = threading.Thread(target=loop)
        ticker.start()
        try:
            for _ in range(12):
                newest = pub.ticks_published
                time.sleep(0.06)  # the slow consumer's work
                assert wait_for(lambda newest=newest: napped(newest)), "the publisher stopped"
                sample = ring.recv()
                payload = decode(sample.payload.to_bytes(), str(sample.encoding))
                taken.append((payload["seq"], newest))
        finally:
            stop.set()
            ticker.join()
        release(ring, watch)
    seqs = [seq for seq, _ in taken]
    assert seqs == sorted(set(seqs))  # each sample once, in order
    assert all(seq > newest for seq, newest in taken), taken


# --- presence, status, scenario updates -------------------------------------------------


def test_the_liveliness_token_comes_and_goes_with_the_publisher(endpoint: str) -> None:
    seen: list[tuple[str, str]] = []

    def on_alive(sample: zenoh.Sample) -> None:
        seen.append((str(sample.key_expr), str(sample.kind)))

    # the monitor joins after the token exists: it learns of it from the history
    with publisher(endpoint) as pub, zenoh.open(peer(endpoint)) as session:
        live = session.liveliness().declare_subscriber(key("*", "alive"), on_alive, history=True)
        assert wait_for(lambda: len(seen) == 1)
        pub.close()
        assert wait_for(lambda: len(seen) == 2)
        release(live)
    assert seen == [
        ("ezcompanion/vehicle1/alive", "SampleKind.PUT"),
        ("ezcompanion/vehicle1/alive", "SampleKind.DELETE"),
    ]


def _query(session: zenoh.Session, key_expr: str, payload: bytes | None = None) -> Any:
    replies = list(session.get(key_expr, payload=payload, timeout=5.0))
    assert len(replies) == 1 and replies[0].ok is not None, [
        (r.replier_id, r.ok and r.ok.payload.to_string()[:200], r.err and r.err.payload.to_string())
        for r in replies
    ]
    return str(replies[0].ok.encoding), json.loads(replies[0].ok.payload.to_bytes())


def test_status_gives_version_provider_and_last_state(endpoint: str) -> None:
    command = next(engagement(1))
    with (
        publisher(endpoint, status=lambda: {"phase": "guiding", "scenario": {"name": "x"},
                                            "last_state": "the provider's"}) as pub,
        zenoh.open(peer(endpoint)) as session,
    ):
        pub.publish_tick(command)
        pub.publish_event(Event(EventKind.ENGAGED, 1.0, "guiding"))
        # nobody subscribes: the tick is not built, the event is put (zenoh drops it)
        assert wait_for(lambda: pub.ticks_published == 1 and pub.samples_published == 1)
        encoding, status = _query(session, key("vehicle1", "status"))
        # asked of every vehicle, each answers under its own key (a reviewer's replies came
        # back keyed with the wildcard: several vehicles could not be told apart)
        (reply,) = list(session.get("ezcompanion/*/status", timeout=5.0))
        assert reply.ok is not None and str(reply.ok.key_expr) == key("vehicle1", "status")
    assert encoding == f"application/json;{SCHEMAS['status']}"
    assert status["version"] and status["vehicle_id"] == "vehicle1"
    assert (status["phase"], status["scenario"]) == ("guiding", {"name": "x"})
    # the state sample itself, whatever the provider adds (the service's five numbers had
    # taken its place: a reviewer's)
    assert status["last_state"]["north_m"] == command.state.north_m
    assert {"seq", "down_m", "yaw_rad"} <= set(status["last_state"])
    assert status["recent_events"][0]["kind"] == "engaged"


def test_a_failing_status_provider_still_replies(endpoint: str) -> None:
    def broken() -> dict[str, Any]:
        raise RuntimeError("no status yet")

    with publisher(endpoint, status=broken), zenoh.open(peer(endpoint)) as session:
        _, status = _query(session, key("vehicle1", "status"))
    assert status["status_error"] == "RuntimeError: no status yet"


def inbox_for(base: Scenario) -> ScenarioInbox:
    """The service's inbox: updates validated against the running scenario."""
    return ScenarioInbox(lambda data: scenario_update(base, data))


def test_the_inbox_takes_the_newest_valid_update_once() -> None:
    inbox = inbox_for(load_scenario(CONFIG))
    more = copy.deepcopy(SCENARIO_RAW)
    more["defenders"][0]["north_m"] = 5.0
    assert inbox.offer(copy.deepcopy(SCENARIO_RAW)) is None
    assert inbox.offer(more) is None
    taken = inbox.take()
    assert taken is not None and taken.defenders[0].north_m == 5.0 and inbox.take() is None
    assert inbox.accepted == 2


# --- many vehicles ------------------------------------------------------------------------


def test_two_vehicles_through_one_router_are_told_apart(endpoint: str) -> None:
    router = session_config(TelemetrySettings(mode="router", listen=(endpoint,)))
    commands = list(engagement(5))
    got = Collector()
    seen: list[str] = []
    with zenoh.open(router):
        client = session_config(TelemetrySettings(mode="client", listen=(), connect=(endpoint,)))
        with (
            zenoh.open(client) as session,
            publisher(
                endpoint, vehicle_id="alpha", mode="client", connect=[endpoint],
                publish_rate_hz=1e3, patient=True,
            ) as a,
            publisher(endpoint, vehicle_id="bravo", mode="client", connect=[endpoint]) as b,
        ):
            sub = session.declare_subscriber(key("*", "guidance"), got)
            live = session.liveliness().declare_subscriber(
                key("*", "alive"), lambda s: seen.append(str(s.key_expr)), history=True
            )
            assert wait_for(lambda: a.has_subscribers() and b.has_subscribers())
            for sent, command in enumerate(commands, start=1):
                a.publish_tick(command)
                assert wait_for(lambda sent=sent: a.ticks_published == sent)  # type: ignore[misc]
            b.publish_tick(commands[-1])
            assert wait_for(lambda: len(got.samples) == len(commands) + 1)
            assert wait_for(lambda: len(seen) == 2)
            _, status_b = _query(session, key("bravo", "status"))
            release(sub)
            release(live)
    by_key: dict[str, list[dict[str, Any]]] = {}
    for k, _, payload in got.samples:
        by_key.setdefault(k, []).append(payload)
    assert sorted(by_key) == ["ezcompanion/alpha/guidance", "ezcompanion/bravo/guidance"]
    assert {p["vehicle_id"] for p in by_key["ezcompanion/alpha/guidance"]} == {"alpha"}
    assert len(by_key["ezcompanion/alpha/guidance"]) == len(commands)
    assert by_key["ezcompanion/bravo/guidance"][0]["time_s"] == commands[-1].time_s
    assert sorted(seen) == ["ezcompanion/alpha/alive", "ezcompanion/bravo/alive"]
    assert status_b["vehicle_id"] == "bravo"


def test_close_is_idempotent_and_later_samples_are_ignored(endpoint: str) -> None:
    pub = publisher(endpoint)
    pub.close()
    pub.close()
    pub.publish_tick(next(engagement(1)))
    pub.publish_event(Event(EventKind.ENDED, 1.0, "over"))
    assert pub.samples_published == 0


def test_threads_do_not_leak(endpoint: str) -> None:
    # by identity, not name: a thread another test's session ends late keeps its own name
    before = set(threading.enumerate())
    pub = publisher(endpoint)
    started = set(threading.enumerate()) - before
    assert any(t.name.startswith("telemetry-") for t in started)  # its own sending thread
    pub.close()
    assert wait_for(lambda: not started & set(threading.enumerate()), 10.0), started
