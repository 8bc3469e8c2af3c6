"""``stealth_attack_v0``: false data against static state estimation with bad-data detection.

## Description

A grid operator estimates the bus angles from its meters by weighted least squares and runs a
bad-data test on the residual (the χ² test at false-alarm rate α, or the largest normalised
residual), see docs/guide/stealth.md. The attacker holds ``budget`` meters and adds an
injection ``a`` to their readings. It wants the estimate moved as far as possible without an
alarm. Every ``a = H c`` is undetectable (the residual does not change and the estimate moves
by c), but on a grid such an attack needs the right meters: the security index of a state is
the fewest meters an undetectable attack on it corrupts. The defender is passive: the env has
the single agent ``"attacker"``. Each step is a fresh measurement snapshot.

## Action Space

``action="shift"`` (default): ``MultiBinary(n)``; bit j shifts state j's estimate by
``magnitude`` radians, i.e. ``a = H c`` with ``c = magnitude · bits`` (only ``a = H c``
shapes). ``action="box_shift"``: the same ``MultiBinary(n)`` bits, shifted as far as the meters'
bound allows, ``c = s · bits`` with ``s = a_max / max_i |(H bits)_i|`` (the largest injection is
``a_max``): the budgeted stealthy attack of ``baselines.stealth.budgeted_attack`` (an exact MILP
over every shift c) restricted to 0/1 directions. ``action="free"``: ``Box(-1, 1, (m,))``,
``a = a_max · action`` (a learner can discover that only ``a = H c`` is safe). Every way,
protected meters get no injection, and when ``a`` would corrupt more than ``budget`` meters only
the ``budget`` largest ``|a_i|`` are written.

## Observation Space

``Box(float32, (3,))``: steps left / N in [0, 1]; whether the last step raised the alarm
(0/1); the last χ² statistic over its threshold, capped at 10 (0 before the first step).

## Rewards

The damage ``|K a|_∞`` (the largest change of any state's estimate, radians) when the test does
not alarm. On an alarm (``on_detect``): 0 (``"zero"``), ``−penalty`` (``"penalty"``) or 0 and the
episode ends (``"end"``). ``dynamics="sampled"`` draws the meter noise and runs the test;
``dynamics="expected"`` pays the expectation with the exact χ² detection probability
``p(a)``: ``(1 − p) · damage + p · (payoff on an alarm)`` (no early end), χ² test only.

## Starting State

Nothing injected yet; the estimator is static (no state carried between snapshots).

## Episode End

Terminates after ``horizon`` snapshots (default 1, or ``max_cycles`` when given), or at the
first alarm with ``on_detect="end"`` (sampled). Truncates after ``max_cycles``.

## Arguments

``scenario`` (a grid case or preset, ``"grid-ieee14"`` default, a ``GridModel``, an (m, n) H or
a :class:`~fdia_env.stealth.StaticEstimation`), ``budget`` (meters, default 6), ``horizon``,
``action`` (``"shift"`` | ``"box_shift"`` | ``"free"``), ``magnitude`` (rad, 0.05, ``"shift"``),
``a_max`` (pu, 0.5, ``"box_shift"`` and ``"free"``),
``dynamics`` (``"sampled"`` | ``"expected"``), ``test`` (``"chi2"`` | ``"lnr"``), ``alpha``
(0.05, or the given StaticEstimation's; another value re-thresholds that model),
``on_detect`` (``"zero"`` | ``"penalty"`` | ``"end"``), ``penalty`` (1.0), ``protected``
(meter positions or names), ``render_mode``, ``max_cycles``; ``defender`` (``None`` |
``"threshold"``), ``alphas`` (the defender's false-alarm rates, default 0.001, 0.01, 0.05, 0.1,
0.2), ``false_alarm_cost`` (1.0).

With ``defender="threshold"`` the env has a second agent ``"defender"`` with ``Discrete(len(
alphas))``: each step it picks the χ² (and LNR) test's false-alarm rate α; its reward is minus
the attacker's minus ``false_alarm_cost · α`` (the expected cost of the false alarms it accepts).
Its Gymnasium view is ``"fdia_env/StealthDefender-v0"`` (the attacker samples its action space);
the attacker's view then faces the rate of ``alphas`` closest to ``alpha``.

Infos (the same keys at reset and every step): ``phi`` (the last damage), ``step``, ``alpha``,
``detected``, ``detection_probability`` (exact, χ² test), ``statistic`` (J; its mean under
``"expected"``), ``meters_used``, ``attacked`` ((m,) int8).

## Version History

- v0: initial release; ``action="box_shift"`` added later (the default and the other actions
  unchanged).

## Example

>>> from fdia_env.stealth import stealth_attack_v0
>>> env = stealth_attack_v0.parallel_env(scenario="grid-ieee14", budget=3, dynamics="expected")
>>> obs, infos = env.reset(seed=0)
>>> bits = [0] * 13
>>> bits[6] = 1  # shift the radial bus 7: 3 meters, undetectable
>>> obs, rewards, terms, truncs, infos = env.step({"attacker": bits})
>>> round(rewards["attacker"], 4), infos["attacker"]["meters_used"]
(0.0475, 3)
"""

from __future__ import annotations

import inspect
from typing import Any

import numpy as np

from fdia_env.envs.factory import aec_views
from fdia_env.envs.policy import PolicyBase, batch_size, repeat_action
from fdia_env.stealth.env import StealthAttackEnv

NAME = "stealth_attack_v0"


def parallel_env(scenario: Any = "grid-ieee14", **kwargs: Any) -> StealthAttackEnv:
    """The PettingZoo ``ParallelEnv`` (see the module docstring).

    Its options are :class:`~fdia_env.stealth.env.StealthAttackEnv`'s, listed once there: this
    function's signature is the class's (``inspect.signature`` and ``train.py --env-kwargs``
    read them).
    """
    return StealthAttackEnv(scenario, **kwargs)


parallel_env.__signature__ = inspect.signature(StealthAttackEnv).replace(  # type: ignore[attr-defined]
    return_annotation=StealthAttackEnv
)


class _Fixed(PolicyBase):
    """Plays one fixed action (SB3 ``predict`` signature)."""

    def __init__(self, action: Any) -> None:
        self.action = np.asarray(action)

    def act(self, observation: Any, deterministic: bool = False) -> np.ndarray:
        return repeat_action(self.action, observation)


class _Sampled(PolicyBase):
    """Samples the attacker's action space (seeded on the view's seeded reset)."""

    def __init__(self, space: Any) -> None:
        self.space = space

    def reset(self, seed: int | None = None) -> None:
        self.space.seed(seed)

    def act(self, observation: Any, deterministic: bool = False) -> Any:
        batch = batch_size(observation)
        if batch is None:
            return self.space.sample()
        return np.stack([self.space.sample() for _ in range(batch)])


def default_opponent(parallel: StealthAttackEnv, agent: str) -> Any:
    """The other player of a Gymnasium view with ``defender="threshold"``.

    The attacker faces the false-alarm rate of ``alphas`` closest to the env's ``alpha``; the
    defender faces an attacker that samples its action space (a seeded random injection).
    """
    if agent == "attacker":
        alphas = np.asarray(parallel.alphas)
        return _Fixed(np.int64(np.argmin(np.abs(alphas - parallel.estimation.alpha))))
    return _Sampled(parallel.action_space("attacker"))


raw_env, env = aec_views(parallel_env)
