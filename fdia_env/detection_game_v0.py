"""``detection_game_v0``: an attacker that injects with probability p against a threshold detector.

## Description

The filter's measurement at the attack time is biased with probability ``p`` by ``b ~ N(0, Σ)``
(power ``tr(Ω Σ) = a²``). The defender tests the innovation ``y = z − H x̂[k|k−1]`` with the
statistic ``"chi2"`` (``y' Pzz0⁻¹ y``) or ``"quadratic"`` (``y'(Pzz0⁻¹ − Pzz1⁻¹) y``, the optimal
Bayesian statistic, built from the defender's model ``assumed_sigma`` of Σ) and declares an attack
when it exceeds its threshold; on detection it discards the measurement or incorporates it with
the attack model (docs/math.md §3). Two settings, by scenario: ``"ch3-static"`` (a static parameter
with prior N(x̄, Pxx), estimated afresh every round) and ``"ch3-tracking"`` (the tracking filter
attacked at step K = 100, after K − 1 clean steps).

## Action Space

Attacker: ``Box(-1, 1, (1 + d,))``: ``p = (a₀ + 1) / 2`` and the factor entries of Σ
(:class:`~fdia_env.attacks.probabilistic.ProbabilisticAttack`). Defender: ``Box(-1, 1, (1,))``
mapped to ``τ = s (1 + a) / (1 − a)`` on [0, ∞]
(:class:`~fdia_env.defenses.detector.ThresholdDetector`). The edge ``a = 1`` is the threshold
``τ = ∞``, "never detect": the info's ``threshold`` is then ``inf`` (exactly what the action
means; every reward and every other info stays finite).

## Observation Space

``Box(float32)``: steps left / N, log variance growth and correlations of the error covariance
(expected) or of the filter's covariance (sampled), and the last NIS in sampled mode.

## Rewards

Expected dynamics pay ± the *exact* expected squared error ``E||x − x̂||²`` of the step (computed
by Imhof's method on generalized chi-square tails, :mod:`fdia_env.detection.expected`); sampled
dynamics pay ± the squared error of the draw, whose mean agrees with it. (The literature's Bayes
cost, built from fixed costs c1..c4, is not the true MSE; ``baselines.detection`` reports both.)

``criterion="bayes_cost"`` pays the literature's Bayes cost instead: the fixed cost c1..c4 of
the (hypothesis, decision) case, so that a threshold sweep recovers OBDD's α.

## Episode End

After ``horizon`` attack steps (default 1). Expected dynamics need ``horizon=1`` in the tracking
setting (after one detection the error is no longer Gaussian); the static setting restarts from
the prior every round, so any horizon works.

## Arguments

``scenario`` (``"ch3-static"`` default, ``"ch3-tracking"`` or a system), ``power`` (a², default
100), ``statistic``, ``on_detect``, ``criterion`` (``"mse"`` | ``"bayes_cost"``),
``assumed_sigma`` (default: the c2-maximising Σ of the power,
docs/math.md §3), ``horizon``, ``warmup``, ``objective``, ``reward_mode``, ``dynamics``,
``render_mode`` (``"human"`` | ``"ansi"`` | ``"rgb_array"``), ``max_cycles``. The Gymnasium
views ``fdia_env/DetectionDefender-v0`` (the attacker fixed to p1 of the preset and the
c2-maximising Σ) and ``fdia_env/DetectionAttacker-v0`` (the defender fixed to the threshold
``s``, action 0) take ``opponent=`` to change the fixed player.

## Version History

- v0: initial release. Infos with the same keys at reset and at every step, ``max_cycles``,
  ``render_mode="human"``.

## Example

>>> from fdia_env import detection_game_v0
>>> env = detection_game_v0.parallel_env(scenario="ch3-static", power=100.0)
>>> _ = env.reset(seed=0)
>>> attack = default_opponent(env, "defender").predict(None)[0]
>>> never = env.defense.threshold_to_action(float("inf"))
>>> _, rewards, *_ = env.step({"attacker": attack, "defender": never})
>>> round(rewards["attacker"], 3)  # never detects: 0.85 c2 + 0.15 c4 = 0.85·101.02 + 0.15·6.759
86.879
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fdia_env.attacks.probabilistic import ProbabilisticAttack
from fdia_env.defenses.detector import ThresholdDetector
from fdia_env.detection.attack import c2_optimal_pbb
from fdia_env.envs.factory import aec_views, episode_spec, with_episode_parameters
from fdia_env.envs.parallel import FdiaParallelEnv
from fdia_env.envs.policy import PolicyBase, repeat_action
from fdia_env.envs.simulation import Simulation
from fdia_env.episode import EpisodeSpec
from fdia_env.kalman import predict_cov
from fdia_env.scenarios import Scenario
from fdia_env.systems import LinearSystem

NAME = "detection_game_v0"


@with_episode_parameters(
    "scenario",
    "power",
    "statistic",
    "on_detect",
    "assumed_sigma",
    "criterion",
    "horizon",
    "warmup",
    "objective",
    "reward_mode",
    "dynamics",
    "render_mode",
    "max_cycles",
)
def parallel_env(
    scenario: str | Scenario | LinearSystem = "ch3-static",
    power: float = 100.0,
    statistic: str = "quadratic",
    on_detect: str = "discard",
    assumed_sigma: np.ndarray | None = None,
    criterion: str = "mse",
    render_mode: str | None = None,
    **episode: Any,
) -> FdiaParallelEnv:
    """The PettingZoo ``ParallelEnv`` (see the module docstring)."""
    episode["warmup"] = _warmup(scenario, episode["warmup"])
    sc, spec = episode_spec(scenario, default_horizon=1, **episode)
    static = _is_static(sc.system)
    if spec.dynamics == "expected" and not static and spec.horizon > 1:
        raise ValueError(
            f"horizon must be 1 with dynamics='expected' in the tracking setting (after one "
            f"detection the estimation error is no longer Gaussian), got {spec.horizon} (from "
            f"horizon, or max_cycles when horizon is not given, on the non-static scenario "
            f"{sc.name!r}); use dynamics='sampled'"
        )
    attack = ProbabilisticAttack(power)
    sigma = c2_optimal_pbb(_prior(sc.system, spec), sc.system.H, sc.system.R, attack.power)
    if assumed_sigma is None:
        assumed_sigma = sigma
    defense = ThresholdDetector(
        assumed_sigma,
        statistic=statistic,
        on_detect=on_detect,
        fresh_prior=static,
        criterion=criterion,
    )
    env = FdiaParallelEnv(
        sc,
        attack,
        defense,
        spec,
        render_mode=render_mode,
        name=NAME,
        max_cycles=episode["max_cycles"],
    )
    env.default_sigma = sigma
    env.default_p1 = float(sc.extra.get("p1", 0.85))
    return env


raw_env, env = aec_views(parallel_env)


class FixedAction(PolicyBase):
    """A policy that always plays ``action`` (SB3 ``predict`` signature)."""

    def __init__(self, action: np.ndarray) -> None:
        self.action = np.asarray(action, dtype=np.float32)

    def act(self, observation: Any, deterministic: bool = False) -> np.ndarray:
        """The fixed action, batched when the observation is a batch."""
        return repeat_action(self.action, observation)


def default_opponent(parallel: FdiaParallelEnv, agent: str) -> FixedAction:
    """The fixed other player of a Gymnasium view of ``agent``.

    The defender faces the preset's attacker (p1, the c2-maximising Σ); the attacker faces the
    threshold ``s`` (action 0).
    """
    if agent == "defender":
        return FixedAction(parallel.attack.to_action(parallel.default_p1, parallel.default_sigma))
    return FixedAction(np.zeros(1, dtype=np.float32))


def _is_static(system: LinearSystem) -> bool:
    """A static parameter: F = I and Q = 0."""
    return bool(np.allclose(system.F, np.eye(system.n)) and not np.any(system.Q))


def _warmup(scenario: Any, warmup: int | str | None) -> int | str | None:
    """Default: the tracking preset's attack step K comes after K − 1 clean steps."""
    if warmup is None and isinstance(scenario, str) and scenario == "ch3-tracking":
        return 99
    return warmup


def _prior(system: LinearSystem, spec: EpisodeSpec) -> np.ndarray:
    """Covariance of the state at the first attack step, before its measurement."""
    if _is_static(system):
        return np.array(system.P0)
    return predict_cov(Simulation(system, spec).P_start, system.F, system.Q)
