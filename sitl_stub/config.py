"""The stub's settings: the optional ``sitl_stub:`` section of a scenario file, then flags.

Layout (every key optional; see ``docs/sitl_stub.md``)::

    sitl_stub:
      profile: copter | plane | px4
      connect: udpout:127.0.0.1:14550   # or udpout://..., tcp://..., /dev/ttyS0,57600, pty:PATH
      system_id: 1
      component_id: 1
      speedup: 1.0
      seed: 0
      physics_dt_s: 0.01
      model: measured               # measured | ideal (docs/sitl_stub.md)
      velocity_lag_s: null          # null: the model's (measured: copter 0.6, PX4 1.2)
      velocity_vector_lag: false    # PX4: the velocity lags as a vector (a velocity loop)
      speed_ratio: null             # flown / commanded (measured: PX4 0.8, plane 23.4/22)
      heading_accel_ratio: null     # plane course command (measured 0.73)
      guided_p: null                # plane: ArduPlane's GUIDED_P, cd/rad (null: 5000)
      roll_limit_deg: null          # plane: ArduPlane's ROLL_LIMIT_DEG (null: 45; SITL's 65)
      vz_hold_drift_m_s: null       # climb under vz = 0 without a height (PX4 0.1)
      failsafe_descent_m_s: null    # after PX4's offboard-loss failsafe (0.8)
      response_time_s: 0.0          # first-order lag of lateral acceleration, 0 = ideal
      course_gain_1_s: 2.0
      yaw_rate_max_deg_s: 90.0
      loiter_radius_m: 60.0
      height_m: 20.0                # above the origin; constant; within [-1000, 100000]
      wind_north_m_s: 0.0           # each within [-100, 100]
      wind_east_m_s: 0.0
      initial_mode: AUTO            # default per profile
      pilot_modes: []               # [[at_s, MODE], ...]: a pilot's mode switches, in order
      start_armed: true
      local_origin_after_s: 0.0     # LOCAL_POSITION_NED only from then on; < 0 = never
      setpoint_timeout_s: 3.0       # default per profile; 0 = no timeout
      attitude_timeout_s: 3.0
      course_timeout_s: 0.0
      max_stream_rate_hz: 200.0     # default per profile
      signing_key_hex: null         # 64 hex digits: sign, refuse unsigned input
      signing_passphrase: null      # or a passphrase (SHA-256, as MAVProxy)
      streams: {global_position_int_hz: 10, local_position_ned_hz: 10, attitude_hz: 10,
                vfr_hud_hz: 4}
      faults: {drop_rate, delay_s, jitter_s, duplicate_rate, reorder_rate, reorder_delay_s,
               freeze_start_s, freeze_duration_s, freeze_mode: silent | stale | link,
               jump_at_s, jump_north_m, jump_east_m, reboot_at_s, reboot_s}

Every number has a stated range (the error gives it); positions and offsets are held to the
scenario's limit (``ezcompanion.config_limits.POSITION_LIMIT_M``, 100 km), so that what the
stub sends fits MAVLink's fields. ``connect`` takes MAVProxy's and MAVSDK's spellings
(``ezcompanion.endpoint``) and is kept as the pymavlink string, or ``pty``/``pty:PATH``: a
pseudo-terminal the stub serves as its serial port (``sitl_stub.transport``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ezcompanion.config import GeoOrigin, Scenario, VehicleStart, build_dataclass, load_scenario
from ezcompanion.config_limits import POSITION_LIMIT_M
from ezcompanion.errors import ConfigError
from sitl_stub.mav import key_from_hex, key_from_passphrase, lla_to_ne
from sitl_stub.profiles import Profile, ProfileSpec, profile_spec
from sitl_stub.transport import check_stub_url
from sitl_stub.vehicle import VelocityShaping

__all__ = ["Faults", "StreamRates", "StubConfig", "StubSettings", "load_stub_config", "stub_config"]


def _check(name: str, value: object, *, low: float, high: float, low_open: bool = False) -> None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(name, value, "must be a finite number")
    if isinstance(value, float) and not math.isfinite(value):
        raise ConfigError(name, value, "must be a finite number")
    if value < low or value > high or (low_open and value == low):  # exact for any int
        left = "(" if low_open else "["
        raise ConfigError(name, value, f"must be within {left}{low}, {high}]")


@dataclass(frozen=True, kw_only=True)
class StreamRates:
    """Default telemetry rates (Hz of simulated time; 0 = not streamed until requested)."""

    global_position_int_hz: float = 10.0
    local_position_ned_hz: float = 10.0
    attitude_hz: float = 10.0
    vfr_hud_hz: float = 4.0

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            _check(f.name, getattr(self, f.name), low=0.0, high=1000.0)


@dataclass(frozen=True, kw_only=True)
class Faults:
    """Telemetry faults, drawn from the run's seeded generator (times in simulated s)."""

    drop_rate: float = 0.0  # probability a streamed message is lost
    delay_s: float = 0.0  # added latency
    jitter_s: float = 0.0  # plus a uniform [0, jitter_s) latency
    duplicate_rate: float = 0.0  # probability a message is sent twice
    reorder_rate: float = 0.0  # probability a message is held back by reorder_delay_s
    reorder_delay_s: float = 0.2
    freeze_start_s: float = 0.0
    freeze_duration_s: float = 0.0  # 0 = no freeze
    # silent: streams stop (heartbeats go on); stale: values stop changing; link: the whole
    # link is down both ways (nothing sent, heartbeats included, nothing received)
    freeze_mode: str = "silent"
    jump_at_s: float = -1.0  # < 0 = no jump; from then on the reported position is offset
    jump_north_m: float = 0.0
    jump_east_m: float = 0.0
    # < 0 = none; at reboot_at_s the autopilot goes down (disarmed, silent both ways) for
    # reboot_s, then starts afresh: time_boot_ms from 0, its initial mode, disarmed, and as
    # ArduCopter 4.5.1 SITL came back from a forced reboot (docs/sitl_stub.md): no telemetry
    # streamed until asked for, its first two heartbeats each sent twice
    reboot_at_s: float = -1.0
    reboot_s: float = 3.0

    def __post_init__(self) -> None:
        for name in ("drop_rate", "duplicate_rate", "reorder_rate"):
            _check(name, getattr(self, name), low=0.0, high=1.0)
        for name in ("delay_s", "jitter_s", "reorder_delay_s", "freeze_start_s",
                     "freeze_duration_s"):
            _check(name, getattr(self, name), low=0.0, high=3600.0)
        _check("jump_at_s", self.jump_at_s, low=-1e6, high=1e6)
        _check("reboot_at_s", self.reboot_at_s, low=-1e6, high=1e6)
        _check("reboot_s", self.reboot_s, low=0.0, high=600.0)
        for name in ("jump_north_m", "jump_east_m"):
            _check(name, getattr(self, name), low=-POSITION_LIMIT_M, high=POSITION_LIMIT_M)
        if self.freeze_mode not in ("silent", "stale", "link"):
            raise ConfigError("freeze_mode", self.freeze_mode, "must be silent, stale or link")

    @property
    def any(self) -> bool:
        """True when some fault is configured."""
        return self != Faults()


