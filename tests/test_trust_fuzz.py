"""Fuzzed and spoofed frames during a real engagement over UDP (issue 10's mix).

A stranger on 127.0.0.1 sends forged frames of every kind the attacks above used
(heartbeats claiming the vehicle or another autopilot, MAVLink 1, positions at the target,
origins, ACKs, STATUSTEXT, frames signed with a wrong key) and garbage; a relay between the
vehicle and the companion adds garbage and corrupted frames from the vehicle's own address.
Seeded, bounded: up to ``EZCOMPANION_FUZZ_FRAMES`` frames (default 2000), at most one every
0.5 ms of wall time, while the engagement lasts (a flood, not a test of starving the
companion's CPU, which on a shared machine would only make it late).
"""

from __future__ import annotations

import os
import random
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from conftest_sitl import M, Relay, forger, frame, stranger_socket
from test_service_loopback import fly
from test_trust_link import LIGHT, SCENARIO, assert_honest, wait_for

from ezcompanion.config import load_scenario
from ezcompanion.service.demo import free_udp_port
from ezcompanion.service.events import EventKind

FRAMES = int(os.environ.get("EZCOMPANION_FUZZ_FRAMES", "2000"))
TARGET = load_scenario(SCENARIO).target
FORGERS = {(s, c): forger(s, c) for s in (1, 2, 42) for c in (0, 1, 191)}


def forged(rng: random.Random, boot_ms: int) -> bytes:
    """One forged frame of a random kind."""
    target = TARGET
    signed = rng.random() < 0.1
    key = (rng.choice([1, 1, 1, 2, 42]), rng.choice([1, 1, 0, 191]))
    mav = forger(*key) if signed else FORGERS[key]
    if signed:  # signed, with a key that is not the vehicle's
        mav.signing.secret_key = rng.randbytes(32)
        mav.signing.sign_outgoing = True
        mav.signing.timestamp = rng.choice([2**48 - 1, 1, int(time.time() * 1e5)])
    kind = rng.randrange(7)
    if kind == 0:
        msg = M.MAVLink_heartbeat_message(
            rng.choice([M.MAV_TYPE_QUADROTOR, M.MAV_TYPE_FIXED_WING, 200]),
            rng.choice([M.MAV_AUTOPILOT_ARDUPILOTMEGA, M.MAV_AUTOPILOT_PX4]),
            rng.randrange(256), rng.choice([0, 4, 5, 2**32 - 1]), M.MAV_STATE_ACTIVE, 3)
    elif kind == 1:
        msg = M.MAVLink_local_position_ned_message(
            max(0, boot_ms + rng.randrange(-50, 50)), target.north_m + rng.uniform(-2, 2),
            target.east_m + rng.uniform(-2, 2), -20.0, rng.uniform(-2, 2), rng.uniform(-2, 2),
            0.0)
    elif kind == 2:
        msg = M.MAVLink_global_position_int_message(
            boot_ms, rng.randrange(-900_000_000, 900_000_000),
            rng.randrange(-1_800_000_000, 1_800_000_000), 0, 0, 0, 0, 0, 0)
    elif kind == 3:
        msg = M.MAVLink_gps_global_origin_message(
            rng.randrange(-900_000_000, 900_000_000), rng.randrange(-1_800_000_000, 1_800_000_000),
            0, 0)
    elif kind == 4:
        msg = M.MAVLink_command_ack_message(rng.randrange(65536), rng.randrange(10), 0, 0,
                                            rng.choice([0, 1, 255]), rng.choice([0, 191, 190]))
    elif kind == 5:
        msg = M.MAVLink_statustext_message(M.MAV_SEVERITY_CRITICAL, b"forged: land now")
    else:
        msg = M.MAVLink_attitude_message(boot_ms, 0.0, 0.0, rng.uniform(-4, 4), 0.0, 0.0, 0.0)
    data = frame(mav, msg, mavlink1=rng.random() < 0.2)
    if rng.random() < 0.1:  # a corrupted byte
        i = rng.randrange(len(data))
        data = data[:i] + bytes([data[i] ^ 0xFF]) + data[i + 1:]
    return data


