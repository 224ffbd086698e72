"""What a companion sends (velocity, course and roll setpoints) and what it reads from a
HEARTBEAT (the flight mode, the guided mode to ask for, the vehicle class), from pymavlink's
own tables."""

from __future__ import annotations

from ezcompanion.wire.dialect import Message, mavlink, mavutil
from ezcompanion.wire.link import Link
from ezcompanion.wire.units import heading_deg_0_360, quaternion_from_euler

# SET_POSITION_TARGET_*: bits set mean "ignore" (POSITION_TARGET_TYPEMASK).
_PT = mavlink
POSITION_TARGET_VELOCITY = (
    _PT.POSITION_TARGET_TYPEMASK_X_IGNORE
    | _PT.POSITION_TARGET_TYPEMASK_Y_IGNORE
    | _PT.POSITION_TARGET_TYPEMASK_Z_IGNORE
    | _PT.POSITION_TARGET_TYPEMASK_AX_IGNORE
    | _PT.POSITION_TARGET_TYPEMASK_AY_IGNORE
    | _PT.POSITION_TARGET_TYPEMASK_AZ_IGNORE
    | _PT.POSITION_TARGET_TYPEMASK_YAW_IGNORE
    | _PT.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
)  # 0x0DC7 = 3527: velocity only
POSITION_TARGET_VELOCITY_YAW_RATE = (
    POSITION_TARGET_VELOCITY & ~_PT.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
)  # 0x05C7 = 1479: velocity and yaw rate
#: SET_ATTITUDE_TARGET type_mask ArduPlane reads as "roll angle from q only" (198).
ATTITUDE_TARGET_IGNORE_ALL_BUT_ROLL = (
    _PT.ATTITUDE_TARGET_TYPEMASK_BODY_PITCH_RATE_IGNORE
    | _PT.ATTITUDE_TARGET_TYPEMASK_BODY_YAW_RATE_IGNORE
    | _PT.ATTITUDE_TARGET_TYPEMASK_THROTTLE_IGNORE
    | _PT.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE
)


def velocity_setpoint(
    link: Link,
    *,
    target_system: int,
    target_component: int,
    time_boot_ms: int,
    north_m_s: float,
    east_m_s: float,
    down_m_s: float = 0.0,
    yaw_rate_rad_s: float | None = None,
    body_frame: bool = False,
    horizontal_only: bool = False,
) -> Message:
    """SET_POSITION_TARGET_LOCAL_NED carrying a velocity (and optionally a yaw rate).

    With ``body_frame`` the first two components are forward and right (MAV_FRAME_BODY_NED).
    ``horizontal_only`` also marks vz as ignored, as ArduRover documents for ground vehicles
    (type_mask 1511 with a yaw rate, instead of 1479).
    """
    mask = POSITION_TARGET_VELOCITY if yaw_rate_rad_s is None else POSITION_TARGET_VELOCITY_YAW_RATE
    if horizontal_only:
        mask |= _PT.POSITION_TARGET_TYPEMASK_VZ_IGNORE
    frame = mavlink.MAV_FRAME_BODY_NED if body_frame else mavlink.MAV_FRAME_LOCAL_NED
    return link.mav.set_position_target_local_ned_encode(
        time_boot_ms,
        target_system,
        target_component,
        frame,
        mask,
        0.0,
        0.0,
        0.0,
        north_m_s,
        east_m_s,
        down_m_s,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0 if yaw_rate_rad_s is None else yaw_rate_rad_s,
    )


def course_command(
    link: Link,
    *,
    target_system: int,
    target_component: int,
    course_rad: float,
    accel_limit_m_s2: float,
    heading: bool = False,
) -> Message:
    """ArduPlane's MAV_CMD_GUIDED_CHANGE_HEADING as COMMAND_INT (course over ground or heading)."""
    kind = mavlink.HEADING_TYPE_HEADING if heading else mavlink.HEADING_TYPE_COURSE_OVER_GROUND
    return link.mav.command_int_encode(
        target_system,
        target_component,
        mavlink.MAV_FRAME_GLOBAL,
        mavlink.MAV_CMD_GUIDED_CHANGE_HEADING,
        0,
        0,
        float(kind),
        heading_deg_0_360(course_rad),
        accel_limit_m_s2,
        0.0,
        0,
        0,
        0.0,
    )


