"""``monitor --record FILE.mcap``: the bridge's Foxglove channels in an MCAP file, read back
with the ``mcap`` package's reader and decoded (protobuf from the recorded schemas, JSON);
the values are the ticks the publisher sent. A real zenoh publisher and monitor on
127.0.0.1 (fresh port, no multicast)."""

from __future__ import annotations

import math
import subprocess
import sys
import threading
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from test_foxglove import SCENARIO, decoder  # type: ignore[import-not-found]
from test_service_loopback import SPEEDUP, stub_process  # type: ignore[import-not-found]
from test_telemetry import SCENARIO_RAW, free_endpoint, publisher, wait_for  # type: ignore[import-not-found]
from test_telemetry_monitor import fly  # type: ignore[import-not-found]

from ezcompanion.cli import main
from ezcompanion.config import scenario_from_dict
from ezcompanion.service.demo import free_udp_port, wait_for_line
from ezcompanion.telemetry.foxglove_sink import topics
from ezcompanion.wire import geodetic_to_ned


def read_mcap(path: Path) -> tuple[dict[str, str], dict[str, list[tuple[int, Any]]]]:
    """(schema name by topic, decoded (log_time_ns, message) by topic) of an MCAP file."""
    schemas: dict[str, str] = {}
    messages: dict[str, list[tuple[int, Any]]] = {}
    decoders: dict[int, Any] = {}
    with path.open("rb") as handle:
        reader = make_reader(handle)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None  # a finished file
        for schema, channel, message in reader.iter_messages():
            assert schema is not None
            schemas[channel.topic] = schema.name
            if channel.id not in decoders:
                decoders[channel.id] = decoder(channel.message_encoding, schema.name, schema.data)
            decoded = decoders[channel.id](message.data)
            messages.setdefault(channel.topic, []).append((message.log_time, decoded))
    return schemas, messages


