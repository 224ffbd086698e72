"""The abandon check of a campaign: is each setpoint safe to keep flying if no other
follows, by an autopilot's measured behaviour (``ezcompanion.guidance.abandon``)?"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from ezcompanion.guidance import GuidanceParams, KinematicState
from ezcompanion.guidance.abandon import ABANDON_PROFILES, abandon_gap_m
from ezcompanion.validation.scenarios import ScenarioBatch

__all__ = ["AbandonChecker"]


class AbandonChecker:
    """``AbandonCheck`` for the autopilot ``name`` (a key of ``ABANDON_PROFILES``); an
    object rather than a closure so that it travels to Dask workers."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.profile = ABANDON_PROFILES[name]
        self.__qualname__ = f"AbandonChecker({name!r})"

    def __call__(
        self,
        scenarios: ScenarioBatch,
        state: KinematicState,
        accel_cmd_m_s2: npt.NDArray[np.float64],
        params: GuidanceParams,
    ) -> npt.NDArray[np.bool_]:
        speed = np.asarray(state.speed_m_s)
        if state.course_rate_rad_s is None:  # the ideal vehicle flies what it is told
            flown = np.asarray(accel_cmd_m_s2)
        else:  # the flown lateral acceleration, as the shield takes it from the course rate
            bound = params.accel_max_m_s2
            flown = np.clip(np.asarray(state.course_rate_rad_s) * speed, -bound, bound)
        gap = abandon_gap_m(
            self.profile, params, scenarios.zones(),
            north_m=np.asarray(state.north_m), east_m=np.asarray(state.east_m),
            course_rad=np.asarray(state.course_rad), accel_lat_m_s2=accel_cmd_m_s2,
            flown_accel_m_s2=flown, speed_m_s=speed, lag_s=scenarios.response_lag_s,
        )  # fmt: skip
        return gap >= 0.0
