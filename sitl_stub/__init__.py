"""sitl_stub: a loopback MAVLink vehicle that behaves like ArduCopter, ArduPlane or PX4.

For tests, demos and trying the companion without an autopilot. See ``docs/sitl_stub.md``.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
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

# each name's module, loaded as the name is first asked for: the ``sitl-stub`` command loads
# this package before its entry's guard is set (``sitl_stub.console``), and its server's
# modules (numpy, pymavlink) take some 0.3 s
_MODULES = {
    "Faults": "config", "StreamRates": "config", "StubConfig": "config",
    "StubSettings": "config", "load_stub_config": "config", "stub_config": "config",
    "Behaviour": "profiles", "Profile": "profiles", "ProfileSpec": "profiles",
    "profile_spec": "profiles", "SitlStub": "server", "TRUTH_COLUMNS": "truth",
    "VehicleState": "vehicle",
}  # fmt: skip


def __getattr__(name: str) -> Any:
    """``name`` of ``__all__``, from its module (loaded now, if it was not)."""
    module = _MODULES.get(name)
    if module is None:
        raise AttributeError(f"module 'sitl_stub' has no attribute {name!r}")
    return getattr(import_module(f"sitl_stub.{module}"), name)
