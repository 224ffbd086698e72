"""The monitor (live table, JSON lines, recording), recordings back to tracks, the CLI."""

from __future__ import annotations

import argparse
import io
import json
import socket
import tempfile
import threading
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from test_telemetry import (  # type: ignore[import-not-found]
    CONFIG,
    SCENARIO_RAW,
    engagement,
    free_endpoint,
    publisher,
    wait_for,
)

from ezcompanion.config import load_scenario
from ezcompanion.errors import ConfigError
from ezcompanion.service.events import Event, EventKind
from ezcompanion.sim.output import track_header
from ezcompanion.telemetry import monitor as monitor_module
from ezcompanion.telemetry.cli import (
    add_telemetry_parsers,
    monitor_config,
    router_config,
    run_router,
    run_telemetry_command,
)
from ezcompanion.telemetry.mcap_recording import McapRecorder
from ezcompanion.telemetry.monitor import MonitorView, run_monitor
from ezcompanion.telemetry.recording import read_recording, recorded_scenario


class Monitor:
    """``run_monitor`` on a thread, printing into a string."""

    def __init__(self, connect: str, **options: Any) -> None:
        self.out = io.StringIO()
        self.stop = threading.Event()
        self.view: MonitorView | None = None
        conf = monitor_config(connect=[connect], **options.pop("conf", {}))

        def run() -> None:
            self.view = run_monitor(conf, out=self.out, stop=self.stop, **options)

        self.thread = threading.Thread(target=run)
        self.thread.start()

    def text(self) -> str:
        return self.out.getvalue()

    def close(self) -> MonitorView:
        self.stop.set()
        self.thread.join(5.0)
        assert self.view is not None
        return self.view


def fly(pub: Any, ticks: int = 40) -> list[Any]:
    """Publish an engagement, each tick out before the next (the publisher sends the newest
    tick it holds: a faster loop would have some skipped), then its interception."""
    commands = list(engagement(ticks))
    pub.publish_event(Event(EventKind.ENGAGED, commands[0].time_s, "guiding in GUIDED"))
    assert wait_for(lambda: pub.samples_published == 1)
    for sent, command in enumerate(commands, start=1):
        pub.publish_tick(command)
        assert wait_for(lambda sent=sent: pub.ticks_published == sent)  # type: ignore[misc]
    pub.publish_event(Event(EventKind.INTERCEPTED, commands[-1].time_s, "within 0.1 m"))
    return commands


