"""The autopilot's own messages over real UDP: chunked STATUSTEXT, EXTENDED_SYS_STATE,
AUTOPILOT_VERSION (what MAVSDK needs for ``in_air`` and ``info``) and GPS_GLOBAL_ORIGIN,
sent once when the origin is set and on request, as ArduPilot and PX4 send them.
"""

from __future__ import annotations

import pytest
from conftest_sitl import Gcs, M, gcs_link, running_stub


@pytest.fixture
def gcs() -> Gcs:
    with gcs_link() as link:
        yield link  # type: ignore[misc]


def test_long_statustext_arrives_in_chunks_that_join(gcs: Gcs) -> None:
    # PX4's failsafe text is longer than one frame's 50 characters
    with running_stub(gcs, profile="px4", speedup=20.0, record_truth=False) as stub:
        gcs.velocity(0.0, 1.0)
        ack = gcs.set_mode(6)
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
        chunks = gcs.collect("STATUSTEXT", 0.3 + 3.0 / 20.0)
        stub.wait_sim_time(stub.sim_time_s + 0.5)
    failsafe = [m for m in chunks if m.id != 0]
    assert len(failsafe) >= 2, [m.text for m in chunks]
    ids = {m.id for m in failsafe}
    assert len(ids) == 1 and 0 not in ids
    assert [m.chunk_seq for m in failsafe] == list(range(len(failsafe)))
    assert all(len(m.text) == 50 for m in failsafe[:-1]) and len(failsafe[-1].text) < 50
    text = "".join(m.text for m in failsafe)
    assert text.startswith("Failsafe activated") and text.endswith("descending (no RC)")
    assert all(len(m.text) <= 50 and m.id == 0 for m in chunks if m not in failsafe)


@pytest.mark.parametrize(("profile", "version"), [("copter", (4, 7, 0)), ("px4", (1, 16, 0))])
def test_autopilot_version_and_landed_state(gcs: Gcs, profile: str,
                                            version: tuple[int, int, int]) -> None:
    with running_stub(gcs, profile=profile, speedup=10.0, record_truth=False):
        state = gcs.recv("EXTENDED_SYS_STATE", 3.0)
        assert state is not None and state.landed_state == M.MAV_LANDED_STATE_IN_AIR
        ack = gcs.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
        info = gcs.recv("AUTOPILOT_VERSION", 3.0)
        gcs.drain()
        ack = gcs.command(M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, 1)
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
        again = gcs.recv("AUTOPILOT_VERSION", 3.0)
        assert gcs.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 0).result == M.MAV_RESULT_ACCEPTED
        landed = gcs.recv("EXTENDED_SYS_STATE", 3.0,
                          lambda m: m.landed_state == M.MAV_LANDED_STATE_ON_GROUND)
    assert info is not None and again is not None
    v = info.flight_sw_version
    assert (v >> 24, (v >> 16) & 0xFF, (v >> 8) & 0xFF) == version
    assert info.capabilities & M.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    assert info.capabilities & M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
    assert landed is not None


@pytest.mark.parametrize("profile", ["copter", "px4"])
def test_gps_global_origin_once_when_set_and_on_request(gcs: Gcs, profile: str) -> None:
    with running_stub(gcs, profile=profile, speedup=10.0, record_truth=False,
                      local_origin_after_s=2.0) as stub:
        early = gcs.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN)
        assert early is not None and early.result == M.MAV_RESULT_TEMPORARILY_REJECTED
        stub.wait_sim_time(1.0)
        sent = gcs.collect("GPS_GLOBAL_ORIGIN", 0.6)  # sim 1 s .. ~7 s
        assert stub.sim_time_s > 4.0
        ack = gcs.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN)
        answered = gcs.recv("GPS_GLOBAL_ORIGIN", 2.0)
    assert len(sent) == 1, sent
    origin = stub.config.origin
    assert sent[0].latitude == round(origin.lat_deg * 1e7)
    assert sent[0].longitude == round(origin.lon_deg * 1e7)
    assert sent[0].altitude == round(origin.alt_m * 1000)
    assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
    assert answered is not None and answered.latitude == sent[0].latitude



@pytest.mark.parametrize(
    ("profile", "mode", "custom_mode"),
    [("copter", (5, 0), 5), ("plane", (12, 0), 12), ("px4", (4, 3), 0x03040000)],
)
def test_a_new_mode_is_said_in_a_heartbeat_at_once_by_ardupilot_and_on_request(
    gcs: Gcs, profile: str, mode: tuple[int, int], custom_mode: int
) -> None:
    """ArduPilot sends a heartbeat as it changes mode (ArduCopter 4.5.1 SITL: 6 ms after the
    mode's ack; Copter::set_mode, ArduPlane's set_mode); PX4 main SITL says it at its next
    1 Hz heartbeat (0.98 s after the ack). Both answer a heartbeat asked for
    (MAV_CMD_REQUEST_MESSAGE 0) at once."""
    with running_stub(gcs, profile=profile, speedup=1.0, record_truth=False):
        gcs.drain()
        ack = gcs.set_mode(*mode)
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
        if profile != "px4":  # the frame after the ack: the heartbeat with the new mode
            after = gcs.conn.recv_match(blocking=True, timeout=3.0)
            assert after is not None and after.get_type() == "HEARTBEAT"
            assert after.custom_mode == custom_mode
        asked = gcs.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_HEARTBEAT)
        assert asked is not None and asked.result == M.MAV_RESULT_ACCEPTED
        assert gcs.recv("HEARTBEAT", 0.3, lambda m: m.custom_mode == custom_mode) is not None
