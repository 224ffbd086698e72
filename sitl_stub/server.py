"""The loopback vehicle: a simulated clock, the vehicle model and the autopilot on one link.

:class:`SitlStub` owns one thread. The thread keeps a simulated clock running ``speedup``
times faster than ``time.monotonic()``, advances the vehicle in fixed physics steps up to
the clock, sends the HEARTBEAT (1 Hz) and the telemetry streams when due, and otherwise
sleeps in ``select`` on the link until the next thing is due or a message arrives. Incoming
messages take effect at the simulated time they are read. ``time_boot_ms`` is the simulated
time since the stub started, or since its autopilot last rebooted (``faults.reboot_at_s``:
down and silent for ``faults.reboot_s``, then up afresh, disarmed, in its initial mode,
nothing streamed until asked for, its first heartbeats sent in pairs).

With ``lockstep=True`` (``sitl-stub --lockstep``) the simulated clock also waits for the
companion: it stops after every position sample and at the time the companion granted, and
goes on when the companion answers (:mod:`sitl_stub.lockstep`); ``speedup`` is then the
most it runs ahead of wall time. The engagement no longer depends on the machine's load.

    with SitlStub(load_stub_config("config/paper_scenario1.yaml", speedup=10)) as stub:
        stub.wait_sim_time(5.0)
        print(stub.state)
"""

from __future__ import annotations

import logging
import math
import select
import socket
import threading
import time
from dataclasses import fields, replace
from pathlib import Path
from types import TracebackType

from ezcompanion.errors import ConfigError
from ezcompanion.sim.kinematics import Wind
from sitl_stub.autopilot import Autopilot
from sitl_stub.config import StreamRates, StubConfig
from sitl_stub.faults import FaultInjector
from sitl_stub.lockstep import LockstepGate
from sitl_stub.mav import Message, StubLink, StubLinkStats
from sitl_stub.signing import signing_rules
from sitl_stub.telemetry import StreamScheduler, TelemetryEncoder
from sitl_stub.truth import TruthWriter
from sitl_stub.vehicle import VehicleParams, VehicleState, step

__all__ = ["SitlStub"]

_log = logging.getLogger(__name__)

_HEARTBEAT_PERIOD_S = 1.0
# after a reboot, as ArduCopter 4.5.1 SITL after a forced MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN:
# its heartbeats of the first 2 s each sent twice (sequence n and n + 1 at once), and no
# stamped message on the companion's port in the 4 s it was watched (the streams it had
# been asked for are gone)
_BOOT_PAIRS_S = 2.0
_NO_STREAMS = StreamRates(**{f.name: 0.0 for f in fields(StreamRates)})
_MAX_WAIT_WALL_S = 0.1  # wake at least this often (wall time) to publish the clock
_MAX_STEPS_PER_PASS = 500  # then look at the link again before catching up further
_POSITIONS = frozenset({"LOCAL_POSITION_NED", "GLOBAL_POSITION_INT"})