def test_the_live_table_shows_margins_mode_accelerations_and_outcome(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    endpoint = free_endpoint()
    record = tmp_path / "engagement.jsonl"
    status = {"phase": "guiding", "scenario": SCENARIO_RAW}
    with publisher(endpoint, status=lambda: status, publish_rate_hz=1000.0, patient=True) as pub:
        monitor = Monitor(endpoint, record=record, refresh_hz=20.0)
        assert wait_for(lambda: pub.has_subscribers("guidance") and pub.has_subscribers("event"))
        assert wait_for(lambda: "yes" in monitor.text())  # alive, and its status asked
        commands = fly(pub)
        assert wait_for(lambda: "intercepted" in monitor.text().rsplit("ezcompanion monitor")[-1])
        view = monitor.close()
    table = monitor.text().rsplit("ezcompanion monitor", 1)[-1]  # the last redraw
    assert "\x1b[2J" not in monitor.text()  # no terminal: plain redraws
    lines = table.splitlines()
    assert lines[1].split()[:6] == ["vehicle", "live", "t_s", "mode", "range_m", "h_m"]
    row = lines[2].split()
    last = commands[-1].step.law
    assert row[0] == "vehicle1" and row[1] == "yes" and row[-1] == "intercepted"
    assert float(row[2]) == pytest.approx(commands[-1].time_s, abs=0.005)
    assert float(row[4]) == pytest.approx(float(last.range_to_target_m), abs=0.0005)
    assert lines[3].split()[0] == "margin_m" and lines[3].split()[1::2] == ["D1", "D2", "D3"]
    assert "intercepted: within 0.1 m" in lines[4]
    vehicle = view.vehicles["vehicle1"]
    assert vehicle.status is not None and vehicle.status["phase"] == "guiding"
    assert vehicle.guidance is not None and vehicle.guidance["seq"] > 0

    # the recording: the same samples, back as a track the simulator's plot can draw
    scenario = recorded_scenario(record)
    assert scenario == load_scenario(CONFIG)
    run = read_recording(record, track_csv=tmp_path / "track.csv")
    header = (tmp_path / "track.csv").read_text().splitlines()[0].split(",")
    assert header == track_header(("D1", "D2", "D3"))
    np.testing.assert_allclose(run.t_s, [c.time_s for c in commands], rtol=0, atol=1e-9)
    np.testing.assert_allclose(
        run.margin_m, [c.step.law.margin_m for c in commands], rtol=1e-8, atol=1e-9
    )
    np.testing.assert_allclose(run.heading_rad, [c.course_rad for c in commands], rtol=1e-8)
    # recorded twice into one file (`--record` appends): the last engagement is the track,
    # and that is said (a reviewer's two had been joined into one, time going back)
    twice = tmp_path / "twice.jsonl"
    twice.write_text(record.read_text() * 2)
    again = read_recording(twice, track_csv=tmp_path / "twice.csv")
    np.testing.assert_allclose(again.t_s, run.t_s, rtol=0, atol=1e-9)
    assert any("holds 2 engagements" in r.getMessage() for r in caplog.records)


def test_json_lines_are_the_raw_samples() -> None:
    endpoint = free_endpoint()
    with publisher(endpoint, publish_rate_hz=1000.0, patient=True) as pub:
        monitor = Monitor(endpoint, json_lines=True, vehicle="vehicle1")
        assert wait_for(lambda: pub.has_subscribers("guidance") and pub.has_subscribers("event"))
        fly(pub, ticks=5)
        assert wait_for(lambda: '"intercepted"' in monitor.text())
        monitor.close()
    lines = [json.loads(line) for line in monitor.text().splitlines()]
    keys = [line["key"] for line in lines]
    assert keys.count("ezcompanion/vehicle1/guidance") == 5
    assert keys.count("ezcompanion/vehicle1/state") == 5
    assert "ezcompanion/vehicle1/alive" in keys and "ezcompanion/vehicle1/status" in keys
    guidance = next(line for line in lines if line["key"].endswith("/guidance"))
    assert guidance["encoding"] == "application/msgpack;ezcompanion.guidance.v1"
    assert guidance["payload"]["vehicle_id"] == "vehicle1"


def test_a_vehicle_that_goes_away_is_marked_gone() -> None:
    view = MonitorView()
    view.update("ezcompanion/v2/alive", True)
    view.update("ezcompanion/v2/guidance", {"time_s": 1.0, "mode": "blend", "zones": []})
    assert view.vehicles["v2"].outcome == "guiding"
    view.update("ezcompanion/v2/alive", False)
    line = view.render().splitlines()[2]
    assert line.split()[:2] == ["v2", "no"] and line.endswith("gone")
    assert "waiting for" in MonitorView().render()


def test_a_recording_without_the_scenario_needs_one(tmp_path: Path) -> None:
    record = tmp_path / "r.jsonl"
    record.write_text(json.dumps({"key": "ezcompanion/v/state", "payload": {}}) + "\n")
    with pytest.raises(ConfigError, match="not in the recording"):
        read_recording(record)
    with pytest.raises(ConfigError, match="no guidance samples"):
        read_recording(record, load_scenario(CONFIG))


# --- the command line ---------------------------------------------------------------------


def parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="ezcompanion")
    commands = parser.add_subparsers(dest="command", required=True)
    commands.add_parser("simulate")
    add_telemetry_parsers(commands)
    return parser.parse_args(argv)


