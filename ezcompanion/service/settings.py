"""The companion's settings: the optional ``companion:`` section of a scenario file, then flags.

Layout (every key optional)::

    companion:
      connect: udpin:127.0.0.1:14550 # pymavlink URL; udpout:, tcp:, tcpin:, /dev/ttyACM0,57600
      system_id: 1                   # ours; the usual companion shares the vehicle's system
      component_id: 191              # MAV_COMP_ID_ONBOARD_COMPUTER
      target_system: 0               # the vehicle; 0 = the first autopilot heard
      target_component: 0            # 0 = the component that sent that heartbeat
      loop_rate_hz: 50.0             # guidance ticks per second (at most the rate
                                     # positions are asked at: 25 Hz on a plane)
      telemetry_rate_hz: 50.0        # what is requested of each streamed message
      setpoint: auto                 # auto | velocity | course (see docs/service.md)
      stale_after_s: 0.25            # position older than this is never fed to the law
      link_lost_after_s: 3.0         # no heartbeat for this long: link lost
      engage: false                  # ask for GUIDED/OFFBOARD ourselves
      abandon_check: false           # check every setpoint is safe to keep flying if it is
                                     # the last (the autopilot's timeout read from it)
      on_exit: default               # hold | loiter | rtl | none | default (per vehicle class)
      accept_soft_heading_loop: false  # fly a plane whose GUIDED_P cannot fly the law's
                                     # hardest turn (a warning, not a refusal: the safety
                                     # argument then does not hold)
      gate_position_m: 0.5           # estimate gate: position innovation allowed (<= 25)
      gate_accel_m_s2: 0.0           # the gate's acceleration bound (<= 50); 0 = 2 x
                                     # accel_max, at least what the autopilot flies
      distrust_give_up_s: 3.0        # untrusted input this long without a break ends guidance
      signing_key_hex: null          # 64 hex digits: sign, refuse unsigned input
      signing_key_file: null         # or a file holding the 64 hex digits (mode 600)
      signing_passphrase: null       # or a passphrase (key = SHA-256 of it, as MAVProxy)
      allow_unsigned: false          # run unsigned where other machines reach `connect`
                                     # (a warning); false: refuse to start there unsigned

The key may also come from the environment: EZCOMPANION_SIGNING_KEY (64 hex digits) or
EZCOMPANION_SIGNING_PASSPHRASE; never from a command-line value, which ``ps`` shows.
      tlog: null                     # path of the telemetry log (every frame in and out)
      speedup: 1.0                   # the vehicle's clock over wall time (loopback tests)
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

from ezcompanion.config import Scenario, build_dataclass, enum_member
from ezcompanion.endpoint import parse_endpoint
from ezcompanion.errors import ConfigError
from ezcompanion.wire import (
    URL_SCHEMES,
    is_serial_device,
    signing_key_from_file,
    signing_key_from_hex,
    signing_key_from_passphrase,
)

__all__ = [
    "GATE_ACCEL_MAX_M_S2",
    "LOOP_RATE_MIN_HZ",
    "SIGNING_ENV",
    "CompanionSettings",
    "OnExit",
    "SetpointKind",
    "companion_settings",
    "refuse_unsigned",
    "signing_key",
    "unsigned_warning",
]

_ON_EXIT = "hold, loiter, rtl, none or default"
# the estimate gate's widest settings (see CompanionSettings.__post_init__)
_GATE_POSITION_MAX_M = 25.0
GATE_ACCEL_MAX_M_S2 = 50.0
LOOP_RATE_MIN_HZ = 1.0  # the slowest loop: a tick a second

#: Environment variables a signing key may come from (hex key, passphrase).
SIGNING_ENV = ("EZCOMPANION_SIGNING_KEY", "EZCOMPANION_SIGNING_PASSPHRASE")


class SetpointKind(StrEnum):
    """How the lateral acceleration reaches the autopilot."""

    AUTO = "auto"  # from the vehicle's heartbeat: fixed wing -> course, else velocity
    VELOCITY = "velocity"  # SET_POSITION_TARGET_LOCAL_NED velocity + yaw rate (copter, PX4)
    COURSE = "course"  # MAV_CMD_GUIDED_CHANGE_HEADING as COMMAND_INT (ArduPlane)


class OnExit(StrEnum):
    """Where the vehicle is left when the companion stops (``ezcompanion.service.ending``)."""

    DEFAULT = "default"  # by vehicle class: copter and PX4 hold, plane loiter
    HOLD = "hold"  # ArduCopter BRAKE, ArduPlane LOITER, ArduRover HOLD, PX4 AUTO.LOITER
    LOITER = "loiter"  # LOITER (PX4 AUTO.LOITER)
    RTL = "rtl"  # RTL (PX4 AUTO.RTL)
    NONE = "none"  # nothing sent: the autopilot's own timeout decides


@dataclass(frozen=True, kw_only=True)
class CompanionSettings:
    """Validated companion settings (SI units)."""

    connect: str = "udpin:127.0.0.1:14550"
    system_id: int = 1
    component_id: int = 191
    target_system: int = 0
    target_component: int = 0
    loop_rate_hz: float = 50.0
    telemetry_rate_hz: float = 50.0
    setpoint: SetpointKind = SetpointKind.AUTO
    stale_after_s: float = 0.25
    link_lost_after_s: float = 3.0
    engage: bool = False
    abandon_check: bool = False
    on_exit: OnExit = OnExit.DEFAULT
    accept_soft_heading_loop: bool = False
    gate_position_m: float = 0.5
    gate_accel_m_s2: float = 0.0
    distrust_give_up_s: float = 3.0
    signing_key_hex: str | None = None
    signing_key_file: str | None = None
    signing_passphrase: str | None = None
    allow_unsigned: bool = False
    tlog: str | None = None
    speedup: float = 1.0

    def __post_init__(self) -> None:
        for name, low in (
            ("system_id", 1),
            ("component_id", 1),
            ("target_system", 0),
            ("target_component", 0),
        ):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= 255:
                raise ConfigError(name, value, f"must be an integer within [{low}, 255]")
        for name in (
            "loop_rate_hz",
            "telemetry_rate_hz",
            "stale_after_s",
            "link_lost_after_s",
            "speedup",
            "gate_position_m",
            "distrust_give_up_s",
        ):
            value = getattr(self, name)
            if (
                isinstance(value, bool)
                or not isinstance(value, int | float)
                or not (math.isfinite(value) and value > 0.0)
            ):
                raise ConfigError(name, value, "must be a finite number > 0")
        value = self.gate_accel_m_s2
        if (
            isinstance(value, bool)
            or not isinstance(value, int | float)
            or not (math.isfinite(value) and value >= 0.0)
        ):
            raise ConfigError("gate_accel_m_s2", value, "must be a finite number >= 0")
        # Wider than these, the gate is off in all but name (1e9 let any jump through): a
        # position gate wider than the 25 m at which ArduPilot's EKF3 itself gives up on
        # its estimate and resets onto the GPS (EK3_GLITCH_RAD's default), an acceleration
        # bound above 5 g, which no multirotor or small plane reaches.
        for name, most in (("gate_position_m", _GATE_POSITION_MAX_M),
                           ("gate_accel_m_s2", GATE_ACCEL_MAX_M_S2)):  # fmt: skip
            if getattr(self, name) > most:
                raise ConfigError(name, getattr(self, name), f"must be at most {most:g}")
        if not LOOP_RATE_MIN_HZ <= self.loop_rate_hz <= 1000.0:
            raise ConfigError("loop_rate_hz", self.loop_rate_hz,
                              f"must be within [{LOOP_RATE_MIN_HZ:g}, 1000]")
        if self.stale_after_s < 2.0 / self.telemetry_rate_hz:
            raise ConfigError(
                "stale_after_s", self.stale_after_s, "must allow at least two telemetry periods"
            )
        if not isinstance(self.setpoint, SetpointKind):
            raise ConfigError("setpoint", self.setpoint, "must be auto, velocity or course")
        if not isinstance(self.abandon_check, bool):
            raise ConfigError("abandon_check", self.abandon_check, "must be true or false")
        if not isinstance(self.on_exit, OnExit):
            raise ConfigError("on_exit", self.on_exit, f"must be one of {_ON_EXIT}")
        for name in ("engage", "accept_soft_heading_loop", "allow_unsigned"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(name, getattr(self, name), "must be true or false")
        given = [
            name
            for name in ("signing_key_hex", "signing_key_file", "signing_passphrase")
            if getattr(self, name) is not None
        ]
        if len(given) > 1:
            raise ConfigError(given[1], "(hidden)", f"give only one of {', '.join(given)}")
        for name in given:
            if not isinstance(getattr(self, name), str) or not getattr(self, name):
                raise ConfigError(name, "(hidden)", "must be a non-empty string")
        if self.signing_key_hex is not None:
            signing_key_from_hex(self.signing_key_hex)
        if self.connect.split(":", 1)[0] not in URL_SCHEMES and not is_serial_device(self.connect):
            raise ConfigError(
                "connect",
                self.connect,
                "must be a pymavlink URL such as udpin:0.0.0.0:14550 or a serial device "
                "such as /dev/ttyACM0,57600",
            )


def signing_key(
    settings: CompanionSettings, environ: Mapping[str, str] | None = None
) -> bytes | None:
    """The signing key: from the settings (hex, file or passphrase), else the environment
    (``EZCOMPANION_SIGNING_KEY``, ``EZCOMPANION_SIGNING_PASSPHRASE``), else None. A bad one
    raises ConfigError naming where it came from (never showing the key)."""
    env = os.environ if environ is None else environ
    if settings.signing_key_hex is not None:
        return signing_key_from_hex(settings.signing_key_hex)
    if settings.signing_key_file is not None:
        return signing_key_from_file(settings.signing_key_file)
    if settings.signing_passphrase is not None:
        return signing_key_from_passphrase(settings.signing_passphrase)
    key_env, passphrase_env = SIGNING_ENV
    if env.get(key_env):
        try:
            return signing_key_from_hex(env[key_env].strip())
        except ConfigError:
            raise ConfigError(key_env, "(hidden)", "must be 64 hexadecimal digits") from None
    if env.get(passphrase_env):
        return signing_key_from_passphrase(env[passphrase_env])
    return None


def _unsigned_risk(connect: str) -> str:
    """What a sender on the vehicle's address can do on an unsigned ``connect``."""
    return (f"whoever can send from the vehicle's address on {connect} can move its position "
            "as the service reads it by the estimate gate's tolerances (5 cm across the "
            "track; docs/service.md, the trust table) and end guidance")


