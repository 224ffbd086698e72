"""What each autopilot does with the companion's setpoints, as measured: how fast the
vehicle responds, and what it flies when the setpoints stop.

Figures (issues 9 and 11, ArduCopter and ArduPlane V4.7.0-dev SITL, PX4 v1.16 SIH):

- ArduCopter: the flown course rate lags the commanded one by 0.54 to 0.59 s (4.5.6 SITL,
  WPNAV_ACCEL / PSC_JERK_XY = 0.5 s of velocity shaping and about 0.1 s of tracking; 0.6 s
  taken); with no new setpoint it flies the last velocity for its GUIDED timeout
  (GUID_TIMEOUT, 3 s), then brakes through the same shaping: at 2 m/s it stopped 7.6 m
  from the last setpoint, where braking at WPNAV_ACCEL (2.5 m/s^2) from the timeout on
  gives 6.8 m. The shaping's stopping distance is at most v * (A / J + 0.1 s) + v^2 / (2 A)
  (A = WPNAV_ACCEL, J = PSC_JERK_XY: ``brake_delay_s`` 0.6 s by default, read with the
  timeout where the vehicle answers).
- PX4 multicopter: velocity setpoints lag by 0.9 to 1.4 s (1.2 s taken) and it flies 0.78
  to 0.80 of the commanded speed; offboard loss after 1.04 to 1.15 s (COM_OF_LOSS_T 1.0 s),
  then a failsafe to POSCTL, which brakes (MPC_ACC_HOR 3 m/s^2) and, with no RC, descends.
  The velocity setpoints cancel the 1.2 s lag (``setpoint_lead_s``: the direction leads
  the course by omega * 1.2 s, the inverse of a first-order lag), so the law is given
  only what remains, 0.3 s (telemetry age and a tick, with room for the 0.9-1.4 s spread).
  On the measured stub this flies both paper scenarios outside every zone, where the law
  told the full 1.2 s and a 30-degree lead clamp entered two zones (scenario 2).
- ArduPlane: a course command is flown until another comes, for ever; the law takes a
  configured horizon of 10 s (long enough for a person to take over), the turn to the
  commanded course (2 to 6 s of turning ahead) first. Roll response lag 0.4 to 0.6 s. With
  the roll clip of a GUIDED_CHANGE_HEADING limit binding, it turns at 0.72 to 0.73 of what
  the limit asks (4.5.1 SITL; ``turn_ratio`` 0.73: the course setpoints' outer loop starts
  from 1 / 0.73); with the course only 2 s ahead the clip did not bind and it turned at
  0.51 to 0.54 of it.

The law uses ``response_lag_s`` unless the scenario states its own. With
``companion.abandon_check`` (off by default) or a scenario's own ``abandon_hold_s``, every
setpoint is checked against the abandon path (the turn, the hold, the braking); the hold is
the vehicle's own timeout parameter where it answers for it (``timeout_parameter``, read at
discovery), plus what it was measured to overshoot by. At the paper's scale ArduCopter's
default 3 s leaves no room to intercept (docs/guidance.md, "Safe to abandon").
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace

from ezcompanion.guidance.scaling import GRAVITY_M_S2
from ezcompanion.wire import Message, is_fixed_wing, mavlink

__all__ = ["AutopilotProfile", "autopilot_profile"]


@dataclass(frozen=True, kw_only=True)
class AutopilotProfile:
    """An autopilot's measured response and what it flies when the setpoints stop."""

    name: str
    response_lag_s: float
    # the law's lead on that lag (``GuidanceParams.intercept_lead_ratio``), given with it;
    # None: the scenario's
    intercept_lead_ratio: float | None = None
    setpoint_lead_s: float = 0.0
    turn_ratio: float = 1.0
    abandon_turn_s: float
    abandon_hold_s: float
    abandon_brake_m_s2: float
    # the parameter that sets the hold, and how much longer than it the vehicle was seen to
    # hold (s); None: no such parameter
    timeout_parameter: str | None = None
    timeout_overshoot_s: float = 0.0
    # braking that starts late: ArduCopter's velocity shaping stops the vehicle within
    # v * delay + v^2 / (2 brake), delay = WPNAV_ACCEL / PSC_JERK_XY + the tracking lag
    brake_delay_s: float = 0.0
    shaping_parameters: tuple[str, str] | None = None  # (accel in cm/s/s, jerk in m/s^3)
    tracking_lag_s: float = 0.0
    # ArduPlane's GUIDED heading loop: a roll of this times the course error (rad/rad), and
    # the parameter that sets it (GUIDED_P, in cd/rad); None: no such loop
    heading_roll_gain: float | None = None
    heading_gain_parameter: str | None = None
    # ... and the roll it clips that demand at (rad), with its parameter (ROLL_LIMIT_DEG, in
    # degrees); pi / 2: none
    roll_limit_rad: float = 0.5 * math.pi
    roll_limit_parameter: str | None = None
    # the tilt (a plane's bank) the autopilot flies at most by default (rad): the telemetry's
    # estimate gate takes at least what it allows as its bound (``manoeuvre_accel_m_s2``).
    # Its default, not the vehicle's answer: a parameter's reply carries no proof of who
    # sent it on an unsigned link, and a reviewer's forged ANGLE_MAX had widened the bound
    # tenfold (a vehicle set to tilt further needs companion.gate_accel_m_s2)
    tilt_limit_rad: float
    # ... times this: what was measured beyond g tan(the tilt flown)
    manoeuvre_margin: float = 1.0

    @property
    def manoeuvre_accel_m_s2(self) -> float:
        """The most horizontal acceleration the vehicle flies under its autopilot: g tan of
        its tilt limit (a copter's thrust tilted, a plane's bank). A vehicle seen to
        accelerate harder than the estimate gate's bound is refused: ArduCopter 4.5.1 SITL
        braked at 2.5 to 2.8 m/s^2 (WPNAV_ACCEL) and rode SITL's turbulence at 4.1, where
        the paper's scale had given the gate a bound of 2 (twice its accel_max). ArduPlane
        4.5.1 SITL's horizontal acceleration in GUIDED_CHANGE_HEADING turns was 1.0 to 1.46
        times g tan(the bank it flew), up to 36 m/s^2 at 68.5 degrees (ROLL_LIMIT_DEG 65)
        where the companion's own turns reached 8.2 m/s^2 (accel_max 4.5)."""
        return self.manoeuvre_margin * GRAVITY_M_S2 * math.tan(self.tilt_limit_rad)

    @property
    def steering_parameter_names(self) -> tuple[str, ...]:
        """The parameters the setpoints are shaped by (read whether or not the abandon
        check is on): the heading loop's gain and roll limit."""
        return tuple(n for n in (self.heading_gain_parameter, self.roll_limit_parameter)
                     if n is not None)

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """The parameters the abandon path and the setpoints are read from."""
        timeout = () if self.timeout_parameter is None else (self.timeout_parameter,)
        return timeout + (self.shaping_parameters or ()) + self.steering_parameter_names

    @property
    def abandon_straight_s(self) -> float:
        """The straight part of the abandon path given to the law: the hold, and the late
        start of the braking (stopping distance v * (hold + delay) + v^2 / (2 brake))."""
        return self.abandon_hold_s + self.brake_delay_s

    def with_parameters(self, values: Mapping[str, float]) -> AutopilotProfile:
        """This profile with the hold the vehicle's own timeout parameter gives, the
        braking its shaping parameters give and the roll gain and limit of its heading
        loop, where it answered for them."""
        profile = self
        gain = self.heading_gain_parameter
        if gain is not None and gain in values:  # cd/rad: a hundredth of a degree per radian
            profile = replace(profile, heading_roll_gain=math.radians(values[gain] / 100.0))
        limit = self.roll_limit_parameter
        if limit is not None and limit in values:  # degrees
            profile = replace(profile, roll_limit_rad=math.radians(values[limit]))
        name = self.timeout_parameter
        if name is not None and name in values:
            profile = replace(profile, abandon_hold_s=values[name] + self.timeout_overshoot_s)
        if self.shaping_parameters is not None and all(
                n in values for n in self.shaping_parameters):
            accel_cm, jerk = (values[n] for n in self.shaping_parameters)
            brake = accel_cm / 100.0
            profile = replace(profile, abandon_brake_m_s2=brake,
                              brake_delay_s=brake / jerk + self.tracking_lag_s)
        return profile