#: The response models: ``measured`` (the autopilots as measured in SITL) or ``ideal``.
MODELS = ("measured", "ideal")
_MODEL_RANGES = (
    ("velocity_lag_s", 0.0, 10.0),
    ("speed_ratio", 0.1, 2.0),
    ("heading_accel_ratio", 0.05, 1.0),
    ("vz_hold_drift_m_s", -5.0, 5.0),
    ("failsafe_descent_m_s", 0.0, 10.0),
)
#: What each model key is in the ideal vehicle (velocity_lag_s: 1 / course_gain_1_s).
_IDEAL = {"speed_ratio": 1.0, "heading_accel_ratio": 1.0, "vz_hold_drift_m_s": 0.0}


@dataclass(frozen=True, kw_only=True)
class StubSettings:
    """The ``sitl_stub:`` section: how the loopback vehicle behaves and talks."""

    profile: str = Profile.COPTER.value
    connect: str = "udpout:127.0.0.1:14550"
    system_id: int = 1
    component_id: int = 1
    speedup: float = 1.0
    seed: int = 0
    physics_dt_s: float = 0.01
    model: str = "measured"
    velocity_lag_s: float | None = None
    # PX4 (measured model): the velocity lags as a vector rather than speed and course apart
    velocity_vector_lag: bool = False
    speed_ratio: float | None = None
    heading_accel_ratio: float | None = None
    guided_p: float | None = None  # ArduPlane's GUIDED_P (cd/rad): its heading loop's roll gain
    roll_limit_deg: float | None = None  # ArduPlane's ROLL_LIMIT_DEG: its heading loop's clip
    vz_hold_drift_m_s: float | None = None
    failsafe_descent_m_s: float | None = None
    response_time_s: float = 0.0
    course_gain_1_s: float = 2.0
    yaw_rate_max_deg_s: float = 90.0
    loiter_radius_m: float = 60.0
    height_m: float = 20.0
    wind_north_m_s: float = 0.0
    wind_east_m_s: float = 0.0
    initial_mode: str | None = None
    # a pilot's (or a ground station's) mode switches: (simulated s, mode name), in order
    pilot_modes: tuple[tuple[float, str], ...] = ()
    start_armed: bool = True
    local_origin_after_s: float = 0.0
    setpoint_timeout_s: float | None = None
    attitude_timeout_s: float | None = None
    course_timeout_s: float | None = None
    max_stream_rate_hz: float | None = None
    signing_key_hex: str | None = None
    signing_passphrase: str | None = None
    streams: StreamRates = field(default_factory=StreamRates)
    faults: Faults = field(default_factory=Faults)

    def __post_init__(self) -> None:
        if not isinstance(self.profile, str) or self.profile not in {p.value for p in Profile}:
            raise ConfigError("profile", self.profile, "must be copter, plane or px4")
        object.__setattr__(self, "connect", check_stub_url(self.connect, field="connect"))
        for name in ("system_id", "component_id"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 255:
                raise ConfigError(name, value, "must be an integer within [1, 255]")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ConfigError("seed", self.seed, "must be an integer >= 0")
        _check("speedup", self.speedup, low=0.0, high=1000.0, low_open=True)
        _check("physics_dt_s", self.physics_dt_s, low=0.0, high=0.1, low_open=True)
        _check("response_time_s", self.response_time_s, low=0.0, high=60.0)
        if self.model not in MODELS:
            raise ConfigError("model", self.model, "must be measured or ideal")
        for name, low, high in _MODEL_RANGES:
            if getattr(self, name) is not None:
                _check(name, getattr(self, name), low=low, high=high)
        _check("course_gain_1_s", self.course_gain_1_s, low=0.0, high=100.0, low_open=True)
        if self.guided_p is not None:
            _check("guided_p", self.guided_p, low=0.0, high=1e5, low_open=True)
        if self.roll_limit_deg is not None:
            _check("roll_limit_deg", self.roll_limit_deg, low=0.0, high=89.0, low_open=True)
        _check("yaw_rate_max_deg_s", self.yaw_rate_max_deg_s, low=0.0, high=3600.0, low_open=True)
        _check("loiter_radius_m", self.loiter_radius_m, low=0.0, high=1e5, low_open=True)
        _check("height_m", self.height_m, low=-1000.0, high=1e5)
        for name in ("wind_north_m_s", "wind_east_m_s"):
            _check(name, getattr(self, name), low=-100.0, high=100.0)
        _check("local_origin_after_s", self.local_origin_after_s, low=-1e6, high=1e6)
        for name in ("setpoint_timeout_s", "attitude_timeout_s", "course_timeout_s"):
            if getattr(self, name) is not None:
                _check(name, getattr(self, name), low=0.0, high=3600.0)
        if self.max_stream_rate_hz is not None:
            _check("max_stream_rate_hz", self.max_stream_rate_hz, low=0.0, high=10000.0,
                   low_open=True)
        for name in ("start_armed", "velocity_vector_lag"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(name, getattr(self, name), "must be true or false")
        if self.signing_key_hex is not None and self.signing_passphrase is not None:
            raise ConfigError("signing_key_hex", self.signing_key_hex,
                              "give at most one of signing_key_hex and signing_passphrase")
        if self.signing_key_hex is not None:
            if not isinstance(self.signing_key_hex, str):
                raise ConfigError("signing_key_hex", self.signing_key_hex, "must be a string")
            key_from_hex(self.signing_key_hex)
        if self.signing_passphrase is not None and not isinstance(self.signing_passphrase, str):
            raise ConfigError("signing_passphrase", self.signing_passphrase, "must be a string")
        spec = profile_spec(Profile(self.profile))
        if self.initial_mode is not None and (
            not isinstance(self.initial_mode, str) or spec.mode_by_name(self.initial_mode) is None
        ):
            names = ", ".join(m.name for m in spec.modes)
            raise ConfigError("initial_mode", self.initial_mode, f"must be one of {names}")
        object.__setattr__(self, "pilot_modes", _pilot_modes(self.pilot_modes, spec))

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any], path: str = "sitl_stub") -> StubSettings:
        """Validate a raw ``sitl_stub:`` mapping; errors name ``sitl_stub.key``."""
        raw = dict(data)
        for key, kind in (("streams", StreamRates), ("faults", Faults)):
            if key in raw:
                value = raw[key]
                if not isinstance(value, Mapping):
                    raise ConfigError(f"{path}.{key}", value, "must be a mapping")
                raw[key] = build_dataclass(f"{path}.{key}", kind, value)
        settings: StubSettings = build_dataclass(path, cls, raw)
        return settings

    def signing_key(self) -> bytes | None:
        """The configured signing key, if any."""
        if self.signing_key_hex is not None:
            return key_from_hex(self.signing_key_hex)
        if self.signing_passphrase is not None:
            return key_from_passphrase(self.signing_passphrase)
        return None


