"""``covariance_attack_v0``: bias covariances under a power budget against an unaware filter.

## Description

A Kalman filter in steady state at time K keeps its nominal gains while the attacker adds zero-
mean Gaussian biases ``b ~ N(0, Σ)`` to the measurements (docs/math.md §2). The attacker chooses Σ
over every sensor's measurement components under the power constraint ``tr(Ω Σ) = a²`` (Ω weights
velocity components by T²) and wants the filter's *actual* error covariance
``M = P + A`` as large as possible. The defender is passive (the unaware filter): the env has the
single agent ``"attacker"``. With the default ``horizon=1`` this is the single injection of
docs/math.md §2.2, whose optimum is ``baselines.covariance.trace_optimal`` / ``det_optimal``.

## Action Space

``Box(-1, 1, (d,), float32)``: the lower-triangular entries of a factor ``L``, mapped to
``Σ = a² Ω^{-1/2} (L L' / tr(L L')) Ω^{-1/2}`` (see :mod:`fdia_env.attacks.covariance`; every
admissible Σ is reachable and ``env.attack.sigma_to_action(Σ)`` inverts the map). With
``structure="diagonal"`` the factor is block diagonal per sensor (independent biases). With
``power_mode="budget"`` a first entry ``f`` spends the fraction ``(f + 1) / 2`` of the power left.

## Observation Space

``Box(float32)``:

| index | feature | range |
|---|---|---|
| 0 | steps left / N | [0, 1] |
| 1..n | log(M_ii / P_ii at window start) | [-30, 30] |
| next n(n−1)/2 | correlations of the actual error covariance | [-1, 1] |
| (sampled only) | normalised innovation squared per measurement, last step | [0, 1000] |
| (budget mode only) | power left / a² | [0, 1] |

## Rewards

Φ = tr or log det of the actual error covariance M (expected dynamics), or the squared
estimation error (sampled); ``reward_mode`` as in every fdia_env env.

## Starting State

Steady state with all sensors (``warmup="steady"``) or ``warmup`` clean steps from the prior.

## Episode End

Terminates after ``horizon`` steps (default 1). No truncation.

## Arguments

``scenario`` (default ``"ch2-position"``), ``power`` (a², default the preset's), ``structure``
(``"full"`` | ``"diagonal"``), ``power_mode`` (``"per_step"`` | ``"budget"``), ``weight`` (Ω),
``horizon``, ``objective``, ``reward_mode``, ``dynamics``, ``warmup``, ``render_mode``
(``"human"`` | ``"ansi"`` | ``"rgb_array"``), ``max_cycles``.

## Version History

- v0: initial release. Infos with the same keys at reset and at every step, ``max_cycles``,
  ``render_mode="human"``.

## Example

>>> import numpy as np
>>> from fdia_env import covariance_attack_v0
>>> env = covariance_attack_v0.parallel_env(scenario="ch2-position", power=3000.0)
>>> _ = env.reset(seed=0)
>>> sigma = np.diag([3000.0, 0.0])  # all power on sensor 1, independent
>>> _, rewards, *_ = env.step({"attacker": env.attack.sigma_to_action(sigma)})
>>> round(rewards["attacker"], 1)
390.8
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fdia_env.attacks import CovarianceAttack
from fdia_env.defenses import UnawareFilter
from fdia_env.envs.factory import (
    EPISODE_ORDER,
    aec_views,
    episode_spec,
    scenario_default,
    with_episode_parameters,
)
from fdia_env.envs.parallel import FdiaParallelEnv
from fdia_env.scenarios import Scenario
from fdia_env.systems import LinearSystem

NAME = "covariance_attack_v0"


@with_episode_parameters("scenario", "power", "structure", "power_mode", "weight", *EPISODE_ORDER)
def parallel_env(
    scenario: str | Scenario | LinearSystem = "ch2-position",
    power: float | None = None,
    structure: str = "full",
    power_mode: str = "per_step",
    weight: np.ndarray | None = None,
    render_mode: str | None = None,
    **episode: Any,
) -> FdiaParallelEnv:
    """The PettingZoo ``ParallelEnv`` (see the module docstring)."""
    sc, spec = episode_spec(scenario, default_horizon=1, **episode)
    attack = CovarianceAttack(
        scenario_default(sc, "power", power),
        structure=structure,
        power_mode=power_mode,
        weight=weight,
    )
    return FdiaParallelEnv(
        sc,
        attack,
        UnawareFilter(),
        spec,
        render_mode=render_mode,
        name=NAME,
        max_cycles=episode["max_cycles"],
    )


raw_env, env = aec_views(parallel_env)
