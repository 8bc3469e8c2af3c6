"""``fdia_v0``: any attack model against any defense model on any scenario.

## Description

The composition every other module specialises: a scenario (preset name, ``Scenario`` or your
own ``LinearSystem``) × an attack model × a defense model × an episode spec. Models are given by
name with their parameters in ``attack_kwargs`` / ``defense_kwargs`` (parameters the preset
defines, such as ``budget`` or ``power``, are filled in unless given), or as model instances.
A passive defense (``"perfect_detection"``, ``"unaware"``) leaves the attacker as the only agent.

## Action Space

The attack model's (``"sparse"``: ``Discrete(2**M)`` bitmasks with an action mask;
``"covariance"``: a ``Box`` mapped to a bias covariance of power a²; ``"subset"``:
``Discrete(2**M − 1)`` subsets; ``"probabilistic"``: a ``Box`` of the attack probability and the
covariance) and, for an active defense, the defense model's (``"sensor_selection"``:
``Discrete(2**M − 1)``; ``"threshold_detector"``: ``Box(-1, 1, (1,))`` mapped to a threshold).

## Observation Space

``Box(float32)`` of the common features (steps left, error variance growth and correlations,
NIS in sampled dynamics) followed by the player's model features; a ``Dict`` with an
``action_mask`` for the sparse attacker.

## Rewards

The attacker +Φ and the defender −Φ, Φ = tr or log det of the actual error covariance
(expected dynamics) or the squared estimation error (sampled), paid as ``reward_mode`` says.

## Episode End

Terminates after ``horizon`` steps (default the preset's, or ``max_cycles`` when only that is
given); truncated after ``max_cycles`` steps when that is shorter.

## Arguments

``scenario``, ``attack`` (``"sparse"`` | ``"covariance"`` | ``"subset"`` | ``"probabilistic"`` or
an ``AttackModel``), ``defense`` (``"perfect_detection"`` | ``"unaware"`` |
``"sensor_selection"`` | ``"threshold_detector"`` or a ``DefenseModel``), ``attack_kwargs``,
``defense_kwargs`` (dicts of the models' parameters; unknown names are an error), ``horizon``,
``objective``, ``reward_mode``, ``dynamics``, ``warmup``, ``render_mode``
(``"human"`` | ``"ansi"`` | ``"rgb_array"``), ``max_cycles``.

## Version History

- v0: initial release. Infos with the same keys at reset and at every step (``attacked`` as an
  (M,) 0/1 array), ``max_cycles``, ``render_mode="human"``.

## Example

>>> from fdia_env import fdia_v0
>>> env = fdia_v0.parallel_env(scenario="ch4-position", attack="sparse",
...                            defense="perfect_detection",
...                            attack_kwargs={"budget": 2}, horizon=3)
>>> env.possible_agents
['attacker']
"""

from __future__ import annotations

import inspect
from typing import Any

from fdia_env.attacks import AttackModel, CovarianceAttack, SparseAttack
from fdia_env.attacks.probabilistic import ProbabilisticAttack
from fdia_env.attacks.subset import SubsetAttack
from fdia_env.defenses import DefenseModel, PerfectDetection, UnawareFilter
from fdia_env.defenses.detector import ThresholdDetector
from fdia_env.defenses.selection import SensorSelection
from fdia_env.envs.factory import (
    EPISODE_ORDER,
    aec_views,
    episode_spec,
    with_episode_parameters,
)
from fdia_env.envs.parallel import FdiaParallelEnv
from fdia_env.scenarios import Scenario
from fdia_env.systems import LinearSystem

NAME = "fdia_v0"
_NAMED = (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
ATTACKS: dict[str, type[AttackModel]] = {
    "sparse": SparseAttack,
    "covariance": CovarianceAttack,
    "subset": SubsetAttack,
    "probabilistic": ProbabilisticAttack,
}
# attack-model parameters filled from the scenario preset when not given
SCENARIO_DEFAULTS: dict[str, tuple[str, ...]] = {
    "sparse": ("budget",),
    "covariance": ("power",),
    "subset": ("power",),
    "probabilistic": ("power",),
}
DEFENSES: dict[str, type[DefenseModel]] = {
    "perfect_detection": PerfectDetection,
    "unaware": UnawareFilter,
    "sensor_selection": SensorSelection,
    "threshold_detector": ThresholdDetector,
}


def _check_kwargs(kind: str, kwargs: Any) -> None:
    if kwargs is not None and not isinstance(kwargs, dict):
        raise TypeError(
            f"{kind}_kwargs must be a dict of the {kind} model's parameters or None, "
            f"got {type(kwargs).__name__}: {kwargs!r}"
        )


def _model(kind: str, value: Any, registry: dict[str, type], kwargs: dict | None) -> Any:
    _check_kwargs(kind, kwargs)
    if isinstance(value, str):
        if value not in registry:
            raise ValueError(
                f"{kind} must be one of {sorted(registry)} or a model instance, got {value!r}"
            )
        cls = registry[value]
        params = {p: v for p, v in inspect.signature(cls).parameters.items() if p != "self"}
        allowed = list(params)
        unknown = sorted(set(kwargs or {}) - set(allowed))
        if unknown:
            raise ValueError(f"{kind}_kwargs: {value!r} takes {allowed}, got unknown {unknown}")
        required = [p for p, v in params.items() if v.default is v.empty and v.kind in _NAMED]
        missing = [p for p in required if p not in (kwargs or {})]
        if missing:
            raise ValueError(
                f"{kind}_kwargs must give {missing} for {kind}={value!r} (the scenario defines "
                f"no default for them), got {kwargs!r}"
            )
        return cls(**(kwargs or {}))
    if kwargs:
        raise ValueError(f"{kind}_kwargs only apply when {kind} is given by name")
    return value


@with_episode_parameters(
    "scenario", "attack", "defense", "attack_kwargs", "defense_kwargs", *EPISODE_ORDER
)
def parallel_env(
    scenario: str | Scenario | LinearSystem = "ch4-position",
    attack: str | AttackModel = "sparse",
    defense: str | DefenseModel = "perfect_detection",
    attack_kwargs: dict | None = None,
    defense_kwargs: dict | None = None,
    render_mode: str | None = None,
    **episode: Any,
) -> FdiaParallelEnv:
    """Compose a scenario, an attack model, a defense model and an episode spec.

    Models are given by name (with ``*_kwargs``) or as instances; names: attacks
    ``ATTACKS``, defenses ``DEFENSES``.
    """
    sc, spec = episode_spec(scenario, **episode)
    for kind, kwargs in (("attack", attack_kwargs), ("defense", defense_kwargs)):
        _check_kwargs(kind, kwargs)
    if isinstance(attack, str):  # model parameters the preset defines, unless given
        attack_kwargs = dict(attack_kwargs or {})
        for param in SCENARIO_DEFAULTS.get(attack, ()):
            if param not in attack_kwargs and getattr(sc, param, None) is not None:
                attack_kwargs[param] = getattr(sc, param)
    return FdiaParallelEnv(
        sc,
        _model("attack", attack, ATTACKS, attack_kwargs),
        _model("defense", defense, DEFENSES, defense_kwargs),
        spec,
        render_mode=render_mode,
        name=NAME,
        max_cycles=episode["max_cycles"],
    )


raw_env, env = aec_views(parallel_env)