def test_monitor_records_the_foxglove_channels_to_mcap(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    endpoint = free_endpoint()
    record = tmp_path / "run.mcap"
    status = {"phase": "guiding", "scenario": SCENARIO_RAW}
    done: list[int] = []
    args = ["monitor", "--connect", endpoint, "--record", str(record), "--duration", "5"]
    asked = threading.Event()  # the monitor asked for the status (the map's origin)

    def answer() -> dict[str, Any]:
        asked.set()
        return status

    with publisher(endpoint, status=answer, publish_rate_hz=1000.0, patient=True) as pub:
        thread = threading.Thread(target=lambda: done.append(main(args)))
        thread.start()
        try:
            assert wait_for(lambda: pub.has_subscribers("guidance"), 5.0)
            assert wait_for(lambda: pub.has_subscribers("event") and pub.has_subscribers("state"))
            assert asked.wait(30.0)
            commands = fly(pub)
        finally:
            thread.join(20.0)
    assert done == [0]
    schemas, messages = read_mcap(record)
    vehicle = topics("vehicle1")
    assert schemas == {
        vehicle["map_vehicle"]: "foxglove.LocationFix",
        vehicle["map_target"]: "foxglove.LocationFix",
        vehicle["scene"]: "foxglove.SceneUpdate",
        vehicle["plots"]: "ezcompanion.plots.v1",
        vehicle["events"]: "foxglove.Log",
    }
    counts = Counter({topic: len(m) for topic, m in messages.items()})
    ticks = len(commands)
    assert counts[vehicle["plots"]] == counts[vehicle["scene"]] == ticks
    # the map begins once the status reply (the origin) is in: asked before the first tick,
    # it can still arrive after some on a loaded machine (38 of 40 were mapped under two CPU
    # burners before this wait); from then on one fix per tick, the last ones checked below
    mapped = counts[vehicle["map_vehicle"]]
    assert counts[vehicle["map_target"]] == mapped and 1 <= mapped <= ticks
    assert counts[vehicle["events"]] == 2  # engaged, intercepted

    plots = [p for _, p in messages[vehicle["plots"]]]
    np.testing.assert_allclose([p["time_s"] for p in plots], [c.time_s for c in commands])
    np.testing.assert_allclose([p["h_m"] for p in plots], [float(c.step.law.h_m) for c in commands])
    np.testing.assert_allclose(
        [p["clearance_m"]["D2"] for p in plots],
        [float(c.step.law.clearance_m.reshape(-1)[1]) for c in commands],
    )
    scenario = scenario_from_dict(SCENARIO_RAW)
    origin = scenario.origin
    for (_, fix), command in zip(messages[vehicle["map_vehicle"]], commands[ticks - mapped:],
                                 strict=True):
        back = geodetic_to_ned(
            fix.latitude, fix.longitude, fix.altitude, origin_lat_deg=origin.lat_deg,
            origin_lon_deg=origin.lon_deg, origin_alt_m=origin.alt_m,
        )  # fmt: skip
        s = command.state
        np.testing.assert_allclose(back, (s.north_m, s.east_m, s.down_m), atol=1e-6)
        assert fix.heading == pytest.approx(s.yaw_rad)
    log_times = [t for t, _ in messages[vehicle["plots"]]]
    assert log_times == sorted(log_times)  # the vehicle's wall time of each tick
    _, scene = messages[vehicle["scene"]][-1]
    assert {e.id for e in scene.entities} == {"zone/D1", "zone/D2", "zone/D3", "target", "track",
                                             "vehicle"}  # fmt: skip
    track = next(e for e in scene.entities if e.id == "track").lines[0].points
    last = commands[-1].state
    assert len(track) == ticks
    assert math.hypot(track[-1].x - last.east_m, track[-1].y - last.north_m) < 1e-12
    # the vehicle's arrow (its +x axis) points along its course: x east, y north
    q = next(e for e in scene.entities if e.id == "vehicle").arrows[0].pose.orientation
    pointing = (1.0 - 2.0 * (q.y**2 + q.z**2), 2.0 * (q.x * q.y + q.w * q.z))
    course = commands[-1].course_rad
    np.testing.assert_allclose(pointing, (math.sin(course), math.cos(course)), atol=1e-9)
    events = [m.message for _, m in messages[vehicle["events"]]]
    assert events == ["engaged: guiding in GUIDED", "intercepted: within 0.1 m"]
    assert {p["mode"] for p in plots} <= {"intercept", "blend", "safety", "captured"}

    # an MCAP file is written once: recording onto an existing one is refused, in one line
    capsys.readouterr()
    assert main(["monitor", "--connect", endpoint, "--record", str(record)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--record" in err[0] and "exists" in err[0]


def test_run_records_its_own_telemetry_to_mcap(tmp_path: Path) -> None:
    # `ezcompanion run --record FILE.mcap` as its own process (as `make demo` runs the
    # companion), the loopback vehicle in another, joined once the companion listens
    endpoint, port = free_endpoint(), free_udp_port()
    record = tmp_path / "run.mcap"
    companion = subprocess.Popen(
        [sys.executable, "-m", "ezcompanion", "run", "--config", str(SCENARIO),
         "--connect", f"udpin:127.0.0.1:{port}", "--engage", "--speedup", f"{SPEEDUP:g}",
         "--zenoh-listen", endpoint, "--record", str(record), "--max-time", "150"],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    assert companion.stdout is not None
    lines: list[str] = []
    try:
        wait_for_line(companion.stdout, "listening:")
        drain = threading.Thread(target=lambda: lines.extend(companion.stdout or []))
        drain.start()
        with stub_process(SCENARIO, port, tmp_path / "truth.csv", "--initial-mode", "GUIDED"):
            code = companion.wait(timeout=90)
        drain.join(10.0)
    finally:
        companion.kill()
        companion.wait()
    # (whether it intercepted is the loopback tests' business: on a saturated machine the
    # stub's stalls can make it miss; the recording must hold the engagement either way)
    assert code in (0, 1), "".join(lines)
    schemas, messages = read_mcap(record)
    vehicle = topics("vehicle1")
    assert set(schemas) == set(vehicle.values())
    plots = [p for _, p in messages[vehicle["plots"]]]
    assert len(plots) >= 10 and len(messages[vehicle["map_vehicle"]]) >= 10
    assert len(messages[vehicle["scene"]]) == len(plots) == len(messages[vehicle["map_target"]])
    # every event the companion printed after it listened is in the recording, in order
    # (and `listening` itself, when the subscription reached the vehicle before it went out)
    printed = [line.split("] ", 1)[1].split(":")[0] for line in lines if line.startswith("[")]
    kinds = [m.message.split(":")[0] for _, m in messages[vehicle["events"]]]
    after_listening = kinds[1:] if kinds[:1] == ["listening"] else kinds
    assert after_listening == printed and "ended" in kinds and "engaged" in kinds
    # after the end, only the end mode: asked for, the vehicle's reports of it, the answer
    assert set(kinds[kinds.index("ended") + 1:]) <= {"on_exit", "mode", "statustext"}
    assert ("intercepted" in kinds) == (code == 0)


def test_an_mcap_that_cannot_be_written_or_is_replayed_is_said_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A reviewer's `monitor --record /proc/x.mcap` said only "No such file or directory
    (os error 2)", and `monitor --replay run.mcap` "not UTF-8 text: ...". Each now names
    the flag, the file and what to do."""
    blocked = tmp_path / "a-file"
    blocked.write_text("")
    path = blocked / "x.mcap"  # (its directory is a file)
    assert main(["monitor", "--connect", free_endpoint(), "--record", str(path),
                 "--duration", "0.1"]) == 2  # fmt: skip
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith("ezcompanion: error: --record: cannot be written: ")
    assert line.endswith("x.mcap')")  # (the file named; a long path is shortened)
    recording = tmp_path / "run.mcap"
    recording.write_bytes(b"\x89MCAP0\r\n")
    assert main(["monitor", "--replay", str(recording)]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith("ezcompanion: error: --replay: is an MCAP recording")
    assert "Foxglove" in line
