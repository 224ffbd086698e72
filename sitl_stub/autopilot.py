"""The autopilot's side of MAVLink: modes, arming, commands, setpoints and their timeouts.

:class:`Autopilot` reads decoded messages and keeps what the vehicle is being asked to do; it
answers through :attr:`Autopilot.outbox` (COMMAND_ACK, STATUSTEXT, TIMESYNC, ...) and tells
the simulation loop the vehicle command in force with :meth:`Autopilot.command_at`. It acts
like the autopilots it imitates (ArduPilot 4.7 and PX4), with one deliberate difference:
whatever it cannot follow is announced in a STATUSTEXT where they would stay silent.

Setpoints are followed only in the guided mode (GUIDED, or OFFBOARD for PX4):

- SET_POSITION_TARGET_LOCAL_NED (copter, PX4) with a velocity in MAV_FRAME_LOCAL_NED or
  MAV_FRAME_BODY_NED: its direction becomes the commanded course, followed with the
  measured lag (a body-frame direction is fixed when received, turning at the yaw rate if
  one is given); its speed, times the measured shortfall, is flown (the ideal model: the
  cruise speed); a z holds a height, else vz is flown (PX4: with its drift); a zero
  velocity stops the vehicle. Timeout: the last velocity is flown for
  ``setpoint_timeout_s``, then the vehicle stops and holds (PX4: 1 s without any setpoint,
  then a failsafe to POSCTL, descending).
- SET_ATTITUDE_TARGET: the roll angle becomes a coordinated turn, a = g tan(roll) (or, copter
  and PX4 with the attitude ignored, a body yaw rate becomes a turn rate). Plane reads
  type_mask as ArduPlane does (198 = roll only). Held for ``attitude_timeout_s``.
- MAV_CMD_GUIDED_CHANGE_HEADING (plane), COMMAND_INT or COMMAND_LONG: p1 0 course over
  ground, 1 heading, 2 cancel; p2 degrees [0, 360); p3 lateral acceleration limit (m/s2).
  No timeout by default (``course_timeout_s``).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

from sitl_stub.commands import CommandHandlers
from sitl_stub.config import StubConfig
from sitl_stub.mav import Message, finite, roll_of_quaternion
from sitl_stub.mav import mav as mavlink
from sitl_stub.profiles import Behaviour, ModeSpec
from sitl_stub.signing import KeyChange, key_change, signing_rules
from sitl_stub.status import (
    extended_sys_state,
    gps_global_origin,
    statustext_frames,
)
from sitl_stub.telemetry import StreamScheduler
from sitl_stub.vehicle import (
    GRAVITY_M_S2,
    FollowCourse,
    LateralAccel,
    Stop,
    Straight,
    TurnRate,
    VehicleCommand,
    VehicleState,
    Vertical,
)

__all__ = ["Autopilot"]

_log = logging.getLogger(__name__)

_MAX_SETPOINT_SPEED_M_S = 100.0  # faster than this is absurd for these vehicles: refused
_MAX_YAW_RATE_RAD_S = 2.0 * math.pi
_MAX_ROLL_RAD = math.radians(80.0)
_REPEAT_NOTICE_S = 1.0  # the same rejection is announced at most this often
_R = mavlink
_POS_IGNORE = _R.POSITION_TARGET_TYPEMASK_X_IGNORE | _R.POSITION_TARGET_TYPEMASK_Y_IGNORE
_Z_IGNORE = _R.POSITION_TARGET_TYPEMASK_Z_IGNORE
_VZ_IGNORE = _R.POSITION_TARGET_TYPEMASK_VZ_IGNORE
_MAX_HEIGHT_M = 100_000.0
_ACC_IGNORE = (_R.POSITION_TARGET_TYPEMASK_AX_IGNORE | _R.POSITION_TARGET_TYPEMASK_AY_IGNORE
               | _R.POSITION_TARGET_TYPEMASK_AZ_IGNORE)
_VEL_NE_IGNORE = _R.POSITION_TARGET_TYPEMASK_VX_IGNORE | _R.POSITION_TARGET_TYPEMASK_VY_IGNORE


@dataclass(frozen=True)
class _Active:
    """A command in force: what, since when, for how long (0 = no timeout)."""

    label: str
    command: VehicleCommand
    received_s: float
    timeout_s: float
    nose: tuple[float, float] | None = None  # body frame: (yaw_rad at received_s, yaw rate)
    vertical: Vertical | None = None  # what the setpoint asks vertically (None: hold)

    def nose_rad(self, t_s: float) -> float | None:
        """Where the nose points at ``t_s`` for a body-frame setpoint (yaw turns at its rate)."""
        if self.nose is None:
            return None
        return self.nose[0] + self.nose[1] * (t_s - self.received_s)

    def expired(self, t_s: float) -> bool:
        return self.timeout_s > 0.0 and t_s - self.received_s > self.timeout_s


class Autopilot(CommandHandlers):
    """Mode, arming and guidance state of the imitated autopilot (one thread owns it)."""

    def __init__(self, config: StubConfig, scheduler: StreamScheduler, mav: Any) -> None:
        self.config = config
        self.spec = config.spec
        self.scheduler = scheduler
        self._mav = mav
        self.system_id = config.settings.system_id
        self.component_id = config.settings.component_id
        mode = self.spec.mode_by_name(config.initial_mode)
        assert mode is not None  # validated with the settings
        self.mode: ModeSpec = mode
        self.armed = config.settings.start_armed
        self.outbox: list[Message] = []
        self.requested: list[str] = []  # messages asked for once (MAV_CMD_REQUEST_MESSAGE)
        self.signing_change: KeyChange | None = None  # a key taken (SETUP_SIGNING), for the link
        self._guided: _Active | None = None  # velocity or course command
        self._override: _Active | None = None  # attitude command, ahead of the guided one
        self._last_setpoint_s = -math.inf
        self._noticed: dict[str, float] = {}
        self._label = ""
        self._descending = False  # PX4's failsafe without RC: descend in POSCTL
        self._text_id = 0
        self._origin_sent = False

    # ---- what the vehicle does ----------------------------------------------------------
    def command_at(self, t_s: float, state: VehicleState) -> VehicleCommand:
        """The vehicle command in force at ``t_s``; expires timed-out setpoints (announced)."""
        command, label = self._resolve(t_s, state)
        if label != self._label:
            self._label = label
            self.statustext(f"{self.mode.name}: {label}", _R.MAV_SEVERITY_INFO)
        return command

    def _resolve(self, t_s: float, state: VehicleState) -> tuple[VehicleCommand, str]:
        if not self.armed:
            return Stop(), "disarmed"
        if self.mode.behaviour is Behaviour.CRUISE:
            return Straight(), "cruising straight"
        if self.mode.behaviour is Behaviour.HOLD:
            return self._hold(state)
        if self._override is not None and self._override.expired(t_s):
            self.statustext(f"{self.mode.name}: attitude timeout", _R.MAV_SEVERITY_WARNING)
            self._override = None
        timeout = self.config.timeout_s("setpoint")
        offboard_lost = (self.spec.failsafe_mode is not None and timeout > 0.0
                         and t_s - self._last_setpoint_s > timeout)
        if offboard_lost or (self._guided is not None and self._guided.expired(t_s)):
            self._guided = None
            if self.spec.failsafe_mode is not None:
                self._set_mode(self.spec.failsafe_mode)
                self._descending = self.config.model_value("failsafe_descent_m_s") > 0.0
                then = "descending (no RC)" if self._descending else "holding"
                self.statustext(f"Failsafe activated: offboard setpoints lost, switching to "
                                f"{self.mode.name}, {then}", _R.MAV_SEVERITY_WARNING)
                return self._resolve(t_s, state)
            self.statustext(f"{self.mode.name}: setpoint timeout", _R.MAV_SEVERITY_WARNING)
            if self.spec.can_hover:
                self._guided = _Active("stopped, holding (timeout)", Stop(), t_s, 0.0)
        active = self._override or self._guided
        if active is not None:
            return active.command, active.label
        return self._hold(state)

    def vertical_at(self, t_s: float, state: VehicleState) -> Vertical:
        """The vertical command in force (call after :meth:`command_at`)."""
        if self._descending and self.armed:
            return Vertical(climb_m_s=-self.config.model_value("failsafe_descent_m_s"))
        if (self.armed and self.mode.behaviour is Behaviour.GUIDED and self._guided is not None
                and self._guided.vertical is not None and self._override is None):
            return self._guided.vertical
        return Vertical()

    def in_air(self, state: VehicleState) -> bool:
        """EXTENDED_SYS_STATE's landed state: armed and above the ground (a plane: armed)."""
        return self.armed and (state.height_m > 0.0 or not self.spec.can_hover)

    def periodic_status(self, state: VehicleState, t_s: float) -> list[Message]:
        """What goes with each HEARTBEAT: EXTENDED_SYS_STATE, and GPS_GLOBAL_ORIGIN once,
        when the local origin is first set (ArduPilot and PX4 send it only then)."""
        out = [extended_sys_state(self._mav, fixed_wing=not self.spec.can_hover,
                                  in_air=self.in_air(state))]
        after = self.config.settings.local_origin_after_s
        if not self._origin_sent and 0.0 <= after <= t_s:
            self._origin_sent = True
            out.append(gps_global_origin(self._mav, self.config.origin, int(t_s * 1e6)))
        return out

    def _hold(self, state: VehicleState) -> tuple[VehicleCommand, str]:
        if self.spec.can_hover:
            return Stop(), "holding position"
        radius = self.config.settings.loiter_radius_m
        accel = min(self.config.accel_max_m_s2, state.speed_m_s**2 / radius)
        return LateralAccel(accel), "loitering"

    # ---- heartbeat ----------------------------------------------------------------------
    def heartbeat(self) -> Message:
        """This autopilot's HEARTBEAT."""
        base = _R.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | _R.MAV_MODE_FLAG_STABILIZE_ENABLED
        if self.mode.behaviour is not Behaviour.CRUISE:
            base |= _R.MAV_MODE_FLAG_GUIDED_ENABLED
        if self.armed:
            base |= _R.MAV_MODE_FLAG_SAFETY_ARMED
        status = _R.MAV_STATE_ACTIVE if self.armed else _R.MAV_STATE_STANDBY
        return self._mav.heartbeat_encode(self.spec.mav_type, self.spec.autopilot, base,
                                          self.mode.custom_mode, status, 3)

    def statustext(self, text: str, severity: int = _R.MAV_SEVERITY_NOTICE) -> None:
        """Queue a STATUSTEXT (chunked, with MAVLink 2's id and chunk_seq, beyond 50 chars)."""
        _log.info("statustext: %s", text)
        self._text_id = self._text_id % 65535 + 1
        self.outbox.extend(statustext_frames(self._mav, text, severity, self._text_id))

    def _notice(self, text: str, t_s: float) -> None:
        """Announce a rejection, at most once per second of simulated time per text."""
        last = self._noticed.get(text, -math.inf)
        if t_s - last >= _REPEAT_NOTICE_S:
            self._noticed[text] = t_s
            self.statustext(text, _R.MAV_SEVERITY_WARNING)

    # ---- incoming -----------------------------------------------------------------------
    def handle(self, msg: Message, t_s: float, state: VehicleState) -> None:
        """React to one decoded message received at ``t_s``."""
        kind = msg.get_type()
        handler = _HANDLERS.get(kind)
        if handler is None:
            return
        if hasattr(msg, "target_system") and msg.target_system not in (0, self.system_id) and not (
                kind == "SETUP_SIGNING" and signing_rules(self.spec.autopilot).any_target):
            return  # addressed to another vehicle
        handler(self, msg, t_s, state)

    def _on_setup_signing(self, msg: Message, t_s: float, state: VehicleState) -> None:
        change, said = key_change(signing_rules(self.spec.autopilot), msg, armed=self.armed)
        if change is not None:
            self.signing_change = change
        if said is not None:
            self.statustext(*said)

    def _guided_ok(self, what: str, t_s: float) -> bool:
        if self.mode.behaviour is not Behaviour.GUIDED:
            self._notice(f"{what} ignored: not in {self.spec.guided_mode}", t_s)
            return False
        if not self.armed:
            self._notice(f"{what} ignored: disarmed", t_s)
            return False
        return True

    def _on_position_target(self, msg: Message, t_s: float, state: VehicleState) -> None:
        mask = int(msg.type_mask)
        # horizontal velocity, with a height (z) or a vertical velocity or neither
        velocity_only = (mask & _POS_IGNORE == _POS_IGNORE and mask & _ACC_IGNORE == _ACC_IGNORE
                         and not mask & _VEL_NE_IGNORE
                         and not mask & _R.POSITION_TARGET_TYPEMASK_FORCE_SET)
        yaw_rate_used = not mask & _R.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
        z_used, vz_used = not mask & _Z_IGNORE, not mask & _VZ_IGNORE
        values = (msg.vx, msg.vy, msg.yaw_rate if yaw_rate_used else 0.0,
                  msg.z if z_used else 0.0, msg.vz if vz_used else 0.0)
        if self.spec.accepts_velocity and velocity_only and finite(*values):
            self._last_setpoint_s = t_s  # PX4's offboard signal, even outside OFFBOARD
        if not self.spec.accepts_velocity:
            self._notice("SET_POSITION_TARGET_LOCAL_NED unsupported", t_s)
            return
        if not self._guided_ok("Velocity setpoint", t_s):
            return
        frame = int(msg.coordinate_frame)
        if frame not in (_R.MAV_FRAME_LOCAL_NED, _R.MAV_FRAME_BODY_NED):
            self._notice(f"Setpoint frame {frame} unsupported", t_s)
            return
        if not velocity_only:
            self._notice(f"Setpoint type_mask {mask} unsupported", t_s)
            return
        if not finite(*values):
            self._notice("Setpoint rejected: not finite", t_s)
            return
        speed = math.hypot(msg.vx, msg.vy)
        if (speed > _MAX_SETPOINT_SPEED_M_S or abs(values[2]) > _MAX_YAW_RATE_RAD_S
                or abs(values[3]) > _MAX_HEIGHT_M or abs(values[4]) > _MAX_SETPOINT_SPEED_M_S):
            self._notice("Setpoint rejected: out of range", t_s)
            return
        timeout = self.config.timeout_s("setpoint")
        if z_used:  # position control of the height: held
            vertical = Vertical(height_m=-float(msg.z))
        else:  # vz (0 when ignored); PX4 does not hold its height this way (drift)
            drift = self.config.model_value("vz_hold_drift_m_s")
            vertical = Vertical(climb_m_s=-float(values[4]) + drift)
        if speed < 1e-3:
            self._guided = _Active("velocity zero, holding", Stop(), t_s, timeout,
                                   vertical=vertical)
            return
        lag = self.config.model_value("velocity_lag_s")
        gain = 1.0 / max(lag, self.config.settings.physics_dt_s)
        direction = math.atan2(msg.vy, msg.vx)
        if frame == _R.MAV_FRAME_BODY_NED:
            # fixed on receipt relative to the nose; the nose yaws at the yaw rate (as
            # ArduCopter's yaw controller does), so a stream of forward + yaw-rate setpoints
            # turns the path at that rate
            previous = self._guided.nose_rad(t_s) if self._guided is not None else None
            nose = state.heading_rad if previous is None else previous
            rate = float(values[2])
            command = FollowCourse(nose + direction, course_rate_rad_s=rate, since_s=t_s,
                                   gain_1_s=gain, speed_m_s=speed)
            self._guided = _Active("following body velocity", command, t_s, timeout,
                                   nose=(nose, rate), vertical=vertical)
            return
        command = FollowCourse(direction, since_s=t_s, gain_1_s=gain, speed_m_s=speed)
        self._guided = _Active("following velocity", command, t_s, timeout, vertical=vertical)

    def _on_attitude_target(self, msg: Message, t_s: float, state: VehicleState) -> None:
        if not self._guided_ok("Attitude target", t_s):
            return
        mask = int(msg.type_mask)
        q = [float(v) for v in msg.q]
        q_ok = finite(*q) and 0.9 <= math.sqrt(sum(v * v for v in q)) <= 1.1
        command: VehicleCommand | None = None
        if self.spec.ardupilot_attitude_mask:
            angles = (mask ^ 0xFF) & 0b10000111
            if (angles & 0b10000001 or angles == 0b10000000) and q_ok:
                command = self._roll_command(roll_of_quaternion(q))
        elif not mask & _R.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE and q_ok:
            command = self._roll_command(roll_of_quaternion(q))
        elif not mask & _R.ATTITUDE_TARGET_TYPEMASK_BODY_YAW_RATE_IGNORE:
            rate = float(msg.body_yaw_rate)
            if finite(rate) and abs(rate) <= _MAX_YAW_RATE_RAD_S:
                command = TurnRate(rate)
        if command is None:
            self._notice(f"Attitude target rejected (mask {mask})", t_s)
            return
        label = "following roll" if isinstance(command, LateralAccel) else "following yaw rate"
        self._override = _Active(label, command, t_s, self.config.timeout_s("attitude"))
        self._last_setpoint_s = t_s  # an offboard signal too (PX4)

    @staticmethod
    def _roll_command(roll_rad: float) -> VehicleCommand | None:
        if abs(roll_rad) > _MAX_ROLL_RAD:
            return None
        return LateralAccel(GRAVITY_M_S2 * math.tan(roll_rad))

    def _follow(self, label: str, command: FollowCourse | None, t_s: float) -> None:
        """A course command (GUIDED_CHANGE_HEADING) in force from ``t_s``; None cancels."""
        self._guided = (None if command is None else
                        _Active(label, command, t_s, self.config.timeout_s("course")))

    def pilot_mode(self, name: str) -> None:
        """A pilot (or a ground station) switches the mode (``pilot_modes``): taken as any
        mode change is, from whatever the vehicle does."""
        self._set_mode(name)

    def _set_mode(self, name: str) -> None:
        mode = self.spec.mode_by_name(name)
        assert mode is not None
        changed = mode != self.mode
        if changed:
            self._guided = None
            self._override = None
            self._descending = False
        self.mode = mode
        if changed and self.spec.autopilot != mavlink.MAV_AUTOPILOT_PX4:
            # ArduPilot says a new mode in a heartbeat at once (ArduCopter's Copter::set_mode,
            # ArduPlane's set_mode: gcs().send_message(MSG_HEARTBEAT); ArduCopter SITL: 6 ms
            # after the mode's ack); PX4 at its next 1 Hz heartbeat
            self.outbox.append(self.heartbeat())



_HANDLERS = {
    "SET_POSITION_TARGET_LOCAL_NED": Autopilot._on_position_target,
    "SET_ATTITUDE_TARGET": Autopilot._on_attitude_target,
    "COMMAND_LONG": Autopilot._on_command,
    "COMMAND_INT": Autopilot._on_command,
    "SET_MODE": Autopilot.set_mode_message,
    "REQUEST_DATA_STREAM": Autopilot._on_data_stream,
    "TIMESYNC": Autopilot._on_timesync,
    "PARAM_REQUEST_READ": Autopilot._on_param_request_read,
    "SETUP_SIGNING": Autopilot._on_setup_signing,
}
