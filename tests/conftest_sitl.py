"""Helpers shared by the sitl_stub tests: a plain-pymavlink ground station on 127.0.0.1 and
a stub built from the paper's first scenario.

The ground station binds ``udpin:127.0.0.1:0`` (an ephemeral port) and the stub sends to it
with ``udpout``, so tests never collide on ports and nothing leaves the loopback interface.
"""

from __future__ import annotations

import math
import select
import socket
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from pymavlink import mavutil

import ezcompanion.wire  # noqa: F401  (sets MAVLink 2 before pymavlink loads)
from ezcompanion.config import load_scenario
from sitl_stub import SitlStub, StubConfig, stub_config

SCENARIO = Path(__file__).resolve().parents[1] / "config" / "paper_scenario1.yaml"
M = mavutil.mavlink
# the wall time an answer (an ACK, the first heartbeat) may take: it returns as soon as the
# answer is in, so it is generous for a loaded machine (was 3 s: issue 12)
ANSWER_WAIT_S = 10.0

Msg = Any


def udp_client(endpoint: str, *, system_id: int = 255, component_id: int = 190) -> Any:
    """A plain pymavlink ``udpout:`` connection that hears only the address it sends to:
    its socket is connected, so the kernel drops every other sender's datagram (under
    the full suite another test's vehicle, still sending to a closed socket's port, reached
    a new socket given that port). Linux: pymavlink sends with sendto, which a connected
    socket takes there (BSD's refuse it)."""
    conn: Any = mavutil.mavlink_connection(endpoint, source_system=system_id,
                                           source_component=component_id)  # fmt: skip
    conn.port.connect(conn.destination_addr)
    return conn