def roll_setpoint(
    link: Link,
    *,
    target_system: int,
    target_component: int,
    time_boot_ms: int,
    roll_rad: float,
) -> Message:
    """SET_ATTITUDE_TARGET with only the roll angle (type_mask 198, as ArduPlane reads it)."""
    return link.mav.set_attitude_target_encode(
        time_boot_ms,
        target_system,
        target_component,
        ATTITUDE_TARGET_IGNORE_ALL_BUT_ROLL,
        quaternion_from_euler(roll_rad, 0.0, 0.0),
        0.0,
        0.0,
        0.0,
        0.0,
    )


def enum_name(enum: str, value: int) -> str:
    """``value`` of MAVLink enum ``enum`` as the standard names it, with its number
    ("MAV_RESULT_FAILED (4)"); the number alone where the dialect has no such entry."""
    entry = mavlink.enums.get(enum, {}).get(int(value))
    return f"{entry.name} ({int(value)})" if entry is not None else f"{enum} {int(value)}"


def mode_name(heartbeat: Message) -> str:
    """The flight mode a HEARTBEAT reports, as the autopilot names it ("GUIDED", "OFFBOARD")."""
    return str(mavutil.mode_string_v10(heartbeat))


def mode_parameters(heartbeat: Message, name: str) -> tuple[float, float, float] | None:
    """The parameters of MAV_CMD_DO_SET_MODE that ask the autopilot that sent ``heartbeat``
    for mode ``name`` (as pymavlink's tables spell it: "GUIDED", "BRAKE", "OFFBOARD",
    "AUTO.LOITER"); None if it has no such mode.

    ArduPilot: (MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, custom_mode, 0). PX4: (base mode, main
    mode, sub mode), as PX4's commander reads the command.
    """
    if heartbeat.autopilot == mavlink.MAV_AUTOPILOT_PX4:
        if name not in mavutil.px4_map:
            return None
        base_mode, main_mode, sub_mode = mavutil.px4_map[name]
        return float(base_mode), float(main_mode), float(sub_mode)
    number = (mavutil.mode_mapping_byname(heartbeat.type) or {}).get(name)
    if number is None:
        return None
    return float(mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED), float(number), 0.0


def guided_mode(heartbeat: Message) -> tuple[str, float, float, float] | None:
    """The mode in which this autopilot follows a companion's setpoints (GUIDED; OFFBOARD on
    PX4), with the parameters of MAV_CMD_DO_SET_MODE that ask for it:
    ``(name, param1, param2, param3)``. None if the vehicle type has no such mode."""
    name = "OFFBOARD" if heartbeat.autopilot == mavlink.MAV_AUTOPILOT_PX4 else "GUIDED"
    params = mode_parameters(heartbeat, name)
    return None if params is None else (name, *params)


def is_ground_vehicle(heartbeat: Message) -> bool:
    """The vehicle drives or sails on a surface (no vertical velocity to command)."""
    return bool(heartbeat.type in (mavlink.MAV_TYPE_GROUND_ROVER, mavlink.MAV_TYPE_SURFACE_BOAT))


def is_autopilot_heartbeat(heartbeat: Message) -> bool:
    """An autopilot's heartbeat (a ground station's or a companion's is no vehicle's)."""
    return heartbeat.type not in (mavlink.MAV_TYPE_GCS, mavlink.MAV_TYPE_ONBOARD_CONTROLLER) and (
        heartbeat.autopilot != mavlink.MAV_AUTOPILOT_INVALID)


def is_fixed_wing(heartbeat: Message) -> bool:
    """The vehicle flies on wings (it cannot stop, and turns by banking)."""
    return bool(heartbeat.type in (mavlink.MAV_TYPE_FIXED_WING, mavlink.MAV_TYPE_FLAPPING_WING))
