"""The guidance law of Ranjan, Sinha and Cao, pure and vectorised.

No clock, I/O or logging in here: state and parameters in, command and diagnostics out.
"""

from ezcompanion.guidance._jit import kernels_cached
from ezcompanion.guidance.actuator import advance_actuator, max_actuator_step_s
from ezcompanion.guidance.controller import (
    GuidanceController,
    GuidanceMode,
    GuidanceStep,
    KinematicState,
)
from ezcompanion.guidance.law import LawOutput, evaluate_law, pack_params
from ezcompanion.guidance.params import BlendMode, Defender, GuidanceParams, LawName, Target
from ezcompanion.guidance.zones import ZoneSet, ez_boundary_point

__all__ = [
    "BlendMode",
    "Defender",
    "GuidanceController",
    "GuidanceMode",
    "GuidanceParams",
    "GuidanceStep",
    "KinematicState",
    "LawName",
    "LawOutput",
    "Target",
    "ZoneSet",
    "advance_actuator",
    "evaluate_law",
    "ez_boundary_point",
    "kernels_cached",
    "max_actuator_step_s",
    "pack_params",
]
