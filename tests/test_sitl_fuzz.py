"""Hostile input never crashes the stub and never moves the vehicle.

The copter is put in GUIDED, where it holds position until it gets a valid setpoint; then it
is sent random datagrams, mutated valid frames (flipped bytes, wrong lengths) and
well-formed frames with NaN, infinite or absurd fields. It must stay exactly where it was,
keep its heartbeat, answer every command addressed to it, and raise nothing.
"""

from __future__ import annotations

import math
import random

import pytest
from conftest_sitl import Gcs, M, gcs_link, running_stub

from ezcompanion import wire
from sitl_stub.config import StreamRates

_BAD_FLOATS = (math.nan, math.inf, -math.inf, 1e30, -1e30, 3.4e38)
_IMPLEMENTED = {176, 400, 510, 511, 512, 43002}


@pytest.fixture
def gcs() -> Gcs:
    with gcs_link() as link:
        yield link  # type: ignore[misc]


def _hostile_setpoints(mav: object, rng: random.Random) -> list[object]:
    m = mav  # pymavlink encoder
    out: list[object] = []
    for _ in range(150):
        bad = rng.choice(_BAD_FLOATS)
        frame = rng.choice((M.MAV_FRAME_LOCAL_NED, M.MAV_FRAME_BODY_NED, 0, 7, 9, 200))
        mask = rng.choice((0x0DC7, 0x05C7, 0, 0xFFFF, 0x0FF8, rng.randrange(0, 0x10000)))
        valid_shape = frame in (1, 8) and mask in (0x0DC7, 0x05C7)
        vel = [bad, rng.uniform(-5, 5)] if valid_shape else [rng.uniform(-5, 5), bad]
        rng.shuffle(vel)
        out.append(m.set_position_target_local_ned_encode(  # type: ignore[attr-defined]
            0, 1, 1, frame, mask, bad, 0, 0, vel[0], vel[1], bad, bad, 0, 0, bad,
            bad if mask == 0x05C7 else 0.0))
        q = rng.choice(([bad, 0, 0, 0], [0.0, 0.0, 0.0, 0.0], [5.0, 5.0, 5.0, 5.0],
                        wire.quaternion_from_euler(math.radians(170), 0, 0)))
        out.append(m.set_attitude_target_encode(  # type: ignore[attr-defined]
            0, 1, 1, rng.choice((0, 198, 7, 0xFF)), q, bad, bad, bad, bad))
    return out


def _hostile_commands(mav: object, rng: random.Random) -> list[object]:
    out: list[object] = []
    for _ in range(60):
        command = rng.choice(sorted(_IMPLEMENTED))
        params = [rng.choice(_BAD_FLOATS) for _ in range(7)]
        if rng.random() < 0.5:
            out.append(mav.command_long_encode(1, 1, command, 0, *params))  # type: ignore[attr-defined]
        else:
            out.append(mav.command_int_encode(  # type: ignore[attr-defined]
                1, 1, 0, command, 0, 0, *params[:4], rng.randrange(-2**31, 2**31),
                rng.randrange(-2**31, 2**31), params[6]))
    for _ in range(40):  # unknown commands with random parameters
        command = rng.randrange(0, 65536)
        while command in _IMPLEMENTED:
            command = rng.randrange(0, 65536)
        out.append(mav.command_long_encode(  # type: ignore[attr-defined]
            1, 1, command, rng.randrange(256), *[rng.uniform(-1e6, 1e6) for _ in range(7)]))
    return out


def _mutate(frame: bytes, rng: random.Random) -> bytes:
    data = bytearray(frame)
    kind = rng.randrange(4)
    if kind == 0:  # flip bytes
        for _ in range(rng.randint(1, 4)):
            data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
    elif kind == 1:  # truncate
        data = data[: rng.randrange(1, len(data))]
    elif kind == 2:  # wrong declared length
        data[1] = rng.randrange(256)
    else:  # trailing garbage
        data += rng.randbytes(rng.randint(1, 40))
    return bytes(data)


def test_hostile_input_never_moves_the_vehicle(gcs: Gcs) -> None:
    rng = random.Random(20240531)
    # 2x and the telemetry at 2 Hz: what is tested is the commands, and a stream at 10x
    # fills the test's socket buffer whenever a loaded machine leaves it unread for a moment
    quiet = StreamRates(global_position_int_hz=2.0, local_position_ned_hz=2.0,
                        attitude_hz=2.0, vfr_hud_hz=0.0)
    with running_stub(gcs, speedup=2.0, streams=quiet) as stub:
        ack = gcs.set_mode(4)
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
        stub.wait_sim_time(stub.sim_time_s + 4.0)  # braked to a hover (3.7 s from 1 m/s)
        held = stub.state
        assert held.speed_m_s == 0.0
        encoder = M.MAVLink(None, 255, 190)
        setpoints = _hostile_setpoints(encoder, rng)
        commands = _hostile_commands(encoder, rng)
        valid = [bytes(msg.pack(encoder)) for msg in setpoints]  # type: ignore[attr-defined]
        for k in range(600):
            choice = k % 3
            if choice == 0:
                gcs.conn.write(rng.randbytes(rng.randint(1, 300)))
            elif choice == 1:
                gcs.conn.write(_mutate(rng.choice(valid), rng))
            else:
                gcs.conn.write(valid[k % len(valid)])
        gcs.drain()
        # The burst may have filled the stub's socket buffer, where the kernel drops what
        # does not fit (UDP). Wait until a harmless command is answered: the backlog is read.
        probe = encoder.command_long_encode(  # type: ignore[attr-defined]
            1, 1, M.MAV_CMD_GET_MESSAGE_INTERVAL, 0, M.MAVLINK_MSG_ID_ATTITUDE, 0, 0, 0, 0, 0, 0)
        for _ in range(40):
            gcs.conn.write(bytes(probe.pack(encoder)))
            if gcs.recv("COMMAND_ACK", 0.5, where=lambda m: m.command == probe.command):
                break
        gcs.drain()
        unanswered = []
        for msg in commands:
            wanted = msg.command  # type: ignore[attr-defined]
            # Over UDP a datagram can be lost when a loaded machine leaves a socket unread
            # (issue 12: 99 of 100 ACKs): a command is sent again until answered, three times
            # at most. A command the stub ignores is ignored every time, so this still fails.
            for _attempt in range(3):
                gcs.conn.write(bytes(msg.pack(encoder)))  # type: ignore[attr-defined]
                if gcs.recv("COMMAND_ACK", 3.0, where=lambda m, c=wanted: m.command == c):
                    break
            else:
                unanswered.append(wanted)
        stub.wait_sim_time(stub.sim_time_s + 1.0)
        assert unanswered == []  # every command answered, none ignored
        assert gcs.recv("HEARTBEAT", 2.0) is not None
        now = stub.state
        assert stub.mode_name == "GUIDED" and stub.autopilot is not None and stub.autopilot.armed
        assert (now.north_m, now.east_m, now.speed_m_s) == (held.north_m, held.east_m, 0.0)
        assert all(s.speed_m_s == 0.0 for s in stub.history if s.t_s >= held.t_s)
        assert stub._link is not None and stub._link.stats.bad_frames > 100
        # and it still flies a valid setpoint afterwards
        gcs.velocity(1.0, 0.0)
        stub.wait_sim_time(stub.sim_time_s + 1.5)
        assert stub.state.speed_m_s > 0.5