def test_the_commands_parse_with_defaults_and_ignore_others() -> None:
    args = parse(["monitor"])
    assert (args.connect, args.vehicle, args.json, args.record) == (None, "*", False, None)
    args = parse(["router", "--listen", "tcp/0.0.0.0:7447", "--listen", "tcp/[::]:7448"])
    assert args.listen == ["tcp/0.0.0.0:7447", "tcp/[::]:7448"]
    assert run_telemetry_command(parse(["simulate"])) is None
    with pytest.raises(SystemExit):  # the flag is checked as it is read
        parse(["monitor", "--connect", "localhost:7447"])


def _accepts(host: str, port: int) -> bool:
    try:
        socket.create_connection((host, port), timeout=0.5).close()
    except OSError:
        return False
    return True


def test_monitor_through_a_router_and_replay_with_a_plot(tmp_path: Path) -> None:
    endpoint = free_endpoint()
    stop = threading.Event()
    router = threading.Thread(target=run_router, args=(router_config(listen=[endpoint]),),
                              kwargs={"stop": stop})  # fmt: skip
    router.start()
    host, port = endpoint.removeprefix("tcp/").split(":")
    # clients cannot wait for a router
    assert wait_for(lambda: _accepts(host, int(port)), timeout_s=30.0)
    record = tmp_path / "rec.jsonl"
    try:
        with publisher(
            endpoint, vehicle_id="alpha", mode="client", connect=[endpoint],
            status=lambda: {"scenario": SCENARIO_RAW}, publish_rate_hz=1000.0,
        ) as pub:  # fmt: skip
            monitor = Monitor(endpoint, record=record, conf={"mode": "client"})
            # three sessions meet through the router: on a loaded machine that can take more
            # than the usual 5 s (each wait returns as soon as it holds)
            assert wait_for(lambda: pub.has_subscribers("guidance"), timeout_s=30.0)
            assert wait_for(lambda: "alpha" in monitor.text(), timeout_s=30.0)
            fly(pub, ticks=30)
            assert wait_for(lambda: "intercepted" in monitor.text(), timeout_s=30.0)
            view = monitor.close()
    finally:
        stop.set()
        router.join(5.0)
    assert view.vehicles["alpha"].outcome == "intercepted"
    png = tmp_path / "replay.png"
    args = parse(["monitor", "--replay", str(record), "--plot", str(png)])
    assert run_telemetry_command(args) == 0
    assert png.stat().st_size > 10_000


def test_replay_of_a_missing_or_broken_file_is_one_line_and_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from ezcompanion.cli import main

    binary = tmp_path / "binary.jsonl"
    binary.write_bytes(b"\x89PNG\r\n\x1a\n\xff\xfe\x00" * 40)
    not_samples = tmp_path / "list.jsonl"
    not_samples.write_text('{"key": "ezcompanion/v/state", "payload": {}}\n[1, 2]\n')
    cases = {
        tmp_path / "missing.jsonl": "recording: no such file",
        binary: "not UTF-8 text",
        not_samples: "list.jsonl:2: not a recorded sample",
    }
    for path, error in cases.items():
        assert main(["monitor", "--replay", str(path)]) == 2
        out, err = capsys.readouterr()
        assert out == "" and err.count("\n") == 1 and error in err, err
        assert "Traceback" not in err
    # a vehicle the recording does not hold (a reviewer's printed "no vehicle yet: waiting
    # ..." from a file, and exit 0)
    one = tmp_path / "one.jsonl"
    one.write_text('{"key": "ezcompanion/vehicle1/alive", "payload": true}\n')
    assert main(["monitor", "--replay", str(one), "--vehicle", "vehicle9"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1, err
    assert "--vehicle: not in the recording" in err and "holds vehicle1" in err, err


def test_replay_with_json_prints_the_recorded_lines(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from ezcompanion.cli import main

    record = tmp_path / "r.jsonl"
    lines = [
        {"key": "ezcompanion/a/guidance", "encoding": "e", "payload": {"seq": 1}},
        {"key": "ezcompanion/b/guidance", "encoding": "e", "payload": {"seq": 2}},
        {"key": "ezcompanion/a/alive", "encoding": "", "payload": True},
    ]
    record.write_text("".join(json.dumps(line) + "\n" for line in lines))
    assert main(["monitor", "--replay", str(record), "--json", "--vehicle", "a"]) == 0
    out = capsys.readouterr().out
    assert [json.loads(text) for text in out.splitlines()] == [lines[0], lines[2]]
    assert main(["monitor", "--replay", str(record)]) == 0  # the table, for both vehicles
    table = capsys.readouterr().out
    assert "ezcompanion monitor" in table and "{" not in table


json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.integers(10**300, 10**400)
    | st.floats(allow_nan=True) | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=8), inner,
                                                                max_size=3),
    max_leaves=8,
)
# objects shaped like the samples, with any values in their fields
sample_like = st.fixed_dictionaries({}, optional={
    k: json_values for k in ("kind", "data", "message", "time_s", "mode", "captured", "zones",
                             "h_m", "alpha", "range_to_target_m", "accel_lat_m_s2")})