# ArduPlane's GUIDED_P by default: 5000 cd/rad, a roll of 50 degrees per radian of course error
GUIDED_P_DEFAULT_RAD_PER_RAD = math.radians(50.0)

ARDUCOPTER = AutopilotProfile(
    name="ArduCopter", response_lag_s=0.6, abandon_turn_s=0.0, abandon_hold_s=3.0,
    abandon_brake_m_s2=2.5, timeout_parameter="GUID_TIMEOUT", brake_delay_s=0.6,
    shaping_parameters=("WPNAV_ACCEL", "PSC_JERK_XY"), tracking_lag_s=0.1,
    tilt_limit_rad=math.radians(30.0),  # ANGLE_MAX 3000 cdeg
)  # fmt: skip
PX4_COPTER = AutopilotProfile(
    name="PX4", response_lag_s=0.3, setpoint_lead_s=1.2, abandon_turn_s=0.0, abandon_hold_s=1.15,
    abandon_brake_m_s2=3.0, timeout_parameter="COM_OF_LOSS_T", timeout_overshoot_s=0.15,
    tilt_limit_rad=math.radians(45.0),  # MPC_TILTMAX_AIR
)  # fmt: skip
# (no lead on the lag: the lead is made for a first-order lag, which a plane's course loop
# is not, and the loopback plane with it circled the target through paper scenario 1's
# 30 s, where without it it intercepted at 26.8 s; docs/guidance.md, "The nominal's lead")
ARDUPLANE = AutopilotProfile(
    name="ArduPlane", response_lag_s=1.0, intercept_lead_ratio=0.0, turn_ratio=0.73,
    abandon_turn_s=6.0, abandon_hold_s=4.0, abandon_brake_m_s2=0.0,
    heading_gain_parameter="GUIDED_P", heading_roll_gain=GUIDED_P_DEFAULT_RAD_PER_RAD,
    roll_limit_rad=math.radians(45.0), roll_limit_parameter="ROLL_LIMIT_DEG",
    tilt_limit_rad=math.radians(45.0),
    manoeuvre_margin=1.5,  # (ROLL_LIMIT_DEG's default)
)  # fmt: skip


def autopilot_profile(heartbeat: Message) -> AutopilotProfile:
    """The profile for the vehicle that sent ``heartbeat``."""
    if is_fixed_wing(heartbeat):
        return ARDUPLANE
    if heartbeat.autopilot == mavlink.MAV_AUTOPILOT_PX4:
        return PX4_COPTER
    return ARDUCOPTER
