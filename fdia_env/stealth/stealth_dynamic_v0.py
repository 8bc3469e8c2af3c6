"""``stealth_dynamic_v0``: stealthy false data against a Kalman filter with a χ² detector.

## Description

A steady-state Kalman filter tracks a linear Gaussian system (any scenario preset, a grid
preset or your own ``LinearSystem``) and a windowed χ² detector watches its innovations: the
sum of the last ``window`` normalised innovations ``g = Σ z̃' Σ⁻¹ z̃`` raises an alarm above
the upper-α quantile of its χ² law, so without attack the alarm rate is α at every step. The
attacker holds the sensors ``sensors`` and corrupts them at every step. It wants the filter's
error as large as possible without an alarm. Mo & Sinopoli: where an unstable mode of the
system shows only on the attacked sensors, a stealthy attack drives the error without bound;
Guo et al.: against a stable system the best linear attack ``z̃ = T z + b`` under a
Kullback-Leibler budget has a closed form (``baselines.stealth``). See docs/guide/stealth.md.

## Action Space

``action="bias"`` (default, the readings are corrupted): ``Box(-1, 1, (r,))`` for the r
measurement rows of the attacked sensors; row i gets ``a_max · σ_i · action_i`` added, σ_i the
innovation's standard deviation. ``action="linear"`` (the sensors send innovations, the
attacker rewrites them): ``Box(-1, 1, (r, r + 1))``: ``T_S = I + t_max · action[:, :r]`` and
``b ~ N(0, diag((b_max · |action[:, r]| · σ)²))`` on the attacked rows (the zero action is
no attack in both formats). Protected sensors (``protected``) pass unchanged.

## Observation Space

``Box(float32, (4,))``: steps left / N in [0, 1]; whether the last step raised the alarm (0/1);
the window statistic over its threshold, capped at 10 (its mean in expected dynamics; 0 before
the first step); ``ln(phi / tr P_f)``, how far the attack has grown the error covariance's
trace, capped at 30.

## Rewards

``phi``, the trace of the estimation error's covariance given the attack so far
(``tr P_f + |d|²`` for a bias, d the estimate's deviation; ``tr P_f + tr D`` for a linear
attack), in expected dynamics, weighted by the exact probability p that the step is not
detected: ``(1 − p) · phi + p · (payoff on an alarm)``. In sampled dynamics the realised
squared error ``|x − x̂|²`` when no alarm sounds. On an alarm (``on_detect``): 0 (``"zero"``),
``−penalty`` (``"penalty"``) or 0 and the episode ends (``"end"``, sampled dynamics).

## Starting State

The filter in steady state (its error drawn from ``N(0, P_f)`` in sampled dynamics), nothing
injected, the detector's window empty.

## Episode End

Terminates after ``horizon`` steps (default 20, or ``max_cycles`` when given), or at the first
alarm with ``on_detect="end"`` (sampled). Truncates after ``max_cycles``.

## Arguments

``scenario`` (a preset name, ``"ch4-position"`` default, a ``Scenario`` or a ``LinearSystem``),
``sensors`` (the attacked sensors: positions or names, default all), ``horizon``, ``window``
(the detector's window, 5), ``action`` (``"bias"`` | ``"linear"``), ``a_max`` (5.0 innovation
standard deviations), ``t_max`` (4.0), ``b_max`` (2.0), ``dynamics`` (``"sampled"`` |
``"expected"``), ``alpha`` (0.05), ``on_detect`` (``"zero"`` | ``"penalty"`` | ``"end"``),
``penalty`` (1.0), ``protected`` (sensors the attacker cannot touch), ``render_mode``,
``max_cycles``; ``defender`` (``None`` | ``"threshold"`` | ``"protect"``), ``alphas`` (the
defender's false-alarm rates, default 0.001, 0.01, 0.05, 0.1, 0.2), ``false_alarm_cost`` (1.0),
``protect_budget`` (sensors the ``"protect"`` defender may guard per step, 1).

With ``defender="threshold"`` the env has a second agent ``"defender"`` with ``Discrete(len(
alphas))``: each step it picks the detector's false-alarm rate; its reward is minus the
attacker's minus ``false_alarm_cost · α``. Its Gymnasium view is
``"fdia_env/StealthDynamicDefender-v0"`` (the attacker samples its action space); the
attacker's view then faces the rate of ``alphas`` closest to ``alpha``. With
``defender="protect"`` the defender has ``MultiBinary(M)`` (M sensors): each step the first
``protect_budget`` sensors it selects pass unchanged (on top of ``protected``); its reward is
minus the attacker's minus ``false_alarm_cost · alpha``.

Infos (the same keys at reset and every step): ``phi``, ``error`` (the realised squared error;
``phi`` in expected dynamics), ``step``, ``alpha``, ``detected``, ``detection_probability``
(exact: non-central χ² for a bias, Imhof's integral for a linear attack), ``statistic`` (g; its
mean in expected dynamics), ``threshold``, ``kl`` (the KL divergence of the step's innovation
law from the clean one), ``protected`` ((M,) int8: the sensors guarded at the step).

## Version History

- v0: initial release.

## Example

>>> from fdia_env.stealth import stealth_dynamic_v0
>>> env = stealth_dynamic_v0.parallel_env(dynamics="expected", action="linear", horizon=3)
>>> obs, infos = env.reset(seed=0)
>>> flip = -0.5 * np.eye(3, 4)  # T = I − 4 · 0.5 I = −I: the innovation's sign reversed
>>> for _ in range(3):
...     obs, rewards, terms, truncs, infos = env.step({"attacker": flip})
>>> round(infos["attacker"]["detection_probability"], 6), round(infos["attacker"]["kl"], 6)
(0.05, 0.0)
"""

from __future__ import annotations

import inspect
from typing import Any

import numpy as np

from fdia_env.envs.factory import aec_views
from fdia_env.stealth.dynamic import StealthDynamicEnv
from fdia_env.stealth.stealth_attack_v0 import _Fixed, _Sampled

NAME = "stealth_dynamic_v0"


def parallel_env(scenario: Any = "ch4-position", **kwargs: Any) -> StealthDynamicEnv:
    """The PettingZoo ``ParallelEnv`` (see the module docstring).

    Its options are :class:`~fdia_env.stealth.dynamic.StealthDynamicEnv`'s, listed once there:
    this function's signature is the class's (``inspect.signature`` reads it).
    """
    return StealthDynamicEnv(scenario, **kwargs)


parallel_env.__signature__ = inspect.signature(StealthDynamicEnv).replace(  # type: ignore[attr-defined]
    return_annotation=StealthDynamicEnv
)


def default_opponent(parallel: StealthDynamicEnv, agent: str) -> Any:
    """The other player of a Gymnasium view with ``defender="threshold"``.

    The attacker faces the false-alarm rate of ``alphas`` closest to the env's ``alpha`` (with
    ``defender="protect"``: no protection); the defender faces an attacker that samples its
    action space (a seeded random attack).
    """
    if agent == "attacker" and parallel.defender == "protect":
        return _Fixed(np.zeros(parallel.scenario.system.M, dtype=np.int8))  # nothing protected
    if agent == "attacker":
        alphas = np.asarray(parallel.alphas)
        return _Fixed(np.int64(np.argmin(np.abs(alphas - parallel.alpha))))
    return _Sampled(parallel.action_space("attacker"))


raw_env, env = aec_views(parallel_env)
