"""Issue 11's targets, end to end, over every transport a user meets beside an autopilot:
both paper scenarios on the copter and on PX4, and scenario 1 scaled to a 22 m/s plane.

The companion (in a thread of this process, its own wire code) and the loopback vehicle
(``python -m sitl_stub``, its own wire code in ``sitl_stub/mav.py``) each take one side of a
real link on this machine:

=========  ===============================  ===========================================
name       companion ``--connect``          the stub ``--connect``
=========  ===============================  ===========================================
tcp        ``tcp:127.0.0.1:P`` (client)     ``tcpin:127.0.0.1:P``: SITL's TCP 5760
tcpin      ``tcpin:127.0.0.1:P``            ``tcp:127.0.0.1:P`` (client)
udpin      ``udpin:127.0.0.1:P``            ``udpout:127.0.0.1:P``: SITL's UDP 14550
udpout     ``udpout:127.0.0.1:P``           ``udpin:127.0.0.1:P``
serial     ``DIR/ttyFC,115200`` (pyserial)  ``pty:DIR/ttyFC``: a pseudo-terminal's master
=========  ===============================  ===========================================

The companion starts first wherever it can (a vehicle is usually up before its companion,
but the other order is the harder one): its ``tcp:`` client then finds nothing listening and
waits for the stub, and its ``udpout:`` sends before anyone hears. The serial port exists
only once the stub has made it. Both run in lockstep (the vehicle's time waits for the
companion), so the engagement is the same on a loaded machine, only slower; each must
intercept with true clearance > 0 by the stub's truth.
"""

from __future__ import annotations

import csv
import logging
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml
from test_service_loopback import STUCK, stop_or_dump

from ezcompanion.config import load_scenario
from ezcompanion.service.demo import free_port, free_udp_port, judge_truth
from ezcompanion.service.events import EventKind, EventLog
from ezcompanion.service.runner import CompanionService, EngagementOutcome
from ezcompanion.service.settings import companion_settings
from ezcompanion.wire import Link
from sitl_stub import SitlStub, stub_config
from sitl_stub.mav import StubLink

CONFIG = Path(__file__).resolve().parents[1] / "config"
SCENARIO = CONFIG / "paper_scenario1.yaml"


@dataclass(frozen=True)
class Case:
    """A scenario on a vehicle with its measured response: the copter's 0.5 s course lag;
    PX4's 1.2 s velocity lag, 0.8 of the commanded speed, vz = 0 drifting; ArduPlane
    flying 0.73x of the course command's turn where its roll clip binds, 23.4 m/s over
    ground."""

    config: str
    profile: str
    start_mode: str
    rate_hz: float = 20.0  # the companion's loop and telemetry


CASES = {
    "copter-1": Case("paper_scenario1.yaml", "copter", "GUIDED"),
    "copter-2": Case("paper_scenario2.yaml", "copter", "GUIDED"),
    "px4-1": Case("paper_scenario1.yaml", "px4", "LOITER"),
    "px4-2": Case("paper_scenario2.yaml", "px4", "LOITER"),
    "plane22-1": Case("paper_scenario1_plane22.yaml", "plane", "GUIDED", rate_hz=10.0),
}
_WALL_BUDGET_S = 90.0  # a stuck run fails here instead of hanging the suite


@dataclass(frozen=True)
class Transport:
    """One way to connect: each side's endpoint, and who must start first."""

    companion: str
    stub: str
    stub_first: bool = False


def _transport(name: str, tmp_path: Path) -> Transport:
    if name == "serial":
        tty = tmp_path / "ttyFC"
        return Transport(f"{tty},115200", f"pty:{tty}", stub_first=True)
    port = free_port() if name.startswith("tcp") else free_udp_port()
    pairs: dict[str, tuple[str, str]] = {
        "tcp": ("tcp", "tcpin"),
        "tcpin": ("tcpin", "tcp"),
        "udpin": ("udpin", "udpout"),
        "udpout": ("udpout", "udpin"),
    }
    ours, theirs = pairs[name]
    # udpout: datagrams sent before the stub listens are lost; a lockstep companion's clock
    # waits for the vehicle, but its heartbeat goes on each wall second until one is heard
    return Transport(f"{ours}:127.0.0.1:{port}", f"{theirs}:127.0.0.1:{port}")