zone_lists = st.lists(st.fixed_dictionaries({}, optional={
    k: json_values for k in ("name", "clearance_m", "margin_m")}) | json_values, max_size=3)


@settings(max_examples=300, deadline=None)
@given(leaf=st.sampled_from(["event", "guidance", "state", "status", "alive"]),
       payload=json_values | sample_like | st.builds(lambda d, z: {**d, "zones": z},
                                                     sample_like, zone_lists))
def test_any_payload_from_the_network_is_drawn_or_dropped_never_a_crash(leaf: str,
                                                                       payload: Any) -> None:
    """A sample is whatever a peer on the router put there: the monitor takes it or drops
    it, and every view of it draws (a reviewer's list on the event key, a number
    on the guidance key, a zone that is a string, had raised)."""
    view = MonitorView()
    view.update("ezcompanion/uav/guidance", {"time_s": 1.0, "zones": [{"name": "D1"}]})
    view.update(f"ezcompanion/uav/{leaf}", payload)
    assert isinstance(view.render(), str)
    assert isinstance(view.render_table(120), str) and isinstance(view.render_table(40), str)


@settings(max_examples=150, deadline=None)
@given(leaf=st.sampled_from(["event", "guidance", "state", "status"]),
       payload=sample_like | st.builds(lambda d, z: {**d, "zones": z}, sample_like, zone_lists)
       | st.fixed_dictionaries({"north_m": json_values, "east_m": json_values,
                                "message": st.binary(max_size=4) | json_values}))
@example(leaf="guidance", payload={"north_m": 10**400, "east_m": 1.0})  # a reviewer's two
@example(leaf="event", payload={"kind": "x", "message": b"\xff"})
def test_any_payload_is_recorded_or_refused_never_a_crash(leaf: str, payload: Any) -> None:
    """The monitor's sinks (``--record FILE.mcap``, the Foxglove bridge) and its JSON lines
    take whatever the view takes (a reviewer's 400-digit ``north_m`` raised out of the
    MCAP recorder, MessagePack's bytes out of ``--json``)."""
    with tempfile.TemporaryDirectory() as folder, McapRecorder(Path(folder) / "r.mcap") as rec:
        rec.take(f"ezcompanion/uav/{leaf}", payload, 1.0)
    line = json.loads(monitor_module.json_line(f"ezcompanion/uav/{leaf}", "", payload, 1.0))
    assert line["key"] == f"ezcompanion/uav/{leaf}"


def test_a_payload_nested_deeper_than_python_recurses_is_undecodable_not_a_crash() -> None:
    deep = b"[" * 100_000 + b"]" * 100_000  # (a reviewer's: RecursionError out of the loop)
    assert "undecodable" in monitor_module._decode(deep, "application/json")