def garbage(rng: random.Random) -> bytes:
    head = rng.choice([b"", b"\xfd", b"\xfe", b"\xfd\xff\x01\x00"])
    return head + rng.randbytes(rng.randrange(1, 300))


@dataclass
class Fuzzed:
    """One fuzzed engagement: what was sent, what the stranger got back, and the flight."""

    flight: Any
    sent: dict[str, int]
    to_stranger: list[str]  # message types the stranger received

    def violations(self) -> list[str]:
        """Everything that went wrong, in words (empty: nothing forged steered anything)."""
        out: list[str] = []
        flight = self.flight
        if flight.outcome is None:
            return ["the service did not run to its end"]
        if "SET_POSITION_TARGET_LOCAL_NED" in self.to_stranger:
            out.append("a setpoint went to the stranger")
        reasons = {e.data["reason"] for e in flight.events.of_kind(EventKind.FAILSAFE)}
        if reasons & {"gate", "disagree", "origin", "spoof"}:
            out.append(f"a trust failsafe: {sorted(reasons)}")
        if [e for e in flight.events.of_kind(EventKind.STATUSTEXT) if "forged" in e.message]:
            out.append("a forged STATUSTEXT was reported")
        if flight.events.of_kind(EventKind.COMMAND_ACK):
            out.append("a forged COMMAND_ACK was taken")
        telemetry = flight.service.vehicle_telemetry
        if telemetry is None or sum(telemetry.refused.values()) >= 10:
            out.append("the vehicle's own frames were refused")
        return out


def fuzz_engagement(where: Path, rng: random.Random, frames: int) -> Fuzzed:
    """Fly paper scenario 1 over real UDP while up to ``frames`` fuzzed and spoofed frames
    arrive from a stranger and through a relay on the vehicle's own address."""
    port = free_udp_port()
    relay = Relay(port)
    stranger = stranger_socket()
    to_stranger: list[bytes] = []
    sent = {"stranger": 0, "relay": 0}

    def attack(service: Any, *_: Any) -> None:
        assert wait_for(service, EventKind.ENGAGED)
        time.sleep(0.4)  # past the lock's 1.5 s (vehicle time) of listening for others
        boot_ms = 0
        while sent["stranger"] + sent["relay"] < frames and service.phase.value != "done":
            boot_ms += 20
            if rng.random() < 0.8:
                stranger.sendto(forged(rng, boot_ms), ("127.0.0.1", port))
                sent["stranger"] += 1
            else:
                relay.inject(garbage(rng))
                sent["relay"] += 1
            time.sleep(0.0005)
            try:
                while True:
                    to_stranger.append(stranger.recv(65535))
            except OSError:
                pass

    try:
        # the vehicle's id configured, as a hardened companion would be: the stranger's 1/1
        # frames are refused, its other autopilots ignored
        flight = fly(SCENARIO, where, port=port, stub_port=relay.vehicle_port,
                     during=attack, target_system=1, target_component=1, max_time_s=60.0,
                     **LIGHT)
    finally:
        relay.close()
        stranger.close()
    parser = M.MAVLink(None)
    parser.robust_parsing = True
    got = [m.get_type() for data in to_stranger for m in parser.parse_buffer(data) or []]
    return Fuzzed(flight, sent, got)


def test_fuzzed_and_spoofed_frames_steer_nothing(tmp_path: Path) -> None:
    fuzzed = fuzz_engagement(tmp_path, random.Random(2026), FRAMES)
    print("FUZZ sent", fuzzed.sent, "received by the stranger", len(fuzzed.to_stranger))
    assert fuzzed.violations() == []
    assert sum(fuzzed.sent.values()) >= min(FRAMES, 300)  # during one engagement
    _, clearance = assert_honest(fuzzed.flight)
    assert clearance > 0.0
