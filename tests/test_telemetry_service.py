"""Zenoh telemetry from the real service during a loopback engagement (real sessions on
127.0.0.1, a fresh port, no multicast): a monitor on plain TCP watches, an operator with a
TLS client certificate moves a defender."""

from __future__ import annotations

import json
import threading
from pathlib import Path
from typing import Any

import numpy as np
import zenoh
from test_service_loopback import CONFIG, fly
from test_telemetry import Collector, _query, free_endpoint, peer, wait_for
from test_telemetry_access import Pki, client, pki, tls_endpoint  # noqa: F401 (a fixture)

from ezcompanion.config import load_scenario, scenario_update
from ezcompanion.guidance import evaluate_law
from ezcompanion.service.events import EventKind
from ezcompanion.telemetry import key, telemetry_settings
from ezcompanion.telemetry.settings import release

SCENARIO = CONFIG / "paper_scenario1.yaml"
# D2 moved 1.5 m west, away from the flight path; same three defenders
MOVED = {
    "defenders": [
        {
            "name": "D1",
            "north_m": 2.0,
            "east_m": 3.0,
            "range_m": 1.5,
            "capture_radius_m": 0.5,
            "speed_ratio": 0.7,
        },
        {
            "name": "D2",
            "north_m": 4.4,
            "east_m": -3.5,
            "range_m": 1.5,
            "capture_radius_m": 0.5,
            "speed_ratio": 0.7,
        },
        {
            "name": "D3",
            "north_m": 1.0,
            "east_m": -2.6,
            "range_m": 1.5,
            "capture_radius_m": 0.5,
            "speed_ratio": 0.7,
        },
    ],
    "target": {"north_m": 2.0, "east_m": 0.0},
}


def clearances(scenario: Any, sample: dict[str, Any]) -> list[float]:
    """What the law's geometry gives for a published sample's position and course."""
    out = evaluate_law(
        scenario.law,
        scenario.guidance,
        scenario.zones(),
        target_north_m=scenario.target.north_m,
        target_east_m=scenario.target.east_m,
        north_m=sample["north_m"],
        east_m=sample["east_m"],
        course_rad=sample["course_rad"],
        speed_m_s=sample["speed_m_s"],
        accel_m_s2=0.0,
    )
    return [float(c) for c in out.clearance_m]


def test_a_monitor_follows_the_engagement_and_a_scenario_update_moves_a_defender(
    tmp_path: Path,
    pki: Pki,  # noqa: F811 (the fixture)
) -> None:
    endpoint, operator_endpoint = free_endpoint(), tls_endpoint()
    got = Collector()
    alive: list[str] = []
    replies: dict[str, Any] = {}

    def monitor(service: Any, _stub: Any, _port: int, _truth: Path) -> None:
        with zenoh.open(peer(endpoint)) as session:
            subs = [
                session.declare_subscriber(key("vehicle1", leaf), got)
                for leaf in ("guidance", "state")
            ]
            token = session.liveliness().declare_subscriber(
                key("*", "alive"), lambda s: alive.append(str(s.kind)), history=True
            )
            assert wait_for(lambda: len(got.of("guidance")) >= 25, 30.0)
            moved = json.dumps(MOVED).encode()
            bad = json.loads(moved)
            bad["defenders"][0]["speed_ratio"] = 1.5
            # the monitor cannot change the scenario: zenoh's ACL keeps its query out
            replies["monitor"] = list(session.get(key("vehicle1", "scenario"), payload=moved))
            with zenoh.open(client(operator_endpoint, tls=pki.tls("operator"))) as operator:
                assert wait_for(lambda: bool(list(operator.info.peers_zid())), 10.0)
                scenario = key("vehicle1", "scenario")
                replies["good"] = _query(operator, scenario, moved)[1]
                replies["bad"] = _query(operator, scenario, json.dumps(bad).encode())[1]
            ended = threading.Event()
            service.events.add_sink(lambda e: ended.set() if e.kind is EventKind.ENDED else None)
            assert ended.wait(60.0)
            assert wait_for(lambda: "SampleKind.DELETE" in alive, 10.0)
            for sub in (*subs, token):
                release(sub)

    flight = fly(
        SCENARIO,
        tmp_path,
        telemetry=telemetry_settings(
            {
                "listen": [endpoint, operator_endpoint],
                "tls": pki.tls("vehicle1"),
                "scenario_updates": {"enabled": True, "cert_common_names": ["operator"]},
                "publish_rate_hz": 50.0,  # the loop's: 20 samples each side of the update
            }
        ),
        during=monitor,
        max_time_s=60.0,
    )
    assert replies["monitor"] == []
    assert replies["good"] == {"ok": True}
    assert replies["bad"]["ok"] is False and "defenders[0].speed_ratio" in replies["bad"]["error"]
    assert alive[0] == "SampleKind.PUT" and alive[-1] == "SampleKind.DELETE"
    assert flight.outcome.intercepted
    # the loop took the update between ticks, once (the bad one changed nothing)
    updates = flight.events.of_kind(EventKind.SCENARIO)
    assert len(updates) == 1
    assert flight.service.scenario.defenders[1].east_m == -3.5
    # guidance published before the update follows the old geometry, after it the new one
    original = load_scenario(SCENARIO)
    moved = scenario_update(original, MOVED)
    guidance = got.of("guidance")
    before = [g for g in guidance if g["time_s"] < updates[0].time_s]
    after = [g for g in guidance if g["time_s"] > updates[0].time_s]
    assert len(before) > 20 and len(after) > 20 and got.of("state")
    for sample in (before[-1], after[0], after[-1]):
        geometry = moved if sample in after else original
        published = [z["clearance_m"] for z in sample["zones"]]
        np.testing.assert_allclose(published, clearances(geometry, sample), atol=1e-9)
    # (and the two geometries differ enough there for that check to tell them apart)
    assert abs(clearances(moved, after[0])[1] - clearances(original, after[0])[1]) > 0.1
