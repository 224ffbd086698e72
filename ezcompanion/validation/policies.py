"""The policies a campaign can fly, by name: every guidance law (``LawName``) and the
CBF-QP filter. A law added to ``LawName`` is a policy here with no other change."""

from __future__ import annotations

from ezcompanion.errors import ConfigError
from ezcompanion.guidance import GuidanceParams, LawName
from ezcompanion.validation.batch import Policy, law_policy
from ezcompanion.validation.qpfilter import QpFilterPolicy
from ezcompanion.validation.scenarios import ScenarioBatch

__all__ = ["POLICIES", "QP_FILTER", "make_policy"]

QP_FILTER = "qp-filter"
POLICIES: tuple[str, ...] = (*(law.value for law in LawName), QP_FILTER)


def make_policy(name: str, scenarios: ScenarioBatch, params: GuidanceParams) -> Policy:
    """The policy ``name`` (a ``LawName`` value or ``qp-filter``) for ``scenarios``."""
    if name == QP_FILTER:
        return QpFilterPolicy(scenarios, params)
    if name not in POLICIES:
        raise ConfigError("policy", name, f"must be one of {POLICIES}")
    return law_policy(scenarios, params, LawName(name))