@dataclass(frozen=True, kw_only=True)
class StubConfig:
    """A stub run, resolved: start state and limits from the scenario, settings, profile."""

    start: VehicleStart
    accel_max_m_s2: float
    origin: GeoOrigin
    settings: StubSettings = field(default_factory=StubSettings)
    # the start as the file gave it in latitude and longitude, if it did: placed as the
    # profile's autopilot maps it (``placed_start``)
    start_lat_lon_deg: tuple[float, float] | None = None

    @property
    def placed_start(self) -> VehicleStart:
        """The start in the vehicle's local frame: a start given as latitude and longitude
        where the profile's autopilot maps it (where a vehicle there says it is), not on
        WGS84 as the scenario file reader put it (3.3 m a kilometre apart on ArduPilot)."""
        if self.start_lat_lon_deg is None:
            return self.start
        o = self.origin
        north, east = lla_to_ne(*self.start_lat_lon_deg, (o.lat_deg, o.lon_deg, o.alt_m),
                                self.spec.autopilot)  # fmt: skip
        return dataclasses.replace(self.start, north_m=north, east_m=east)

    @property
    def spec(self) -> ProfileSpec:
        """The profile's built-in description."""
        return profile_spec(Profile(self.settings.profile))

    def timeout_s(self, kind: str) -> float:
        """``setpoint``, ``attitude`` or ``course`` timeout: the setting or the profile's."""
        value = getattr(self.settings, f"{kind}_timeout_s")
        return float(getattr(self.spec, f"{kind}_timeout_s") if value is None else value)

    @property
    def measured(self) -> bool:
        """The measured response model (else the ideal vehicle)."""
        return self.settings.model == "measured"

    def model_value(self, name: str) -> float:
        """A response-model figure: the setting, else the model's (profile's measured one)."""
        value = getattr(self.settings, name)
        if value is not None:
            return float(value)
        if self.measured or name == "failsafe_descent_m_s":
            return float(getattr(self.spec, name))
        if name == "velocity_lag_s":
            return 1.0 / self.settings.course_gain_1_s
        return _IDEAL[name]

    @property
    def heading_roll_gain(self) -> float | None:
        """ArduPlane's heading loop in the measured model: its roll per course error (rad/rad,
        from ``guided_p`` or the profile's 5000 cd/rad); None: the stub's own course loop."""
        gain = self.spec.heading_roll_gain
        if not self.measured or gain is None:
            return None
        guided_p = self.settings.guided_p
        return gain if guided_p is None else math.radians(guided_p / 100.0)

    @property
    def roll_rate_max_rad_s(self) -> float:
        """The most the vehicle's bank turns a second: the profile's in the measured model
        (a plane's, as ArduPlane SITL rolled), 0 (at once) in the ideal one."""
        return self.spec.roll_rate_max_rad_s if self.measured else 0.0

    @property
    def roll_limit_rad(self) -> float:
        """ArduPlane's roll limit, which clips its heading loop's roll: ``roll_limit_deg``,
        else the profile's (the firmware's default, 45 degrees)."""
        limit = self.settings.roll_limit_deg
        return self.spec.roll_limit_rad if limit is None else math.radians(limit)

    def velocity_shaping(self) -> VelocityShaping | None:
        """ArduCopter's velocity shaping in the measured model, else None: WPNAV_ACCEL from
        the profile, the tracking lag (at most half the lag), and PSC_JERK_XY such that
        the shaping and the tracking add up to ``velocity_lag_s``; None at a lag of 0."""
        accel = self.spec.shaping_accel_m_s2
        lag = self.model_value("velocity_lag_s")
        if not self.measured or accel is None or lag <= 0.0:
            return None
        tracking = min(self.spec.tracking_lag_s, 0.5 * lag)
        return VelocityShaping(accel_max_m_s2=accel, jerk_max_m_s3=accel / (lag - tracking),
                               tracking_lag_s=tracking)

    def vector_lag_s(self) -> float:
        """The velocity loop's lag where ``velocity_vector_lag`` is set (the measured model,
        a vehicle that hovers without ArduCopter's shaping: PX4), else 0."""
        if (not self.settings.velocity_vector_lag or not self.measured
                or not self.spec.can_hover or self.spec.shaping_accel_m_s2 is not None):
            return 0.0
        return self.model_value("velocity_lag_s")

    @property
    def max_stream_rate_hz(self) -> float:
        """Fastest stream rate a request may ask for."""
        value = self.settings.max_stream_rate_hz
        return self.spec.max_stream_rate_hz if value is None else float(value)

    @property
    def initial_mode(self) -> str:
        """The mode the vehicle boots in."""
        value = self.settings.initial_mode
        return self.spec.initial_mode if value is None else str(value).upper()

    def with_settings(self, **changes: Any) -> StubConfig:
        """A copy with some settings replaced (validated again)."""
        merged = {f.name: getattr(self.settings, f.name) for f in dataclasses.fields(StubSettings)}
        merged.update(changes)
        return dataclasses.replace(self, settings=StubSettings(**merged))