class SitlStub:
    """A MAVLink vehicle on a pymavlink URL; start/stop or use as a context manager."""

    def __init__(self, config: StubConfig, *, truth_out: str | Path | None = None,
                 record_truth: bool = False, duration_s: float | None = None,
                 lockstep: bool = False) -> None:
        self.config = config
        s = config.settings
        self._wind = Wind(s.wind_north_m_s, s.wind_east_m_s)
        self.params = VehicleParams(
            cruise_speed_m_s=config.start.speed_m_s, accel_max_m_s2=config.accel_max_m_s2,
            yaw_rate_max_rad_s=math.radians(s.yaw_rate_max_deg_s),
            response_time_s=s.response_time_s, course_gain_1_s=s.course_gain_1_s,
            can_hover=config.spec.can_hover, wind=self._wind,
            speed_ratio=config.model_value("speed_ratio"),
            speed_lag_s=config.model_value("velocity_lag_s") if config.measured else 0.0,
            follows_setpoint_speed=config.measured, shaping=config.velocity_shaping(),
            vector_lag_s=config.vector_lag_s(),
            roll_rate_max_rad_s=config.roll_rate_max_rad_s,
            bank_accel_ratio=config.model_value("heading_accel_ratio"),
        )
        grounded = not s.start_armed and config.spec.can_hover
        start = config.placed_start
        speed = 0.0 if grounded else start.speed_m_s
        self._state = VehicleState(
            t_s=0.0, north_m=start.north_m, east_m=start.east_m,
            heading_rad=start.course_rad, speed_m_s=speed, height_m=s.height_m,
        )
        self._truth_out = Path(truth_out) if truth_out is not None else None
        self._record = record_truth
        self.history: list[VehicleState] = [self._state] if record_truth else []
        self._duration_s = duration_s
        self._lock = threading.Condition()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._link: StubLink | None = None
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._sim_s = 0.0
        self._steps = 0
        self.handler_errors = 0
        self.error: BaseException | None = None
        self.autopilot: Autopilot | None = None
        self.faults = FaultInjector(s.faults, s.seed)
        self._stale: VehicleState | None = None
        self._truth: TruthWriter | None = None
        self.lockstep: LockstepGate | None = LockstepGate() if lockstep else None
        if lockstep and s.faults.reboot_at_s >= 0.0:
            raise ConfigError("faults.reboot_at_s", s.faults.reboot_at_s,
                              "a reboot restarts the clock that lockstep runs on: not both")
        self._boot_s = 0.0  # the simulated time the autopilot last booted at
        self.reboots = 0  # 1 once the autopilot has rebooted (faults.reboot_at_s)
        self._pilot_next = 0  # the next of pilot_modes to fall due

    # ---- lifecycle ---------------------------------------------------------------------
    def start(self) -> SitlStub:
        """Open the link and start the simulation thread."""
        s = self.config.settings
        self._link = StubLink(s.connect, system_id=s.system_id, component_id=s.component_id,
                              hear_only_peer=self.config.spec.udp_client_hears_only_peer)
        self._scheduler = StreamScheduler(s.streams, self.config.max_stream_rate_hz)
        self.autopilot = Autopilot(self.config, self._scheduler, self._link.mav)
        self._signing = signing_rules(self.autopilot.spec.autopilot)
        key = s.signing_key()
        if key is not None:
            self._link.enable_signing(key, unsigned_ids=self._signing.unsigned_ids)
        self._encoder = TelemetryEncoder(self._link, self.config.origin, self._wind,
                                         self.autopilot.spec.autopilot)
        self._truth = TruthWriter(self._truth_out, self._wind) if self._truth_out else None
        if self._truth is not None:
            self._truth.write(self._state, self.autopilot.mode.name, self.autopilot.armed)
        self._thread = threading.Thread(target=self._run, name="sitl-stub", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the thread and close the link and files (idempotent)."""
        self._stop.set()
        if self._wake_w.fileno() >= 0:
            self._wake_w.send(b"x")
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        if self._link is not None:
            self._link.close()
            self._link = None
        if self._truth is not None:
            self._truth.close()
            self._truth = None
        self._wake_r.close()
        self._wake_w.close()

    def __enter__(self) -> SitlStub:
        return self.start()

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.stop()

    @property
    def running(self) -> bool:
        """True while the simulation thread runs (it ends at ``duration_s`` or on error)."""
        return self._thread is not None and self._thread.is_alive()

    # ---- observation (thread-safe) -----------------------------------------------------
    @property
    def state(self) -> VehicleState:
        """The vehicle's true state at the last physics step."""
        with self._lock:
            return self._state

    @property
    def sim_time_s(self) -> float:
        """The simulated clock (s since start)."""
        with self._lock:
            return self._sim_s

    @property
    def local_address(self) -> tuple[str, int] | None:
        """The address the stub's socket is bound to (for ``udpin:127.0.0.1:0``)."""
        return self._link.local_address if self._link is not None else None

    @property
    def serial_device(self) -> str | None:
        """The pseudo-terminal the stub serves (``connect: pty``), for the companion."""
        return self._link.serial_device if self._link is not None else None

    @property
    def link_stats(self) -> StubLinkStats | None:
        """The link's receive counters (None before it opens and after it closes). Read
        from another thread than the link's: plain counters, each read whole."""
        return self._link.stats if self._link is not None else None

    @property
    def mode_name(self) -> str:
        """The current flight mode's name."""
        assert self.autopilot is not None
        return self.autopilot.mode.name

    def wait_sim_time(self, t_s: float, timeout_s: float | None = None) -> bool:
        """Wait until the simulated clock reaches ``t_s``; False on wall ``timeout_s``."""
        speedup = self.config.settings.speedup
        if timeout_s is None:
            timeout_s = 2.0 + 2.0 * max(t_s - self.sim_time_s, 0.0) / speedup
        deadline = time.monotonic() + timeout_s
        with self._lock:
            while self._sim_s < t_s and not self._stop.is_set():
                remaining = deadline - time.monotonic()
                if remaining <= 0.0:
                    return False
                self._lock.wait(remaining)
            return self._sim_s >= t_s

    # ---- the loop ----------------------------------------------------------------------
    def _run(self) -> None:
        try:
            self._loop()
        except BaseException as exc:
            self.error = exc
            _log.exception("sitl_stub thread failed")
        finally:
            with self._lock:
                self._stop.set()
                self._lock.notify_all()

    def _loop(self) -> None:
        assert self._link is not None and self.autopilot is not None
        link, speedup = self._link, self.config.settings.speedup
        wall0 = time.monotonic()
        self._next_heartbeat_s = 0.0
        gate = self.lockstep
        dt = self.config.settings.physics_dt_s
        while not self._stop.is_set():
            now = (time.monotonic() - wall0) * speedup
            if self._duration_s is not None:
                now = min(now, self._duration_s)
            if gate is not None:
                now = min(now, gate.limit_s(self._state.t_s, dt))
            caught_up = self._advance(now)
            # on the simulated clock, the one the frames' stamps are on: a loop that has
            # fallen behind the wall releases nothing before its own time reaches it
            for frame in self.faults.release(self._state.t_s):
                link.write(frame)
            with self._lock:
                self._sim_s = self._state.t_s
                self._lock.notify_all()
            if self._duration_s is not None and self._state.t_s >= self._duration_s - 1e-9:
                return
            wait_s = 0.0 if not caught_up else self._wait_wall_s(now, speedup)
            if gate is not None and gate.stopped(self._state.t_s):
                request = gate.request(link.mav, self._state.t_s)
                if request is not None:
                    link.send(request)
                if gate.given_up(self._state.t_s):
                    return
                wait_s = gate.wait_wall_s()
            if gate is not None and not gate.stopped(self._state.t_s):
                # lockstep, running: the link is read at the next stop, so that whatever the
                # companion sent takes effect at a simulated time that no wall timing moves
                select.select([self._wake_r], [], [], wait_s)
                continue
            readable = link.wait_readable(wait_s, self._wake_r.fileno())
            if self._wake_r.fileno() in readable:
                self._drain_wake()
            if link.fileno() in readable:
                self._receive(link)

    def _wait_wall_s(self, now: float, speedup: float) -> float:
        events = [self._next_heartbeat_s, self._scheduler.next_due_s(),
                  self._state.t_s + self.config.settings.physics_dt_s]
        release = self.faults.next_release_s()
        if release is not None:  # released on the simulated clock: at a physics step
            events.append(max(release, self._state.t_s + self.config.settings.physics_dt_s))
        return max(0.0, min(_MAX_WAIT_WALL_S, (min(events) - now) / speedup))

    def _drain_wake(self) -> None:
        try:
            while self._wake_r.recv(64):
                pass
        except BlockingIOError:
            pass

    def _link_down(self) -> bool:
        """A ``link`` freeze or a reboot: nothing goes out and nothing that comes in is
        heard."""
        link_freeze = self.config.settings.faults.freeze_mode == "link"
        return self._rebooting(self._state.t_s) or (
            link_freeze and self.faults.frozen(self._state.t_s))

    def _rebooting(self, t_s: float) -> bool:
        f = self.config.settings.faults
        return 0.0 <= f.reboot_at_s <= t_s < f.reboot_at_s + f.reboot_s

    def _pilot(self, t_s: float) -> None:
        """The pilot's mode switches (``pilot_modes``) that have fallen due."""
        assert self.autopilot is not None
        changes = self.config.settings.pilot_modes
        while self._pilot_next < len(changes) and changes[self._pilot_next][0] <= t_s + 1e-9:
            self.autopilot.pilot_mode(changes[self._pilot_next][1])
            self._pilot_next += 1

    def _power(self, t_s: float) -> None:
        """The reboot of ``faults.reboot_at_s``: the autopilot goes down (disarmed, no
        guidance), and ``reboot_s`` later boots afresh: a new clock, its initial mode, no
        streams until asked for, the origin sent again once set."""
        f = self.config.settings.faults
        assert self.autopilot is not None and self._link is not None
        if self.reboots or f.reboot_at_s < 0.0 or t_s < f.reboot_at_s:
            return
        if self._rebooting(t_s):
            self.autopilot.armed = False
            return
        self._boot_s = t_s
        self.reboots = 1
        # nothing streamed until asked for (the requests before the reboot are gone)
        self._scheduler = StreamScheduler(_NO_STREAMS, self.config.max_stream_rate_hz)
        self._scheduler.shift(t_s)
        self.autopilot = Autopilot(self.config, self._scheduler, self._link.mav)
        self.autopilot.armed = False
        _log.info("rebooted at %.2f s", t_s)

    def _receive(self, link: StubLink) -> None:
        assert self.autopilot is not None
        messages = link.recv_messages()
        if self._link_down():
            return
        for msg in messages:
            if self.lockstep is not None and self.lockstep.on_message(msg):
                continue
            try:
                self.autopilot.handle(msg, self._state.t_s, self._state)
            except Exception:
                self.handler_errors += 1
                _log.exception("handling %s failed", msg.get_type())
            self._take_key(link)  # the next frames, the answer among them, signed with it
        if self._flush() and self.lockstep is not None:
            self.lockstep.hold(self._state.t_s)  # the companion sees the replies first

    def _take_key(self, link: StubLink) -> None:
        """A key the autopilot took (SETUP_SIGNING) goes to the link, as on every link of
        the autopilots it imitates (:mod:`sitl_stub.signing`)."""
        assert self.autopilot is not None
        change, self.autopilot.signing_change = self.autopilot.signing_change, None
        if change is None:
            return
        if change.key is None:
            link.disable_signing()
        else:
            link.enable_signing(change.key, timestamp_10us=change.timestamp_10us,
                                unsigned_ids=self._signing.unsigned_ids)
        _log.info("signing %s", "off" if change.key is None else "on with a new key")

    def _flush(self) -> int:
        """Send what the autopilot has to say; how many messages."""
        assert self._link is not None and self.autopilot is not None
        if self._link_down():
            self.autopilot.outbox.clear()
            self.autopilot.requested.clear()
            return 0
        sent = len(self.autopilot.outbox) + len(self.autopilot.requested)
        for msg in self.autopilot.outbox:
            self._link.send(msg)
        self.autopilot.outbox.clear()
        for name in self.autopilot.requested:
            self._emit(name, self._state.t_s)
        self.autopilot.requested.clear()
        return sent

    def _advance(self, now: float) -> bool:
        """Step the physics up to ``now``; False if it stopped early to look at the link."""
        assert self.autopilot is not None and self._link is not None
        dt = self.config.settings.physics_dt_s
        ap = self.autopilot
        for _ in range(_MAX_STEPS_PER_PASS):
            if self._state.t_s + dt > now + 1e-12:
                return True
            command = ap.command_at(self._state.t_s, self._state)
            vertical = ap.vertical_at(self._state.t_s, self._state)
            self._steps += 1
            new = replace(step(self._state, command, self.params, dt, vertical),
                          t_s=self._steps * dt)
            with self._lock:
                self._state = new
                self._sim_s = new.t_s  # before any frame stamped at it goes out
            if self._record:
                self.history.append(new)
            self._power(new.t_s)
            self._pilot(new.t_s)
            ap = self.autopilot
            if self._truth is not None:
                self._truth.write(new, ap.mode.name, ap.armed)
            self._periodic(new.t_s)
            self._flush()
            if self.lockstep is not None and self.lockstep.stopped(new.t_s):
                return True  # wait for the companion's answer
        return False

    def _periodic(self, t_s: float) -> None:
        assert self.autopilot is not None and self._link is not None
        if self._next_heartbeat_s < t_s - _HEARTBEAT_PERIOD_S:
            self._next_heartbeat_s = t_s  # fell behind (a starved process): do not burst
        while self._next_heartbeat_s <= t_s + 1e-9:
            if not self._link_down():
                self._link.send(self.autopilot.heartbeat())
                if self.reboots and self._next_heartbeat_s < self._boot_s + _BOOT_PAIRS_S:
                    self._link.send(self.autopilot.heartbeat())  # booting: sent in pairs
                for msg in self.autopilot.periodic_status(self._state, t_s):
                    self._link.send(msg)
            self._next_heartbeat_s += _HEARTBEAT_PERIOD_S
        for stamp, name in self._scheduler.pop_due(t_s):
            self._emit(name, stamp)

    def _emit(self, name: str, stamp_s: float) -> None:
        """Send one telemetry message about the current state, through the faults."""
        assert self._link is not None
        s = self.config.settings
        if self._rebooting(stamp_s):
            return
        if name == "LOCAL_POSITION_NED" and not (0.0 <= s.local_origin_after_s <= stamp_s):
            return  # no local origin yet (ArduPilot sends it only once the EKF has one)
        state = self._state
        if self.faults.frozen(stamp_s):
            if s.faults.freeze_mode in ("silent", "link"):
                return
            if self._stale is None:
                self._stale = state
            state = self._stale
        else:
            self._stale = None
        north, east = self.faults.position_offset_m(stamp_s)
        msg: Message = self._encoder.encode(name, state, stamp_s - self._boot_s, north, east)
        frame = self._link.pack(msg)
        if s.faults.any:
            self.faults.submit(frame, stamp_s)
            for ready in self.faults.release(self._state.t_s):
                self._link.write(ready)
        else:
            self._link.write(frame)
        if self.lockstep is not None and name in _POSITIONS:
            self.lockstep.hold(self._state.t_s)