def refuse_unsigned(settings: CompanionSettings) -> None:
    """Refuse to run a link with no signing key where other machines reach it (not the
    loopback, not a serial port) unless ``allow_unsigned`` says the user accepts it:
    MAVLink 1 and unsigned MAVLink 2 frames carry no proof of who sent them. ConfigError
    naming ``connect`` and its value; called once the key is known (settings, file or
    environment) and before the link opens."""
    if settings.allow_unsigned or not parse_endpoint(settings.connect).on_a_network:
        return
    raise ConfigError(
        "connect", settings.connect,
        "is reachable from other machines and no signing key is set: "
        f"{_unsigned_risk(settings.connect)}. Set a signing key (--signing-key-file or "
        "EZCOMPANION_SIGNING_KEY), listen on 127.0.0.1, or accept the risk with "
        "--allow-unsigned (companion.allow_unsigned: true)",
    )  # fmt: skip


def unsigned_warning(settings: CompanionSettings) -> str | None:
    """What to say of a link left unsigned where other machines reach it, with the user's
    ``allow_unsigned`` (None on the loopback or a serial port)."""
    if not parse_endpoint(settings.connect).on_a_network:
        return None
    return (f"MAVLink unsigned on {settings.connect} (companion.allow_unsigned): "
            f"{_unsigned_risk(settings.connect)}; set a signing key "
            "(companion.signing_key_file)")


def companion_settings(scenario: Scenario, **overrides: Any) -> CompanionSettings:
    """The scenario's ``companion:`` section with command-line ``overrides`` (None = unset)."""
    raw = dict(scenario.sections.get("companion", {}))
    raw.update({key: value for key, value in overrides.items() if value is not None})
    if "setpoint" in raw:
        raw["setpoint"] = enum_member("companion.setpoint", SetpointKind, raw["setpoint"],
                                      "must be auto, velocity or course")  # fmt: skip
    if "on_exit" in raw:
        raw["on_exit"] = enum_member("companion.on_exit", OnExit, raw["on_exit"],
                                     f"must be one of {_ON_EXIT}")  # fmt: skip
    settings: CompanionSettings = build_dataclass("companion", CompanionSettings, raw)
    return settings
