"""Input checks shared by every baseline family (sparse, covariance, game, detection)."""

from __future__ import annotations

from typing import Any

from fdia_env.scenarios import Scenario, resolve


def resolve_system(system_or_scenario: Any, param: str = "system_or_scenario") -> Scenario:
    """:func:`fdia_env.scenarios.resolve`, its errors re-raised naming the parameter.

    Args:
        system_or_scenario: Preset name, :class:`~fdia_env.scenarios.Scenario` or
            :class:`~fdia_env.systems.LinearSystem`.
        param: The name of the caller's parameter, put in front of the message.

    Raises:
        ValueError: ``"<param>: <reason>"`` for anything :func:`~fdia_env.scenarios.resolve`
            rejects (an unknown preset name, a value of another type).
    """
    try:
        return resolve(system_or_scenario)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{param}: {exc}") from exc