def _scenario_file(tmp_path: Path, case: Case) -> Path:
    """The case's scenario with the companion at its rate (fewer lockstep round trips than
    50 Hz; the law is the same)."""
    data = yaml.safe_load((CONFIG / case.config).read_text())
    data.setdefault("companion", {}).update(loop_rate_hz=case.rate_hz,
                                            telemetry_rate_hz=case.rate_hz)  # fmt: skip
    path = tmp_path / case.config
    path.write_text(yaml.safe_dump(data))
    return path


def _start_stub(config: Path, url: str, truth: Path, duration_s: float,
                case: Case = CASES["copter-1"]) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "sitl_stub", "--config", str(config), "--profile", case.profile,
         "--connect", url, "--speedup", "1000", "--lockstep", "--truth-out", str(truth),
         "--initial-mode", case.start_mode, "--duration", f"{duration_s:g}"],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip


def _wait_until_ready(stub: subprocess.Popen[str], url: str) -> None:
    """Until the stub has made its serial port, or bound its UDP port."""
    if url.startswith("pty:"):
        assert stub.stdout is not None
        for line in stub.stdout:
            if "serial port" in line:
                return
        raise AssertionError(f"the stub ended ({stub.wait()}) before making its serial port")
    port = int(url.rpartition(":")[2])
    deadline = time.monotonic() + 30.0
    while time.monotonic() < deadline and stub.poll() is None:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            try:
                probe.bind(("127.0.0.1", port))
            except OSError:
                return  # taken: the stub holds it
        time.sleep(0.05)
    raise AssertionError(f"the stub never bound {url} ({stub.poll()})")


@dataclass
class Flown:
    outcome: EngagementOutcome
    events: EventLog
    truth: Path


def fly(name: str, tmp_path: Path, case: Case = CASES["copter-1"]) -> Flown:
    config = _scenario_file(tmp_path, case)
    scenario = load_scenario(config)
    duration_s = scenario.simulation.duration_s
    transport = _transport(name, tmp_path)
    truth = tmp_path / "truth.csv"
    stub: subprocess.Popen[str] | None = None
    if transport.stub_first:
        stub = _start_stub(config, transport.stub, truth, duration_s + 5.0, case)
        _wait_until_ready(stub, transport.stub)
    settings = companion_settings(scenario, connect=transport.companion, engage=True)
    events = EventLog(lambda e: print(e.line()))  # shown when a test fails
    listening = threading.Event()
    events.add_sink(lambda e: listening.set() if e.kind is EventKind.LISTENING else None)
    service = CompanionService(scenario, settings, events=events, telemetry=None, lockstep=True)
    result: list[EngagementOutcome] = []
    run: Callable[[], None] = lambda: result.append(service.run(max_time_s=duration_s))  # noqa: E731
    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    try:
        assert listening.wait(30.0), "the companion never opened its link"
        if stub is None:
            stub = _start_stub(config, transport.stub, truth, duration_s + 5.0, case)
        thread.join(timeout=_WALL_BUDGET_S)
    finally:
        service.stop()
        thread.join(timeout=10.0)
        if stub is not None:
            assert stop_or_dump(stub), STUCK
    assert result, "the companion did not finish"
    return Flown(result[0], events, truth)