class Gcs:
    """A ground station speaking plain pymavlink over UDP on 127.0.0.1."""

    def __init__(self, *, system_id: int = 255, component_id: int = 190) -> None:
        self.conn: Any = mavutil.mavlink_connection(
            "udpin:127.0.0.1:0", source_system=system_id, source_component=component_id)
        self.port: int = self.conn.port.getsockname()[1]
        # a fast stub outruns a test that is not reading: keep the kernel from dropping
        self.conn.port.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)

    def close(self) -> None:
        self.conn.close()

    def lock(self, port: int) -> None:
        """Hear and answer only the stub sending from 127.0.0.1:``port``. (pymavlink's
        ``udpin`` answers every address it has heard: under the full suite another test's
        vehicle, sending to a port this one was then given, was answered, and its
        COMMAND_ACK taken for this stub's.)"""
        conn, peer = self.conn, ("127.0.0.1", port)

        def recv(n: int | None = None) -> bytes:
            try:
                data, source = conn.port.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                return b""
            return data if source == peer else b""

        conn.recv = recv
        conn.clients = {peer}
        conn.clients_last_alive = {peer: math.inf}

    def unlock(self) -> None:
        """Hear every address again (the next stub's)."""
        del self.conn.recv  # the instance's, over pymavlink's own
        self.conn.clients = set()
        self.conn.clients_last_alive = {}

    @property
    def mav(self) -> Any:
        return self.conn.mav

    def recv(self, types: str | tuple[str, ...], timeout_s: float = 3.0,
             where: Callable[[Msg], bool] | None = None) -> Msg | None:
        """The next message of ``types`` (matching ``where``) within a wall-time deadline."""
        wanted = (types,) if isinstance(types, str) else types
        deadline = time.monotonic() + timeout_s
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0.0:
                return None
            msg = self.conn.recv_match(blocking=True, timeout=min(remaining, 0.2))
            if msg is None or msg.get_type() not in wanted:
                continue
            if where is None or where(msg):
                return msg

    def collect(self, types: str | tuple[str, ...], wall_s: float) -> list[Msg]:
        """Every message of ``types`` arriving during ``wall_s`` seconds."""
        wanted = (types,) if isinstance(types, str) else types
        out: list[Msg] = []
        deadline = time.monotonic() + wall_s
        while (remaining := deadline - time.monotonic()) > 0.0:
            msg = self.conn.recv_match(blocking=True, timeout=min(remaining, 0.2))
            if msg is not None and msg.get_type() in wanted:
                out.append(msg)
        return out

    def read_until(self, types: str | tuple[str, ...], done: Callable[[Msg], bool],
                   clock: Callable[[], float] = time.monotonic, wall_s: float = 30.0
                   ) -> list[tuple[float, Msg]]:
        """(``clock()`` as each was read, message) of ``types`` in the order they came, up to
        the first for which ``done`` holds (kept); none within ``wall_s`` fails. Ended by a
        message (by its stamp), not by a clock: at 10-40x a test descheduled for 0.1 s of
        wall time would otherwise see seconds of the stub's time go by unread, and leave in
        its socket what came meanwhile."""
        wanted = (types,) if isinstance(types, str) else types
        out: list[tuple[float, Msg]] = []
        deadline = time.monotonic() + wall_s
        while time.monotonic() < deadline:
            msg = self.recv(wanted, 1.0)
            if msg is None:
                continue
            out.append((clock(), msg))
            if done(msg):
                return out
        raise AssertionError(f"no message of {wanted} ended the read in {wall_s:g} s "
                             f"({len(out)} read)")

    def collect_until(self, types: str | tuple[str, ...], done: Callable[[Msg], bool]
                      ) -> list[Msg]:
        """The messages of :meth:`read_until`, without their times."""
        return [msg for _, msg in self.read_until(types, done)]

    def drain(self) -> None:
        """Forget everything received so far."""
        while self.conn.recv_match(blocking=False) is not None:
            pass

    def barrier(self) -> None:
        """Until the stub has handled everything this station sent before (it reads one
        socket in order, so the acknowledgement of a command sent now comes after), then
        drop what arrived meanwhile: for messages that are not acknowledged themselves."""
        ack = self.command(mavutil.mavlink.MAV_CMD_DO_SET_SERVO, 9, 1500)  # unsupported
        assert ack is not None, "the stub did not answer"
        self.drain()

    def command(self, command: int, *params: float, target_system: int = 1,
                timeout_s: float = ANSWER_WAIT_S) -> Msg | None:
        """Send COMMAND_LONG and wait for its COMMAND_ACK."""
        p = [*params, *([0.0] * (7 - len(params)))]
        self.drain()
        self.mav.command_long_send(target_system, 1, command, 0, *p)
        return self.recv("COMMAND_ACK", timeout_s, lambda m: m.command == command)

    def command_int(self, command: int, p1: float = 0.0, p2: float = 0.0, p3: float = 0.0,
                    p4: float = 0.0, *, target_system: int = 1,
                    timeout_s: float = ANSWER_WAIT_S) -> Msg | None:
        """Send COMMAND_INT and wait for its COMMAND_ACK."""
        self.drain()
        self.mav.command_int_send(target_system, 1, M.MAV_FRAME_GLOBAL, command, 0, 0,
                                  p1, p2, p3, p4, 0, 0, 0.0)
        return self.recv("COMMAND_ACK", timeout_s, lambda m: m.command == command)

    def set_mode(self, custom_mode: int, sub_mode: int = 0, target_system: int = 1) -> Msg | None:
        return self.command(M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                            custom_mode, sub_mode, target_system=target_system)

    def velocity(self, north_m_s: float, east_m_s: float, *, body: bool = False,
                 yaw_rate_rad_s: float | None = None, mask: int | None = None) -> None:
        frame = M.MAV_FRAME_BODY_NED if body else M.MAV_FRAME_LOCAL_NED
        if mask is None:
            mask = 0x0DC7 if yaw_rate_rad_s is None else 0x05C7
        self.mav.set_position_target_local_ned_send(
            0, 1, 1, frame, mask, 0, 0, 0, north_m_s, east_m_s, 0, 0, 0, 0, 0,
            yaw_rate_rad_s or 0.0)


@contextmanager
def gcs_link(**kwargs: Any) -> Iterator[Gcs]:
    gcs = Gcs(**kwargs)
    try:
        yield gcs
    finally:
        gcs.close()


