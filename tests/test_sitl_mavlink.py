"""sitl_stub over real UDP on 127.0.0.1: heartbeat, telemetry, rates, acks, modes, signing."""

from __future__ import annotations

import math
import socket
from typing import Any

import pytest
from conftest_sitl import (
    Gcs,
    M,
    forger,
    frame,
    gcs_link,
    measured_rate_hz,
    running_stub,
    stamped_after,
    stamps_s,
    stranger_socket,
)

from ezcompanion import wire

KEY_HEX = "00112233445566778899aabbccddeeff00112233445566778899aabbccddeeff"


STREAMS = ("GLOBAL_POSITION_INT", "LOCAL_POSITION_NED", "ATTITUDE", "VFR_HUD")


@pytest.fixture
def gcs() -> Gcs:
    with gcs_link() as link:
        yield link  # type: ignore[misc]


@pytest.mark.parametrize(
    ("profile", "mav_type", "autopilot", "custom_mode"),
    [
        ("copter", M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA, 3),  # AUTO
        ("plane", M.MAV_TYPE_FIXED_WING, M.MAV_AUTOPILOT_ARDUPILOTMEGA, 10),  # AUTO
        ("px4", M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_PX4, (4 << 16) | (4 << 24)),  # MISSION
    ],
)
def test_heartbeat_identifies_the_profile_at_1_hz(
    gcs: Gcs, profile: str, mav_type: int, autopilot: int, custom_mode: int
) -> None:
    with running_stub(gcs, profile=profile, system_id=7, component_id=3, speedup=10.0):
        # 4.5 s simulated, by the stamps of a stream sent from the same socket
        got = gcs.collect_until(("HEARTBEAT", "ATTITUDE"), stamped_after("ATTITUDE", 4500))
    beats = [m for m in got if m.get_type() == "HEARTBEAT"]
    elapsed = got[-1].time_boot_ms / 1000.0
    assert all(b.get_srcSystem() == 7 and b.get_srcComponent() == 3 for b in beats)
    kinds = {(b.type, b.autopilot, b.custom_mode) for b in beats}
    assert kinds == {(mav_type, autopilot, custom_mode)}
    assert all(b.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED for b in beats)
    assert all(b.base_mode & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED for b in beats)
    # 1 Hz of simulated time: about 4-5 beats in the window (plus the one waited for)
    assert 3 <= len(beats) <= math.ceil(elapsed) + 1


def test_default_streams_and_consistent_units(gcs: Gcs) -> None:
    with running_stub(gcs, speedup=10.0):
        msgs = gcs.collect_until(STREAMS, stamped_after("GLOBAL_POSITION_INT", 3000))
    by = {k: [m for m in msgs if m.get_type() == k] for k in STREAMS}
    assert measured_rate_hz(by["GLOBAL_POSITION_INT"]) == pytest.approx(10.0, rel=0.02)
    assert measured_rate_hz(by["ATTITUDE"]) == pytest.approx(10.0, rel=0.02)
    # VFR_HUD carries no time stamp: compare its count with the 10 Hz stream's
    assert len(by["VFR_HUD"]) / len(by["GLOBAL_POSITION_INT"]) == pytest.approx(0.4, abs=0.1)
    local = {m.time_boot_ms: m for m in by["LOCAL_POSITION_NED"]}
    att = {m.time_boot_ms: m for m in by["ATTITUDE"]}
    checked = 0
    for g in by["GLOBAL_POSITION_INT"]:
        if g.time_boot_ms not in local or g.time_boot_ms not in att:
            continue
        lp, a = local[g.time_boot_ms], att[g.time_boot_ms]
        # the copter is an ArduPilot: its global position is its local one on a flat earth
        north, east, down = wire.geodetic_to_local(
            wire.Projection.ARDUPILOT, g.lat * 1e-7, g.lon * 1e-7, g.alt / 1000.0,
            origin_lat_deg=-35.363261, origin_lon_deg=149.165230, origin_alt_m=584.0)
        assert north == pytest.approx(lp.x, abs=0.02)
        assert east == pytest.approx(lp.y, abs=0.02)
        assert down == pytest.approx(lp.z, abs=0.01) and lp.z == pytest.approx(-20.0)
        assert g.relative_alt == 20000
        assert g.vx / 100.0 == pytest.approx(lp.vx, abs=0.006)
        assert g.vy / 100.0 == pytest.approx(lp.vy, abs=0.006)
        assert math.hypot(lp.vx, lp.vy) == pytest.approx(1.0, abs=1e-6)  # cruise speed
        assert g.hdg == round(math.degrees(a.yaw) * 100) % 36000
        assert math.atan2(lp.vy, lp.vx) == pytest.approx(a.yaw, abs=1e-6)  # no wind
        checked += 1
    assert checked >= 5
    hud = by["VFR_HUD"][-1]
    assert hud.airspeed == pytest.approx(1.0) and hud.groundspeed == pytest.approx(1.0)
    assert 0 <= hud.heading < 360 and hud.alt == pytest.approx(604.0)


