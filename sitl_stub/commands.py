"""COMMAND_LONG / COMMAND_INT, SET_MODE, REQUEST_DATA_STREAM, TIMESYNC, PARAM_REQUEST_READ, as the
imitated autopilots answer them: every command addressed to the stub gets a COMMAND_ACK addressed to
its sender (PX4 v1.16 sends each ack twice); what the stub does not implement is
UNSUPPORTED. Mixed into :class:`sitl_stub.autopilot.Autopilot`, which owns the state.
"""

from __future__ import annotations

import math
from typing import Any

from sitl_stub.config import StubConfig
from sitl_stub.mav import Message, finite, mav
from sitl_stub.profiles import Behaviour, ModeSpec, Profile, ProfileSpec, px4_custom_mode
from sitl_stub.status import autopilot_version, extended_sys_state, gps_global_origin
from sitl_stub.telemetry import STREAMED, StreamScheduler
from sitl_stub.vehicle import FollowCourse, VehicleState

__all__ = ["CommandHandlers"]

_R = mav


class CommandHandlers:
    """The command side of the autopilot (state declared here, owned by the subclass)."""

    config: StubConfig
    spec: ProfileSpec
    scheduler: StreamScheduler
    _mav: Any
    system_id: int
    component_id: int
    mode: ModeSpec
    armed: bool
    outbox: list[Message]
    requested: list[str]
    _last_setpoint_s: float

    def _notice(self, text: str, t_s: float) -> None:
        raise NotImplementedError

    def _set_mode(self, name: str) -> None:
        raise NotImplementedError

    def _follow(self, label: str, command: FollowCourse | None, t_s: float) -> None:
        raise NotImplementedError

    def heartbeat(self) -> Message:
        raise NotImplementedError

    def in_air(self, state: VehicleState) -> bool:
        raise NotImplementedError

    def _for_us(self, msg: Message) -> bool:
        return getattr(msg, "target_component", 0) in (0, self.component_id)

    def _on_command(self, msg: Message, t_s: float, state: VehicleState) -> None:
        if not self._for_us(msg):
            return
        command = int(msg.command)
        params = [float(getattr(msg, f"param{i}")) for i in range(1, 5)]
        before = len(self.outbox)
        result = self._command_result(command, params, t_s, state)
        answers = self.outbox[before:]  # what the command asked for goes after its ack
        del self.outbox[before:]
        self.ack(msg, command, int(result))
        self.outbox.extend(answers)

    def _command_result(self, command: int, params: list[float], t_s: float,
                        state: VehicleState) -> int:
        if command == _R.MAV_CMD_DO_SET_MODE:
            result = self._cmd_set_mode(params[0], params[1], params[2], t_s)
        elif command == _R.MAV_CMD_COMPONENT_ARM_DISARM:
            result = self._cmd_arm(params[0])
        elif command == _R.MAV_CMD_SET_MESSAGE_INTERVAL:
            result = self.scheduler.set_message_interval(params[0], params[1], t_s)
        elif command == _R.MAV_CMD_GET_MESSAGE_INTERVAL:
            result = self._cmd_get_interval(params[0])
        elif command == _R.MAV_CMD_REQUEST_MESSAGE:
            result = self._cmd_request_message(params[0], t_s, state)
        elif command == _R.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES and params[0] == 1.0:
            result = self._cmd_request_message(_R.MAVLINK_MSG_ID_AUTOPILOT_VERSION, t_s, state)
        elif command == _R.MAV_CMD_GUIDED_CHANGE_HEADING and self.spec.accepts_course_command:
            result = self._cmd_change_heading(params[0], params[1], params[2], t_s)
        else:
            result = _R.MAV_RESULT_UNSUPPORTED
        return int(result)

    def ack(self, msg: Message, command: int, result: int) -> None:
        """Queue the COMMAND_ACK for ``command``, addressed to the sender of ``msg`` (twice,
        as PX4 v1.16 acknowledges)."""
        for _ in range(2 if self.spec.acks_twice else 1):
            self.outbox.append(self._mav.command_ack_encode(
                command, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()))

    def _cmd_set_mode(self, base: float, custom: float, sub: float, t_s: float) -> int:
        if not finite(base, custom, sub) or not 0 <= custom < 2**32 or not 0 <= sub < 256:
            return int(_R.MAV_RESULT_DENIED)
        if not int(base) & _R.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return int(_R.MAV_RESULT_DENIED)
        if self.spec.autopilot == _R.MAV_AUTOPILOT_PX4:
            if not custom < 256:
                return int(_R.MAV_RESULT_DENIED)
            number = px4_custom_mode(int(custom), int(sub))
        else:
            number = int(custom)
        mode = self.spec.mode_by_number(number)
        if mode is None:
            return int(_R.MAV_RESULT_FAILED)
        if (mode.behaviour is Behaviour.GUIDED and self.spec.failsafe_mode is not None
                and t_s - self._last_setpoint_s > self.config.timeout_s("setpoint")):
            self._notice(f"{mode.name} needs setpoints first", t_s)
            return int(_R.MAV_RESULT_TEMPORARILY_REJECTED)
        self._set_mode(mode.name)
        return int(_R.MAV_RESULT_ACCEPTED)

    def set_mode_message(self, msg: Message, t_s: float, state: VehicleState) -> None:
        """SET_MODE (the message, not the command): ArduPilot acks it with command = 11."""
        result = self._cmd_set_mode(float(msg.base_mode), float(msg.custom_mode), 0.0, t_s)
        self.ack(msg, int(_R.MAVLINK_MSG_ID_SET_MODE), result)

    def _cmd_arm(self, arm: float) -> int:
        if arm not in (0.0, 1.0):
            return int(_R.MAV_RESULT_DENIED)
        self.armed = arm == 1.0
        return int(_R.MAV_RESULT_ACCEPTED)

    def _cmd_get_interval(self, msg_id: float) -> int:
        if not finite(msg_id) or int(msg_id) != msg_id or int(msg_id) not in STREAMED:
            return int(_R.MAV_RESULT_FAILED)
        interval = self.scheduler.interval_s(STREAMED[int(msg_id)])
        interval_us = -1 if interval is None else round(interval * 1e6)
        self.outbox.append(self._mav.message_interval_encode(int(msg_id), interval_us))
        return int(_R.MAV_RESULT_ACCEPTED)

    def _cmd_request_message(self, msg_id: float, t_s: float, state: VehicleState) -> int:
        if not finite(msg_id) or int(msg_id) != msg_id:
            return int(_R.MAV_RESULT_DENIED)
        number = int(msg_id)
        if number == _R.MAVLINK_MSG_ID_HEARTBEAT:
            self.outbox.append(self.heartbeat())
        elif number in STREAMED:
            self.requested.append(STREAMED[number])
        elif number == _R.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN:
            after = self.config.settings.local_origin_after_s
            if not 0.0 <= after <= t_s:
                return int(_R.MAV_RESULT_TEMPORARILY_REJECTED)  # no origin yet
            self.outbox.append(gps_global_origin(self._mav, self.config.origin,
                                                 int(after * 1e6)))
        elif number == _R.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            self.outbox.append(autopilot_version(self._mav, self.spec, self.system_id))
        elif number == _R.MAVLINK_MSG_ID_EXTENDED_SYS_STATE:
            self.outbox.append(extended_sys_state(
                self._mav, fixed_wing=not self.spec.can_hover, in_air=self.in_air(state)))
        else:
            return int(_R.MAV_RESULT_DENIED)
        return int(_R.MAV_RESULT_ACCEPTED)

    def _cmd_change_heading(self, kind: float, heading_deg: float, accel: float, t_s: float) -> int:
        if self.mode.behaviour is not Behaviour.GUIDED:
            return int(_R.MAV_RESULT_FAILED)
        if not finite(kind, heading_deg, accel) or not 0.0 <= heading_deg < 360.0:
            return int(_R.MAV_RESULT_DENIED)
        if int(kind) == _R.HEADING_TYPE_DEFAULT:
            self._follow("", None, t_s)
            return int(_R.MAV_RESULT_ACCEPTED)
        if int(kind) not in (_R.HEADING_TYPE_COURSE_OVER_GROUND, _R.HEADING_TYPE_HEADING):
            return int(_R.MAV_RESULT_DENIED)
        over_ground = int(kind) == _R.HEADING_TYPE_COURSE_OVER_GROUND
        # ArduPlane turns at ~72% of what its roll predicts (heading_accel_ratio), and rolls
        # GUIDED_P times the course error, clipped at atan(p3 / g) and its roll limit (the
        # measured model; the ideal one closes the stub's own course loop)
        ratio = self.config.model_value("heading_accel_ratio")
        command = FollowCourse(math.radians(heading_deg), over_ground=over_ground,
                               accel_limit_m_s2=ratio * max(accel, 0.05), since_s=t_s,
                               roll_gain=self.config.heading_roll_gain,
                               roll_limit_rad=self.config.roll_limit_rad,
                               turn_ratio=ratio)  # fmt: skip
        label = "following course" if over_ground else "following heading"
        self._follow(label, command, t_s)
        return int(_R.MAV_RESULT_ACCEPTED)

    def _on_data_stream(self, msg: Message, t_s: float, state: VehicleState) -> None:
        if not self._for_us(msg):
            return
        if not self.spec.supports_data_streams:
            self._notice("REQUEST_DATA_STREAM unsupported", t_s)
            return
        rate = int(msg.req_message_rate)
        if rate > self.scheduler.max_rate_hz:
            self._notice(f"Stream rate limited to {self.scheduler.max_rate_hz:g} Hz", t_s)
        if not self.scheduler.request_data_stream(int(msg.req_stream_id), rate,
                                                  bool(msg.start_stop), t_s):
            self._notice(f"Data stream {int(msg.req_stream_id)} unsupported", t_s)

    def _on_timesync(self, msg: Message, t_s: float, state: VehicleState) -> None:
        if int(msg.tc1) == 0:
            self.outbox.append(self._mav.timesync_encode(int(t_s * 1e9), int(msg.ts1)))

    def parameters(self) -> dict[str, float]:
        """The parameters the stub answers for: its setpoint timeout, under the imitated
        autopilot's name (ArduCopter GUID_TIMEOUT, PX4 COM_OF_LOSS_T), and ArduCopter's
        velocity shaping (WPNAV_ACCEL in cm/s/s, PSC_JERK_XY in m/s/s/s) where it is
        modelled; ArduPlane's heading loop gain (GUIDED_P, cd/rad) and roll limit
        (ROLL_LIMIT_DEG) where it is (its course command has no timeout)."""
        timeout = self.config.timeout_s("setpoint")
        if self.spec.profile is Profile.PX4:
            return {"COM_OF_LOSS_T": timeout}
        if self.spec.profile is Profile.COPTER:
            shaping = self.config.velocity_shaping()
            if shaping is None:
                return {"GUID_TIMEOUT": timeout}
            return {"GUID_TIMEOUT": timeout, "WPNAV_ACCEL": 100.0 * shaping.accel_max_m_s2,
                    "PSC_JERK_XY": shaping.jerk_max_m_s3}
        gain = self.config.heading_roll_gain
        if gain is None:
            return {}
        return {"GUIDED_P": 100.0 * math.degrees(gain),
                "ROLL_LIMIT_DEG": math.degrees(self.config.roll_limit_rad)}

    def _on_param_request_read(self, msg: Message, t_s: float, state: VehicleState) -> None:
        if not self._for_us(msg):
            return
        name = msg.param_id
        name = (name.decode("ascii", "replace") if isinstance(name, bytes) else str(name))
        name = name.rstrip("\x00")
        params = self.parameters()
        if name in params:  # an unknown name gets no answer, as on ArduPilot
            self.outbox.append(self._mav.param_value_encode(
                name.encode("ascii"), params[name], _R.MAV_PARAM_TYPE_REAL32, len(params),
                sorted(params).index(name)))
