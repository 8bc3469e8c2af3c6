"""Build environments from keyword arguments, filling defaults from the scenario preset."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from pettingzoo.utils.wrappers import OrderEnforcingWrapper

from fdia_env._validation import check_int
from fdia_env.envs.aec import FdiaAECEnv, FdiaOrderEnforcingWrapper
from fdia_env.episode import EpisodeSpec
from fdia_env.scenarios import Scenario, resolve, scenario_default
from fdia_env.systems import LinearSystem


def episode_spec(
    scenario: str | Scenario | LinearSystem,
    *,
    horizon: int | None = None,
    warmup: int | str | None = None,
    objective: str = "trace",
    reward_mode: str = "terminal",
    dynamics: str = "expected",
    max_cycles: int | None = None,
    default_horizon: int | None = None,
) -> tuple[Scenario, EpisodeSpec]:
    """Resolve the scenario and build the :class:`EpisodeSpec`, defaults taken from the preset.

    ``horizon`` defaults to ``max_cycles`` when that is given (PettingZoo's episode length),
    else to ``default_horizon`` or the preset's window length; ``warmup`` to ``"steady"`` when
    the preset starts in steady state, else to its attack step (or 0).
    """
    sc = resolve(scenario)
    if max_cycles is not None:
        max_cycles = check_int("max_cycles", max_cycles, minimum=1)
    if horizon is None:
        horizon = max_cycles if max_cycles is not None else default_horizon
    if horizon is None:
        horizon = scenario_default(sc, "horizon", None)
    if warmup is None:
        warmup = "steady" if sc.steady_state else (sc.attack_step or 0)
    spec = EpisodeSpec(
        horizon=horizon,
        warmup=warmup,
        objective=objective,
        reward_mode=reward_mode,
        dynamics=dynamics,
    )
    return sc, spec


def aec_views(
    parallel_env: Callable[..., Any],
) -> tuple[Callable[..., FdiaAECEnv], Callable[..., OrderEnforcingWrapper]]:
    """PettingZoo's ``raw_env`` (AEC, unwrapped) and ``env`` (order-enforcing) for a module."""

    def raw_env(**kwargs: Any) -> FdiaAECEnv:
        """The AEC view without wrappers."""
        return FdiaAECEnv(parallel_env(**kwargs))

    def env(**kwargs: Any) -> OrderEnforcingWrapper:
        """The AEC view with PettingZoo's order-enforcing wrapper."""
        return FdiaOrderEnforcingWrapper(raw_env(**kwargs))

    return raw_env, env