@pytest.mark.parametrize("case", sorted(CASES))
@pytest.mark.parametrize("name", ["tcp", "tcpin", "udpin", "udpout", "serial"])
def test_each_target_intercepts_outside_every_zone_over(
    name: str, case: str, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, logger="ezcompanion.wire")
    flown = fly(name, tmp_path, CASES[case])
    scenario = load_scenario(CONFIG / CASES[case].config)
    intercepted, time_s, miss, clearance, accel = judge_truth(scenario, flown.truth)
    assert flown.outcome.intercepted and intercepted, (miss, flown.outcome)
    assert min(clearance) > 0.0, clearance
    assert accel <= 1.0
    # one vehicle, found once, never lost: the transport carried the whole engagement
    assert len(flown.events.of_kind(EventKind.VEHICLE_FOUND)) == 1
    assert not flown.events.of_kind(EventKind.LINK_LOST)
    print(f"{name} {case}: intercepted at {time_s:.2f} s, miss {miss:.3f} m, true clearance "
          f"{', '.join(f'{c:+.3f}' for c in clearance)} m")  # fmt: skip
    rows = guided_rows(flown.truth, "OFFBOARD" if CASES[case].profile == "px4" else "GUIDED")
    assert rows, "never guided"
    speeds = [float(r["speed_m_s"]) for r in rows[len(rows) // 2:]]
    if CASES[case].profile == "plane":
        assert min(speeds) == pytest.approx(23.4, rel=1e-3)  # the plane's own speed, not 22
        assert accel > 0.6  # the outer loop turned it as hard as the law asked (not 0.73x)
        return
    heights = [float(r["height_m"]) for r in rows]
    assert max(heights) - min(heights) < 0.5  # held, though PX4 drifts 0.1 m/s on vz = 0
    if CASES[case].profile == "px4":  # the vehicle really flew short of the commanded 1 m/s
        assert max(speeds) < 0.81
    if case != "copter-1":
        return
    assert 5.0 < time_s < 15.0  # the paper's 8.2 s, with ArduCopter's measured lag
    if name == "tcp":  # the companion's client was up before the stub's server, and waited
        notices = [r.getMessage() for r in caplog.records if "cannot connect" in r.getMessage()]
        assert notices and "Connection refused" in notices[0]


def guided_rows(truth: Path, mode: str) -> list[dict[str, str]]:
    """The truth's rows while the vehicle was in ``mode``."""
    with truth.open(encoding="utf-8") as f:
        return [row for row in csv.DictReader(f) if row["mode"] == mode]


def _heartbeat(stub_link: StubLink) -> bytes:
    return stub_link.pack(stub_link.mav.heartbeat_encode(2, 3, 0, 0, 4))


def _until(link: Link, done: Callable[[list[str]], bool], send: Callable[[], object] = bool,
           wall_s: float = 5.0) -> list[str]:
    """Wait as the service does, ``send`` each round, until ``done(types received)``."""
    got: list[str] = []
    deadline = time.monotonic() + wall_s
    while not done(got) and time.monotonic() < deadline:
        send()
        link.wait_readable(0.05)
        got += [m.get_type() for m in link.recv_messages()]
    return got


def test_a_serial_port_that_goes_away_is_opened_again_from_its_path(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, logger="ezcompanion.wire")
    tty = str(tmp_path / "ttyFC")
    vehicle = StubLink(f"pty:{tty}", system_id=1, component_id=1)  # the stub's own code
    link = Link(f"{tty},115200", system_id=245, component_id=191)
    try:
        got = _until(link, lambda got: "HEARTBEAT" in got,
                     lambda: vehicle.write(_heartbeat(vehicle)))  # fmt: skip
        assert "HEARTBEAT" in got
        assert link.send(link.mav.heartbeat_encode(18, 8, 0, 0, 0)) is True
        vehicle.wait_readable(2.0)
        assert [m.get_type() for m in vehicle.recv_messages()] == ["HEARTBEAT"]
        # the vehicle goes away (its program ended, the device with it): noticed, one line
        vehicle.close()
        _until(link, lambda _: not link.connected, wall_s=3.0)
        assert not link.connected and "went away" in (link.down_reason or "")
        assert link.send(link.mav.heartbeat_encode(18, 8, 0, 0, 0)) is False
        # ... and back behind the same path (a new /dev/pts/N): opened again within ~1 s
        vehicle = StubLink(f"pty:{tty}", system_id=1, component_id=1)
        _until(link, lambda _: link.connected, wall_s=5.0)
        assert link.connected and link.down_reason is None
        got = _until(link, lambda got: "HEARTBEAT" in got,
                     lambda: vehicle.write(_heartbeat(vehicle)))  # fmt: skip
        assert "HEARTBEAT" in got
        assert all(r.exc_info is None for r in caplog.records)
        assert any("open again after" in r.getMessage() for r in caplog.records)
    finally:
        link.close()
        vehicle.close()


def test_a_tcp_vehicle_that_restarts_is_reached_again_and_guided_again(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """ArduPilot SITL restarted under a companion on its TCP port: the connection closes, the
    companion says so, stops guiding (link lost), connects again within its retry period
    once the new vehicle listens, and guides it again: setpoints leave over the new
    connection. As the UDP test of link loss (test_service_loopback.py), the first vehicle
    dies at the engagement, still holding: one killed at speed comes back with a velocity the
    estimate gate refuses, which is the gate's business, not the link's. Vehicle clocks at
    5x, not lockstep (a vehicle that dies cannot answer a lockstep request), so the outcome
    of the engagement is not asserted: a loaded machine may make it miss."""
    caplog.set_level(logging.WARNING, logger="ezcompanion.wire")
    speedup = 5.0
    scenario = load_scenario(SCENARIO)
    port = free_port()
    settings = companion_settings(scenario, connect=f"tcp:127.0.0.1:{port}", engage=True,
                                  speedup=speedup, loop_rate_hz=20.0,
                                  telemetry_rate_hz=20.0)  # fmt: skip
    events = EventLog(lambda e: print(e.line()))
    kinds: list[EventKind] = []
    seen = threading.Condition()

    def note(event: object) -> None:
        with seen:
            kinds.append(event.kind)  # type: ignore[attr-defined]
            seen.notify_all()

    events.add_sink(note)

    def wait_for(kind: EventKind, count: int = 1) -> None:
        with seen:
            assert seen.wait_for(lambda: kinds.count(kind) >= count, timeout=30.0), kinds

    service = CompanionService(scenario, settings, events=events, telemetry=None)
    outcome: list[EngagementOutcome] = []
    thread = threading.Thread(
        target=lambda: outcome.append(service.run(max_time_s=60.0)), daemon=True
    )

    def vehicle(n: int) -> SitlStub:  # in this process: no interpreter to start twice
        config = stub_config(scenario, connect=f"tcpin:127.0.0.1:{port}", speedup=speedup,
                             profile="copter", initial_mode="GUIDED")  # fmt: skip
        return SitlStub(config, truth_out=tmp_path / f"truth{n}.csv").start()

    first = vehicle(1)
    second: SitlStub | None = None
    thread.start()
    try:
        wait_for(EventKind.ENGAGED)
        first.stop()  # the vehicle goes away, its socket closed
        wait_for(EventKind.LINK_LOST)
        assert not service.session.connected
        second = vehicle(2)
        wait_for(EventKind.LINK_RESTORED)
        wait_for(EventKind.ENGAGED, 2)
        resumed_at = service.setpoints_sent
        deadline = time.monotonic() + 30.0
        while service.setpoints_sent < resumed_at + 10 and time.monotonic() < deadline:
            time.sleep(0.02)  # setpoints leave again, over the new connection
        assert service.setpoints_sent >= resumed_at + 10, (resumed_at, service.setpoints_sent)
    finally:
        service.stop()
        thread.join(timeout=20.0)
        first.stop()
        if second is not None:
            second.stop()
            assert second.error is None
    assert outcome, "the companion did not finish"
    notices = [r.getMessage() for r in caplog.records if r.name == "ezcompanion.wire.streams"]
    url = f"tcp:127.0.0.1:{port}"
    assert any(n.startswith(f"{url}: the server closed the connection; ") or n.startswith(
        f"{url}: the server reset the connection") for n in notices), notices  # fmt: skip
    assert any(n.startswith(f"{url}: connected after ") for n in notices), notices
    assert all(r.exc_info is None for r in caplog.records)


@pytest.mark.parametrize(
    ("url", "reason"),
    [("pty:ttyFC", "absolute PATH"), ("pty:/no/such/dir/ttyFC", "absolute PATH"),
     ("tcp:127.0.0.1", "tcp:HOST:PORT")],
)  # fmt: skip
def test_a_bad_stub_endpoint_is_one_line_naming_the_flag(
    url: str, reason: str, capsys: pytest.CaptureFixture[str]
) -> None:
    from sitl_stub.cli import main as stub_main

    assert stub_main(["--config", str(SCENARIO), "--connect", url]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert "argument --connect" in line and reason in line and repr(url) in line, line


def test_a_free_port_is_drawn_outside_the_kernels_ephemeral_range() -> None:
    """A port chosen for a peer that binds it later is not one the kernel hands to unbound
    sockets meanwhile (a loopback stub once found its UDP port so taken)."""
    from ezcompanion.service import demo

    low, high = demo._ephemeral_ports()
    assert low <= high
    for kind in (socket.SOCK_STREAM, socket.SOCK_DGRAM):
        ports = [free_port(kind) for _ in range(20)]
        assert not [port for port in ports if low <= port <= high], (low, high, ports)
        with socket.socket(socket.AF_INET, kind) as sock:
            sock.bind(("127.0.0.1", ports[-1]))  # free when given
