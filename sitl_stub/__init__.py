"""sitl_stub: a loopback MAVLink vehicle that behaves like ArduCopter, ArduPlane or PX4.

For tests, demos and trying the companion without an autopilot. See ``docs/sitl_stub.md``.
"""

from sitl_stub.config import (
    Faults,
    StreamRates,
    StubConfig,
    StubSettings,
    load_stub_config,
    stub_config,
)
from sitl_stub.profiles import Behaviour, Profile, ProfileSpec, profile_spec
from sitl_stub.server import SitlStub
from sitl_stub.truth import TRUTH_COLUMNS
from sitl_stub.vehicle import VehicleState

__all__ = [
    "TRUTH_COLUMNS",
    "Behaviour",
    "Faults",
    "Profile",
    "ProfileSpec",
    "SitlStub",
    "StreamRates",
    "StubConfig",
    "StubSettings",
    "VehicleState",
    "load_stub_config",
    "profile_spec",
    "stub_config",
]