def stub_config(scenario: Scenario, **overrides: Any) -> StubConfig:
    """The stub's configuration for ``scenario``; ``overrides`` replace section values."""
    raw = dict(scenario.sections.get("sitl_stub", {}))
    settings = StubSettings.from_mapping(raw)
    fixed = [(f.lat_deg, f.lon_deg) for f in scenario.fixed if f.path == "vehicle"]
    config = StubConfig(
        start=scenario.start, accel_max_m_s2=scenario.guidance.accel_max_m_s2,
        origin=scenario.origin, settings=settings,
        start_lat_lon_deg=fixed[0] if fixed else None,
    )
    changes = {k: v for k, v in overrides.items() if v is not None}
    return config.with_settings(**changes) if changes else config


def load_stub_config(path: str | Path, **overrides: Any) -> StubConfig:
    """Read a scenario file and resolve the stub's configuration (file, then overrides)."""
    return stub_config(load_scenario(path), **overrides)


def _pilot_modes(value: Any, spec: Any) -> tuple[tuple[float, str], ...]:
    """``pilot_modes`` checked: a list of [at_s, MODE] pairs, times increasing, each mode
    one of the profile's."""
    if not isinstance(value, (list, tuple)):
        raise ConfigError("pilot_modes", value, "must be a list of [at_s, MODE] pairs")
    out: list[tuple[float, str]] = []
    for index, pair in enumerate(value):
        where = f"pilot_modes[{index}]"
        if not isinstance(pair, (list, tuple)) or len(pair) != 2:
            raise ConfigError(where, pair, "must be a pair [at_s, MODE]")
        at_s, mode = pair
        _check(where, at_s, low=0.0, high=1e6)
        if not isinstance(mode, str) or spec.mode_by_name(mode) is None:
            names = ", ".join(m.name for m in spec.modes)
            raise ConfigError(where, mode, f"mode must be one of {names}")
        if out and float(at_s) <= out[-1][0]:
            raise ConfigError(where, at_s, "must come after the switch before it")
        out.append((float(at_s), mode))
    return tuple(out)