def attitudes_over(gcs: Gcs, span_s: float) -> list[Any]:
    """The ATTITUDEs of ``span_s`` of the stub's time, from the next one on, by their stamps
    (a window of wall time, read by a test descheduled in it, held fewer, and their rate's
    error from a stamp's jitter grew with it)."""
    first = gcs.recv("ATTITUDE", 3.0)
    assert first is not None
    last_ms = first.time_boot_ms + span_s * 1000.0
    return [first, *gcs.collect_until("ATTITUDE", stamped_after("ATTITUDE", last_ms))]


@pytest.mark.parametrize(("profile", "limit_hz"), [("copter", 200.0), ("plane", 40.0)])
def test_set_message_interval_limits(gcs: Gcs, profile: str, limit_hz: float) -> None:
    attitude = M.MAVLINK_MSG_ID_ATTITUDE
    # a stream goes out once a physics step at most, stamped with its state: 200 Hz needs
    # 5 ms steps (the default 10 ms gives 100 Hz)
    with running_stub(gcs, profile=profile, speedup=2.0, record_truth=False,
                      physics_dt_s=1.0 / limit_hz):  # fmt: skip
        ack = gcs.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, attitude, 1e6 / 25.0)
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
        gcs.drain()
        assert measured_rate_hz(attitudes_over(gcs, 0.8)) == pytest.approx(25.0, rel=0.03)
        # faster than the autopilot streams: DENIED, and the previous rate stays
        ack = gcs.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, attitude, 1e6 / (limit_hz * 1.25))
        assert ack is not None and ack.result == M.MAV_RESULT_DENIED
        gcs.drain()
        assert measured_rate_hz(attitudes_over(gcs, 0.8)) == pytest.approx(25.0, rel=0.03)
        # exactly the limit is allowed
        ack = gcs.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, attitude, 1e6 / limit_hz)
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
        gcs.drain()
        assert measured_rate_hz(attitudes_over(gcs, 0.6)) == pytest.approx(limit_hz, rel=0.03)
        gcs.mav.command_long_send(1, 1, M.MAV_CMD_GET_MESSAGE_INTERVAL, 0, attitude,
                                  0, 0, 0, 0, 0, 0)
        interval = gcs.recv("MESSAGE_INTERVAL", 2.0)
        assert interval is not None and interval.interval_us == round(1e6 / limit_hz)
        # -1 stops the stream, 0 restores the default (10 Hz)
        ack = gcs.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, attitude, -1)
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
        gcs.drain()
        assert gcs.collect("ATTITUDE", 0.4) == []
        ack = gcs.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, attitude, 0)
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
        gcs.drain()
        assert measured_rate_hz(attitudes_over(gcs, 1.2)) == pytest.approx(10.0, rel=0.05)


def test_request_data_stream_overrides_message_interval(gcs: Gcs) -> None:
    with running_stub(gcs, speedup=5.0, record_truth=False):
        ack = gcs.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE, 1e6 / 50.0)
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
        gcs.mav.request_data_stream_send(1, 1, M.MAV_DATA_STREAM_EXTRA1, 4, 1)
        gcs.barrier()  # the request handled (a loaded machine may take a while)
        assert measured_rate_hz(attitudes_over(gcs, 4.0)) == pytest.approx(4.0, rel=0.05)
        gcs.mav.request_data_stream_send(1, 1, M.MAV_DATA_STREAM_POSITION, 0, 0)  # stop
        gcs.barrier()
        kinds = {m.get_type() for m in gcs.collect(
            ("GLOBAL_POSITION_INT", "LOCAL_POSITION_NED", "ATTITUDE"), 0.5)}
        assert kinds == {"ATTITUDE"}