def make_config(port: int, **settings: Any) -> StubConfig:
    """The paper's scenario 1 (1 m/s, 1 m/s2) as a stub sending to ``127.0.0.1:port``."""
    settings.setdefault("connect", f"udpout:127.0.0.1:{port}")
    settings.setdefault("speedup", 20.0)
    return stub_config(load_scenario(SCENARIO), **settings)


@contextmanager
def running_stub(gcs: Gcs, *, record_truth: bool = True, lockstep: bool = False,
                 **settings: Any) -> Iterator[SitlStub]:
    """A started stub talking to ``gcs``; waits for its first heartbeat (``lockstep``: its
    first request for time, sent before anything else: drive it with :class:`Lockstep`)."""
    stub = SitlStub(make_config(gcs.port, **settings), record_truth=record_truth,
                    lockstep=lockstep)  # fmt: skip
    with stub:
        first = "TIMESYNC" if lockstep else "HEARTBEAT"
        assert gcs.recv(first, ANSWER_WAIT_S) is not None, f"no {first} from the stub"
        address = stub.local_address  # bound by its first send
        assert address is not None
        gcs.lock(address[1])
        try:
            yield stub
        finally:
            gcs.unlock()
    assert stub.error is None, stub.error
    assert stub.handler_errors == 0


NS = 1_000_000_000


class Lockstep:
    """The ground station's side of lockstep (:mod:`sitl_stub.lockstep`) for a stub started
    with ``lockstep=True``: its time moves only as far as granted here, so what the test
    sends while the stub is stopped takes effect at that simulated time however long the
    test was descheduled (a stream's period, a timeout, on the stub's clock alone). Every
    other message read on the way is kept in ``read``, with the stub's time as it was read
    (that of the message or later, by less than to the stub's next stop)."""

    def __init__(self, gcs: Gcs, stub: SitlStub) -> None:
        self.gcs, self.stub = gcs, stub
        self.read: list[tuple[float, Msg]] = []
        self.last_sent_s = -math.inf  # the stub's time at the last ``every``
        # the request read and left unanswered where the last run stopped (ts1), answered as
        # the next one starts; at first none (an answer to 0 grants time, holds nothing)
        self._pending: int | None = 0
        self._answered: set[int] = set()  # (a request resent before its answer came: not again)

    def run(self, until_s: float, *, every: Callable[[], None] | None = None,
            period_s: float = 0.1, done: Callable[[Msg], bool] | None = None,
            wall_s: float = 120.0) -> Msg | None:
        """Let the stub's time run to ``until_s``, where it stays stopped (None), or until a
        message for which ``done`` holds is read (that message), answering each of its
        requests for time. ``every`` is called at the first stop before ``until_s`` and then
        at the first at or after each ``period_s`` of the stub's time from it (before
        ``until_s``), before the answer: what it sends takes effect at that stop's time."""
        eps = 1e-4  # (the stub's times are whole physics steps, 10 ms)
        next_s = -math.inf
        deadline = time.monotonic() + wall_s
        request, self._pending = self._pending, None
        while True:
            if request is not None:  # the stub is stopped at its time until answered
                t = self.stub.sim_time_s
                if t >= until_s - eps:
                    self._pending = request
                    return None
                if every is not None and t >= next_s - eps:
                    every()
                    self.last_sent_s = t
                    next_s = t + period_s if next_s == -math.inf else next_s + period_s
                    while next_s <= t + eps:
                        next_s += period_s
                grant = until_s if every is None else min(next_s, until_s)
                self.gcs.mav.timesync_send(round(grant * NS), request)
                self._answered.add(request)
                request = None
            assert time.monotonic() < deadline, f"the stub did not reach {until_s:g} s"
            msg = self.gcs.conn.recv_match(blocking=True, timeout=0.2)
            if msg is None:
                continue
            if msg.get_type() == "TIMESYNC" and msg.tc1 == 0:
                if int(msg.ts1) not in self._answered:
                    request = int(msg.ts1)
                continue
            self.read.append((self.stub.sim_time_s, msg))
            if done is not None and done(msg):
                return msg


def stream_until(stub: SitlStub, send: Callable[[], None], until_s: float,
                 period_s: float = 0.1) -> None:
    """Call ``send`` every ``period_s`` of simulated time until ``until_s``."""
    t = stub.sim_time_s
    while t < until_s:
        send()
        t += period_s
        assert stub.wait_sim_time(min(t, until_s)), "stub clock stalled"


