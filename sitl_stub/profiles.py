"""What each autopilot the stub stands in for looks like on the wire.

ArduPilot numbers its flight modes in HEARTBEAT.custom_mode (Copter GUIDED = 4, Plane
GUIDED = 15). PX4 packs a main mode into bits 16-23 and a sub mode into bits 24-31
(OFFBOARD = main mode 6). Each mode of the stub maps to one of three behaviours of the
vehicle model: follow guidance setpoints, cruise straight on, or hold (a copter stops and
hovers, a plane circles).
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

from sitl_stub.mav import mav as mavlink

__all__ = ["Behaviour", "ModeSpec", "Profile", "ProfileSpec", "profile_spec"]


class Profile(enum.StrEnum):
    """The autopilot being imitated."""

    COPTER = "copter"  # ArduCopter
    PLANE = "plane"  # ArduPlane
    PX4 = "px4"  # PX4 multicopter


class Behaviour(enum.Enum):
    """What the vehicle does in a mode."""

    GUIDED = "guided"  # follows the companion's setpoints
    CRUISE = "cruise"  # flies straight on at cruise speed
    HOLD = "hold"  # copter: stops and hovers; plane: circles at the loiter radius


@dataclass(frozen=True)
class ModeSpec:
    """One flight mode: its name, its HEARTBEAT.custom_mode and what the vehicle does."""

    name: str
    custom_mode: int
    behaviour: Behaviour


@dataclass(frozen=True, kw_only=True)
class ProfileSpec:
    """Everything that differs between the imitated autopilots.

    Timeouts are in simulated seconds; 0 means "no timeout".
    """

    profile: Profile
    mav_type: int
    autopilot: int
    modes: tuple[ModeSpec, ...]
    guided_mode: str
    initial_mode: str
    failsafe_mode: str | None  # mode entered when guided setpoints stop (PX4), else None
    max_stream_rate_hz: float
    setpoint_timeout_s: float  # velocity / yaw-rate setpoints
    attitude_timeout_s: float  # SET_ATTITUDE_TARGET
    course_timeout_s: float  # GUIDED_CHANGE_HEADING
    accepts_velocity: bool  # SET_POSITION_TARGET_LOCAL_NED velocities
    accepts_course_command: bool  # MAV_CMD_GUIDED_CHANGE_HEADING
    ardupilot_attitude_mask: bool  # SET_ATTITUDE_TARGET type_mask read as ArduPlane does
    supports_data_streams: bool  # REQUEST_DATA_STREAM
    can_hover: bool
    # as a UDP client (the stub's ``udpout:``), whether it hears its peer alone: ArduPilot
    # SITL's ``udpclient:`` connects its socket (AP_HAL_SITL/UARTDriver.cpp,
    # ``_udp_start_client``), so the kernel drops every other sender's datagram; PX4's
    # receiver (mavlink_receiver.cpp) parses whatever reaches its port
    udp_client_hears_only_peer: bool
    # the measured response (docs/sitl_stub.md, "Measured response models")
    velocity_lag_s: float  # flown velocity direction behind the setpoint's (first order)
    shaping_accel_m_s2: float | None  # velocity shaped as ArduCopter's (WPNAV_ACCEL), or None
    tracking_lag_s: float  # with shaping: the vehicle's velocity behind the shaped reference
    speed_ratio: float  # flown / commanded speed (plane: ground speed / cruise airspeed)
    heading_accel_ratio: float  # flown / commanded lateral acceleration of a course command
    # ArduPlane's GUIDED heading loop (measured model): a roll of this times the course
    # error (GUIDED_P, 5000 cd/rad), within the roll limit (LIM_ROLL_CD, 4500 cd); None: the
    # stub's own course loop (course_gain_1_s)
    heading_roll_gain: float | None = None
    roll_limit_rad: float = math.radians(45.0)
    # the most the bank turns a second (measured model; 0: at once): ArduPlane 4.5.1 SITL's
    # ATTITUDE rolled at 1.29 rad/s at most in a 67 s engagement with reversals (p99 0.86)
    roll_rate_max_rad_s: float = 0.0
    vz_hold_drift_m_s: float  # climb while told vz = 0 without a height (up)
    failsafe_descent_m_s: float  # descent after the offboard-loss failsafe (no RC)
    acks_twice: bool  # every COMMAND_ACK is sent twice (PX4 v1.16)
    firmware: tuple[int, int, int, int]  # AUTOPILOT_VERSION: major, minor, patch, type
    aliases: tuple[tuple[str, str], ...] = ()  # other names a mode is known by

    def mode_by_name(self, name: str) -> ModeSpec | None:
        """The mode called ``name`` (case-insensitive, or an alias), if this autopilot has one."""
        wanted = name.upper()
        wanted = dict(self.aliases).get(wanted, wanted)
        for mode in self.modes:
            if mode.name == wanted:
                return mode
        return None

    def mode_by_number(self, custom_mode: int) -> ModeSpec | None:
        """The mode whose HEARTBEAT.custom_mode is ``custom_mode``."""
        for mode in self.modes:
            if mode.custom_mode == custom_mode:
                return mode
        return None


def px4_custom_mode(main_mode: int, sub_mode: int = 0) -> int:
    """PX4's HEARTBEAT.custom_mode: main mode in bits 16-23, sub mode in bits 24-31."""
    return (main_mode << 16) | (sub_mode << 24)


