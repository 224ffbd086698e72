"""The MAVLink wire: the one package of the project that imports pymavlink.

Everything that touches MAVLink bytes goes through here: opening a connection from a
pymavlink URL (``udpout:127.0.0.1:14550``, ``udpin:0.0.0.0:14550``, ``tcpin:...``,
``tcp:...``), MAVLink 2 signing, the wire units (degE7, mm, cm/s, cdeg, ms, us), geodetic
positions to and from local NED (pymap3d) and the encoding of the guidance setpoints a
companion sends. The rest of the project works in SI units and radians (see
:mod:`ezcompanion.frames`) and converts only here.

One idea per module: ``dialect`` (pymavlink loaded as MAVLink 2, ``ardupilotmega``),
``units`` (wire units, geodetic conversions on WGS84), ``projection`` (each autopilot's own
map from latitude/longitude to its local frame), ``signing``, ``link`` (the connection),
``logs`` (a telemetry log read back) and ``commands`` (setpoints and modes). Importing the
package sets ``MAVLINK20=1`` for the process before pymavlink is loaded, as pymavlink
chooses its wire version from that variable.
"""

from __future__ import annotations

from ezcompanion.wire.commands import (
    ATTITUDE_TARGET_IGNORE_ALL_BUT_ROLL,
    POSITION_TARGET_VELOCITY,
    POSITION_TARGET_VELOCITY_YAW_RATE,
    course_command,
    enum_name,
    guided_mode,
    is_autopilot_heartbeat,
    is_fixed_wing,
    is_ground_vehicle,
    mode_name,
    mode_parameters,
    roll_setpoint,
    velocity_setpoint,
)
from ezcompanion.wire.dialect import Address, Message, mavlink, mavutil
from ezcompanion.wire.link import URL_SCHEMES, Frame, Link, LinkStats, is_serial_device, open_link
from ezcompanion.wire.projection import Projection, geodetic_to_local
from ezcompanion.wire.signing import (
    signing_key_from_file,
    signing_key_from_hex,
    signing_key_from_passphrase,
)
from ezcompanion.wire.units import (
    cdeg_to_rad,
    cm_s_to_m_s,
    deg_to_e7,
    e7_to_deg,
    euler_from_quaternion,
    geodetic_to_ned,
    heading_cdeg,
    heading_deg_0_360,
    is_finite,
    m_s_to_cm_s,
    m_to_mm,
    mm_to_m,
    ms_to_s,
    ned_to_geodetic,
    quaternion_from_euler,
    s_to_ms,
    s_to_us,
    us_to_s,
)

__all__ = [
    "ATTITUDE_TARGET_IGNORE_ALL_BUT_ROLL",
    "POSITION_TARGET_VELOCITY",
    "POSITION_TARGET_VELOCITY_YAW_RATE",
    "URL_SCHEMES",
    "Address",
    "Frame",
    "Link",
    "LinkStats",
    "Message",
    "Projection",
    "cdeg_to_rad",
    "cm_s_to_m_s",
    "course_command",
    "deg_to_e7",
    "e7_to_deg",
    "enum_name",
    "euler_from_quaternion",
    "geodetic_to_local",
    "geodetic_to_ned",
    "guided_mode",
    "heading_cdeg",
    "heading_deg_0_360",
    "is_autopilot_heartbeat",
    "is_finite",
    "is_fixed_wing",
    "is_ground_vehicle",
    "is_serial_device",
    "m_s_to_cm_s",
    "m_to_mm",
    "mavlink",
    "mavutil",
    "mm_to_m",
    "mode_name",
    "mode_parameters",
    "ms_to_s",
    "ned_to_geodetic",
    "open_link",
    "quaternion_from_euler",
    "roll_setpoint",
    "s_to_ms",
    "s_to_us",
    "signing_key_from_file",
    "signing_key_from_hex",
    "signing_key_from_passphrase",
    "us_to_s",
    "velocity_setpoint",
]
