"""Build environments from keyword arguments, filling defaults from the scenario preset."""

from __future__ import annotations

import functools
import inspect
from collections.abc import Callable
from typing import Any, TypeVar

from pettingzoo.utils.wrappers import OrderEnforcingWrapper

from fdia_env._validation import check_int
from fdia_env.envs.aec import FdiaAECEnv, FdiaOrderEnforcingWrapper
from fdia_env.episode import EpisodeSpec
from fdia_env.scenarios import Scenario, resolve, scenario_default
from fdia_env.systems import LinearSystem

F = TypeVar("F", bound=Callable[..., Any])

# The episode parameters every Kalman env module's ``parallel_env`` takes, as they pass to
# :func:`episode_spec`: name -> (annotation, default).
EPISODE_PARAMETERS: dict[str, tuple[str, Any]] = {
    "horizon": ("int | None", None),
    "warmup": ("int | str | None", None),
    "objective": ("str", "trace"),
    "reward_mode": ("str", "terminal"),
    "dynamics": ("str", "expected"),
    "max_cycles": ("int | None", None),
}
# Their public order (``render_mode``, a parameter of the env itself, among them) in most modules.
EPISODE_ORDER = (
    "horizon",
    "objective",
    "reward_mode",
    "dynamics",
    "warmup",
    "render_mode",
    "max_cycles",
)


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


def with_episode_parameters(*order: str) -> Callable[[F], F]:
    """Give an env module's ``parallel_env(own..., **episode)`` its explicit public signature.

    The decorated function declares its own parameters and collects the episode parameters
    (:data:`EPISODE_PARAMETERS`) in ``**episode``, always all of them (defaults filled), ready
    for ``episode_spec(scenario, **episode)``. The public signature (``inspect.signature``, read
    by the trainers) lists every parameter in ``order``, so positional calls work as with a plain
    ``def``, and a wrong argument raises the same ``TypeError``.

    Args:
        *order: Every parameter name (the function's own and the episode ones) in public order.

    Returns:
        The decorator.
    """

    def decorate(fn: F) -> F:
        base = inspect.signature(fn)
        own = {n: p for n, p in base.parameters.items() if p.kind is not p.VAR_KEYWORD}
        if sorted(order) != sorted([*own, *EPISODE_PARAMETERS]):
            raise TypeError(
                f"order must list {fn.__qualname__}'s own parameters {list(own)} and the episode "
                f"parameters {list(EPISODE_PARAMETERS)} once each, got {list(order)}"
            )
        kind = inspect.Parameter.POSITIONAL_OR_KEYWORD
        parameters = []
        for name in order:
            if name in own:
                parameters.append(own[name])
            else:
                annotation, default = EPISODE_PARAMETERS[name]
                parameters.append(
                    inspect.Parameter(name, kind, default=default, annotation=annotation)
                )
        signature = base.replace(parameters=parameters)

        @functools.wraps(fn)
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            bound = signature.bind(*args, **kwargs)
            bound.apply_defaults()
            return fn(**bound.arguments)

        wrapper.__signature__ = signature  # type: ignore[attr-defined]
        return wrapper  # type: ignore[return-value]

    return decorate