_G, _C, _H = Behaviour.GUIDED, Behaviour.CRUISE, Behaviour.HOLD

_COPTER = ProfileSpec(
    profile=Profile.COPTER,
    mav_type=mavlink.MAV_TYPE_QUADROTOR,
    autopilot=mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
    modes=(
        ModeSpec("STABILIZE", 0, _C), ModeSpec("ALT_HOLD", 2, _C), ModeSpec("AUTO", 3, _C),
        ModeSpec("GUIDED", 4, _G), ModeSpec("LOITER", 5, _H), ModeSpec("BRAKE", 17, _H),
    ),
    guided_mode="GUIDED", initial_mode="AUTO", failsafe_mode=None,
    max_stream_rate_hz=200.0, setpoint_timeout_s=3.0, attitude_timeout_s=3.0, course_timeout_s=0.0,
    accepts_velocity=True, accepts_course_command=False, ardupilot_attitude_mask=False,
    supports_data_streams=True, can_hover=True, udp_client_hears_only_peer=True,
    # WPNAV_ACCEL 2.5 m/s^2 and PSC_JERK_XY 5 m/s^3 (shaping 0.5 s) + 0.1 s tracking: the
    # course flies 0.54 to 0.59 s behind (docs/sitl_stub.md), taken as 0.6
    velocity_lag_s=0.6, shaping_accel_m_s2=2.5, tracking_lag_s=0.1,
    speed_ratio=1.0, heading_accel_ratio=1.0, vz_hold_drift_m_s=0.0,
    failsafe_descent_m_s=0.0, acks_twice=False, firmware=(4, 7, 0, 0),
)

_PLANE = ProfileSpec(
    profile=Profile.PLANE,
    mav_type=mavlink.MAV_TYPE_FIXED_WING,
    autopilot=mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
    modes=(
        ModeSpec("MANUAL", 0, _C), ModeSpec("CIRCLE", 1, _H), ModeSpec("FBWA", 5, _C),
        ModeSpec("CRUISE", 7, _C), ModeSpec("AUTO", 10, _C), ModeSpec("LOITER", 12, _H),
        ModeSpec("GUIDED", 15, _G),
    ),
    guided_mode="GUIDED", initial_mode="AUTO", failsafe_mode=None,
    max_stream_rate_hz=40.0, setpoint_timeout_s=0.0, attitude_timeout_s=3.0, course_timeout_s=0.0,
    accepts_velocity=False, accepts_course_command=True, ardupilot_attitude_mask=True,
    supports_data_streams=True, can_hover=False, udp_client_hears_only_peer=True,
    velocity_lag_s=0.0, shaping_accel_m_s2=None, tracking_lag_s=0.0,
    speed_ratio=23.4 / 22.0, heading_accel_ratio=0.73, vz_hold_drift_m_s=0.0,
    failsafe_descent_m_s=0.0, acks_twice=False, firmware=(4, 7, 0, 0),
    heading_roll_gain=math.radians(50.0),  # GUIDED_P 5000 cd/rad: 50 degrees per radian
    roll_rate_max_rad_s=1.3,  # 74 deg/s: ArduPlane 4.5.1 SITL's most (docs/sitl_stub.md)
)

_PX4 = ProfileSpec(
    profile=Profile.PX4,
    mav_type=mavlink.MAV_TYPE_QUADROTOR,
    autopilot=mavlink.MAV_AUTOPILOT_PX4,
    modes=(
        ModeSpec("POSCTL", px4_custom_mode(3), _H),
        ModeSpec("LOITER", px4_custom_mode(4, 3), _H),  # 0x03040000, pymavlink's name
        ModeSpec("MISSION", px4_custom_mode(4, 4), _C),
        ModeSpec("OFFBOARD", px4_custom_mode(6), _G),
    ),
    aliases=(("AUTO.LOITER", "LOITER"), ("AUTO.MISSION", "MISSION")),
    guided_mode="OFFBOARD", initial_mode="MISSION", failsafe_mode="POSCTL",
    max_stream_rate_hz=200.0, setpoint_timeout_s=1.0, attitude_timeout_s=1.0, course_timeout_s=0.0,
    accepts_velocity=True, accepts_course_command=False, ardupilot_attitude_mask=False,
    supports_data_streams=False, can_hover=True, udp_client_hears_only_peer=False,
    velocity_lag_s=1.2, shaping_accel_m_s2=None, tracking_lag_s=0.0,
    speed_ratio=0.8, heading_accel_ratio=1.0, vz_hold_drift_m_s=0.1,
    failsafe_descent_m_s=0.8, acks_twice=True, firmware=(1, 16, 0, 255),
)

_SPECS = {spec.profile: spec for spec in (_COPTER, _PLANE, _PX4)}


def profile_spec(profile: Profile) -> ProfileSpec:
    """The built-in description of ``profile``."""
    return _SPECS[profile]