def test_local_position_only_once_origin_exists(gcs: Gcs) -> None:
    with running_stub(gcs, speedup=10.0, local_origin_after_s=2.0, record_truth=False):
        msgs = gcs.collect_until(("LOCAL_POSITION_NED", "GLOBAL_POSITION_INT"),
                                 stamped_after("GLOBAL_POSITION_INT", 2500))
    local = stamps_s([m for m in msgs if m.get_type() == "LOCAL_POSITION_NED"])
    global_ = stamps_s([m for m in msgs if m.get_type() == "GLOBAL_POSITION_INT"])
    assert local and min(local) >= 2.0
    assert min(global_) < 1.0


def test_every_command_is_acknowledged(gcs: Gcs) -> None:
    with running_stub(gcs, speedup=5.0, record_truth=False) as stub:
        ack = gcs.command(M.MAV_CMD_DO_SET_SERVO, 9, 1500)  # not implemented
        assert ack is not None and ack.result == M.MAV_RESULT_UNSUPPORTED
        ack = gcs.command_int(M.MAV_CMD_DO_CHANGE_SPEED, 0, 5)
        assert ack is not None and ack.result == M.MAV_RESULT_UNSUPPORTED
        ack = gcs.command(M.MAV_CMD_GUIDED_CHANGE_HEADING, 0, 90, 1)  # a plane command
        assert ack is not None and ack.result == M.MAV_RESULT_UNSUPPORTED
        ack = gcs.set_mode(99)  # no such mode
        assert ack is not None and ack.result == M.MAV_RESULT_FAILED
        ack = gcs.set_mode(4)  # GUIDED
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
        assert ack.target_system == 255 and ack.target_component == 190
        beat = gcs.recv("HEARTBEAT", 2.0, lambda m: m.custom_mode == 4)
        assert beat is not None
        ack = gcs.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 0)
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
        beat = gcs.recv("HEARTBEAT", 2.0, lambda m: not m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
        assert beat is not None and beat.system_status == M.MAV_STATE_STANDBY
        ack = gcs.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
        assert gcs.recv("HEARTBEAT", 2.0, lambda m: m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
        # SET_MODE (the old message): ArduPilot acks it with command = 11
        gcs.mav.set_mode_send(1, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 5)  # LOITER
        ack = gcs.recv("COMMAND_ACK", 2.0, lambda m: m.command == M.MAVLINK_MSG_ID_SET_MODE)
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
        assert stub.mode_name == "LOITER"
        # commands for another system are not ours to answer
        assert gcs.command(M.MAV_CMD_DO_SET_SERVO, 9, 1500, target_system=42, timeout_s=0.3) is None


def test_timesync_answered_with_simulated_clock(gcs: Gcs) -> None:
    with running_stub(gcs, speedup=5.0, record_truth=False) as stub:
        stub.wait_sim_time(2.0)
        gcs.mav.timesync_send(0, 123456789)
        reply = gcs.recv("TIMESYNC", 2.0, lambda m: m.ts1 == 123456789)
        now = stub.sim_time_s
    assert reply is not None
    assert 2.0 <= reply.tc1 / 1e9 <= now


def test_signing_refuses_unsigned_frames(gcs: Gcs) -> None:
    key = bytes.fromhex(KEY_HEX)
    with running_stub(gcs, speedup=5.0, record_truth=False, signing_key_hex=KEY_HEX) as stub:
        beat = gcs.recv("HEARTBEAT", 2.0)
        assert beat is not None and beat._signed is False  # we hold no key: unchecked
        gcs.mav.command_long_send(1, 1, M.MAV_CMD_DO_SET_MODE, 0, 1, 4, 0, 0, 0, 0, 0)
        assert gcs.recv("COMMAND_ACK", 0.5) is None  # unsigned: refused, no answer
        gcs.conn.setup_signing(b"\x01" * 32, sign_outgoing=True)  # wrong key
        gcs.mav.command_long_send(1, 1, M.MAV_CMD_DO_SET_MODE, 0, 1, 4, 0, 0, 0, 0, 0)
        gcs.conn.disable_signing()
        assert gcs.recv("COMMAND_ACK", 0.5) is None
        assert stub.mode_name == "AUTO"
        gcs.conn.setup_signing(key, sign_outgoing=True)
        ack = gcs.set_mode(4)
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED and ack._signed
        assert stub.mode_name == "GUIDED"


def test_signing_off_accepts_signed_and_unsigned(gcs: Gcs) -> None:
    with running_stub(gcs, speedup=5.0, record_truth=False) as stub:
        assert gcs.set_mode(4) is not None
        gcs.conn.setup_signing(bytes.fromhex(KEY_HEX), sign_outgoing=True,
                               allow_unsigned_callback=lambda _mav, _msg_id: True)
        ack = gcs.set_mode(5)
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED and not ack._signed
        assert stub.mode_name == "LOITER"


@pytest.mark.parametrize(
    ("profile", "loiter", "peer_mode", "hears_strangers"),
    [
        ("copter", (5, 0), ((4, 0), "GUIDED"), False),
        ("plane", (12, 0), ((15, 0), "GUIDED"), False),
        ("px4", (4, 3), ((3, 0), "POSCTL"), True),
    ],
)
def test_a_stub_sending_udpout_hears_whom_its_autopilot_hears(
    gcs: Gcs, profile: str, loiter: tuple[int, int], peer_mode: tuple[tuple[int, int], str],
    hears_strangers: bool,
) -> None:
    """ArduPilot SITL's ``udpclient:`` connects its socket (AP_HAL_SITL/UARTDriver.cpp), so
    only its peer's datagrams reach it; PX4's receiver parses whatever reaches its port. A
    stranger on 127.0.0.1 and one on the peer's own port at another loopback address (a
    Linux loopback: 127/8) ask the stub for LOITER; then the peer asks for another mode."""
    with running_stub(gcs, profile=profile, speedup=5.0, record_truth=False) as stub:
        address = stub.local_address
        assert address is not None
        before = stub.mode_name
        mav = forger(255, 190)  # as the ground station
        ask = M.MAVLink_command_long_message(1, 1, M.MAV_CMD_DO_SET_MODE, 0,
                                             M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, *loiter,
                                             0, 0, 0, 0)  # fmt: skip
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as elsewhere, \
                stranger_socket() as stranger:
            elsewhere.bind(("127.0.0.3", gcs.port))  # the peer's port, another address
            stranger.sendto(frame(mav, ask), address)
            elsewhere.sendto(frame(mav, ask), address)
        gcs.barrier()  # the stub reads one socket in order: both were read before this
        stats = stub.link_stats
        assert stats is not None
        if hears_strangers:
            assert stub.mode_name == "LOITER" and stats.foreign_datagrams == 0
        else:  # (at least: another test's vehicle may reach an ephemeral port too)
            assert stub.mode_name == before and stats.foreign_datagrams >= 2
        (custom, sub), name = peer_mode
        ack = gcs.set_mode(custom, sub)
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
        assert stub.mode_name == name


def test_stub_listening_with_udpin() -> None:
    from conftest_sitl import make_config, udp_client

    from ezcompanion.service.demo import free_udp_port
    from sitl_stub import SitlStub

    config = make_config(0, connect=f"udpin:127.0.0.1:{free_udp_port()}", speedup=5.0)
    with SitlStub(config) as stub:
        address = stub.local_address
        assert address is not None
        gcs_conn = udp_client(f"udpout:127.0.0.1:{address[1]}")
        try:
            gcs_conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            beat = gcs_conn.recv_match(type="HEARTBEAT", blocking=True, timeout=3.0)
            assert beat is not None and beat.type == M.MAV_TYPE_QUADROTOR
        finally:
            gcs_conn.close()