def course_deg(state: Any) -> float:
    """Course over ground of a truth state in degrees [0, 360) (no wind in these tests)."""
    return math.degrees(state.heading_rad) % 360.0


def angle_diff_deg(a: float, b: float) -> float:
    """a - b wrapped to [-180, 180)."""
    return (a - b + 180.0) % 360.0 - 180.0


def between(stub: SitlStub, t0_s: float, t1_s: float) -> list[Any]:
    """Truth states with t0 <= t <= t1."""
    return [s for s in list(stub.history) if t0_s - 1e-9 <= s.t_s <= t1_s + 1e-9]


def stamped_after(kind: str, after_ms: float) -> Callable[[Msg], bool]:
    """A message of ``kind`` stamped later than ``after_ms`` (for :meth:`Gcs.read_until`)."""
    return lambda msg: msg.get_type() == kind and msg.time_boot_ms > after_ms


def stamps_s(msgs: list[Msg]) -> list[float]:
    return [m.time_boot_ms / 1000.0 for m in msgs]


def measured_rate_hz(msgs: list[Msg]) -> float:
    """Rate from the messages' own (simulated) time stamps."""
    t = sorted(stamps_s(msgs))
    assert len(t) >= 3, f"too few messages: {len(t)}"
    return (len(t) - 1) / (t[-1] - t[0])


class Relay:
    """A UDP man in the middle on 127.0.0.1, for the companion's trust tests.

    The vehicle sends to ``vehicle_port``; every datagram goes on to the companion from the
    relay's own socket, and the companion's replies go back to the vehicle. To the companion
    the relay *is* the vehicle's address, so :meth:`inject` forges frames from it (an
    attacker on the path, or spoofing the source address), and ``tamper`` may rewrite or
    drop the vehicle's datagrams. Frames are encoded here with plain pymavlink, not with
    the code under test.
    """

    def __init__(self, companion_port: int) -> None:
        self._companion = ("127.0.0.1", companion_port)
        self._vehicle_side = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._vehicle_side.bind(("127.0.0.1", 0))
        self._companion_side = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._companion_side.bind(("127.0.0.1", 0))
        self.vehicle_port: int = self._vehicle_side.getsockname()[1]
        self._vehicle: tuple[str, int] | None = None
        self.tamper: Callable[[bytes], bytes | None] | None = None
        self.from_companion: list[bytes] = []
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        sockets = [self._vehicle_side, self._companion_side]
        while not self._stop.is_set():
            readable, _, _ = select.select(sockets, [], [], 0.05)
            for sock in readable:
                try:
                    data, source = sock.recvfrom(65535)
                except OSError:
                    continue
                if sock is self._vehicle_side:
                    self._vehicle = source
                    tamper = self.tamper
                    out = tamper(data) if tamper is not None else data
                    if out:
                        self._send(out)
                else:
                    self.from_companion.append(data)
                    if self._vehicle is not None:
                        self._vehicle_side.sendto(data, self._vehicle)

    def _send(self, data: bytes) -> None:
        with self._lock:
            self._companion_side.sendto(data, self._companion)

    def inject(self, frame: bytes) -> None:
        """Send ``frame`` to the companion from the vehicle's address (as it sees it)."""
        self._send(frame)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
        self._vehicle_side.close()
        self._companion_side.close()


def forger(system_id: int = 1, component_id: int = 1) -> Any:
    """A pymavlink encoder that signs nothing and claims ``system_id/component_id``."""
    return M.MAVLink(None, srcSystem=system_id, srcComponent=component_id)


def stranger_socket() -> socket.socket:
    """A UDP socket of its own on 127.0.0.1 (another address than the vehicle's), not
    blocking: a stranger on the companion's port."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.setblocking(False)
    return sock


def frame(mav: Any, msg: Any, *, mavlink1: bool = False) -> bytes:
    """``msg`` packed by ``mav`` (advancing its sequence number)."""
    return bytes(msg.pack(mav, force_mavlink1=mavlink1))
