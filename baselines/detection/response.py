"""Best responses in the one-step detection game, from its exact expected reward (docs/math.md §3).

In expected dynamics a ``detection_game_v0`` step pays the attacker the exact expected squared
error (``criterion="mse"``) or the literature's Bayes cost (``"bayes_cost"``) of the defender's
threshold test against the attack (p, Σ); the defender is paid minus it. Nothing is random, so
the reward of a pair of actions is a deterministic function, computed here through
:func:`~baselines.detection.evaluate.expected_mse` /
:func:`~baselines.detection.evaluate.bayes_cost` of a
:class:`~baselines.detection.detectors.Detector` designed on the defender's model, with the
attacker's (p, Σ) as the truth (:class:`DetectionGame`).

- :func:`best_threshold`: the defender's best threshold against a fixed attack, a 1-D
  optimisation over the defender's action ``a ∈ [-1, 1]`` (``τ = s (1 + a) / (1 − a)``): a fine
  grid, then a bounded scalar refinement around the best grid point. Under the Bayes cost it
  recovers OBDD's α (the Bayes test's threshold); under the true MSE the optimum differs.
- :func:`best_attack`: the attacker's best (p, Σ) against a fixed threshold. The reward is
  linear in p (``p R1(Σ) + (1 − p) R0``, R0 independent of Σ), so p* is 0 or 1 and Σ maximises
  R1 over the attacker's action box (the factor entries of
  :class:`~fdia_env.attacks.covariance.CovarianceMap`): seeded multi-start, the best starts
  refined by bounded Nelder-Mead.

>>> from fdia_env import detection_game_v0
>>> env = detection_game_v0.parallel_env(scenario="ch3-static", power=1000.0)
>>> game = DetectionGame.of(env)
>>> best = best_threshold(game, game.preset_probability, game.preset_sigma)
>>> round(best.threshold, 2), round(best.value, 2)  # OBDD (always detect) pays -200
(1.88, -168.87)
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import minimize, minimize_scalar

from baselines.detection.detectors import Detector
from baselines.detection.evaluate import bayes_cost, expected_mse
from baselines.detection.problem import DetectionProblem, check_probability
from fdia_env.attacks.covariance import CovarianceMap
from fdia_env.defenses.detector import CRITERIA, ThresholdDetector, threshold_to_action
from fdia_env.detection_game_v0 import _prior

GRID = 201  # default grid of defender actions in [-1, 1]
STARTS = 16  # default random starts of the attacker's search


@dataclass(frozen=True, eq=False)
class DetectionGame:
    """The one-step detection game of a ``detection_game_v0`` env, in exact expected dynamics.

    Attributes:
        design: The defender's model: the prior at the attack step, H, R, its assumed Σ (the
            detector's statistic and gains are built from it) and the preset's p1.
        statistic: ``"quadratic"`` or ``"chi2"``.
        on_detect: ``"discard"`` or ``"incorporate"``.
        criterion: ``"mse"`` or ``"bayes_cost"`` (what the step pays).
        scale: ``s`` of the defender's threshold map ``τ = s (1 + a) / (1 − a)``.
        power: The attack power a² (``tr(Ω Σ)``).
        cov_map: The attacker's map from factor entries to Σ.
        preset_probability: The preset attacker's p (p1 of the scenario).
        preset_sigma: The preset attacker's Σ (the c2-maximising one of the power).
    """

    design: DetectionProblem
    statistic: str
    on_detect: str
    criterion: str
    scale: float
    power: float
    cov_map: CovarianceMap = field(repr=False)
    preset_probability: float
    preset_sigma: np.ndarray = field(repr=False)

    def __post_init__(self) -> None:
        if self.criterion not in CRITERIA:
            raise ValueError(f"criterion must be one of {list(CRITERIA)}, got {self.criterion!r}")

    @classmethod
    def of(cls, env: Any) -> DetectionGame:
        """The game of a ``detection_game_v0`` parallel env or one of its Gymnasium views.

        Raises:
            ValueError: For any other env, or one whose episodes are longer than one attack
                step or pay a shaped reward (no one-step game).
        """
        parallel = getattr(getattr(env, "unwrapped", env), "parallel", env)
        defense = getattr(parallel, "defense", None)
        if not isinstance(defense, ThresholdDetector) or not hasattr(parallel, "default_sigma"):
            raise ValueError(f"env must be a detection_game_v0 env or view, got {env!r}")
        spec = parallel.spec
        if spec.horizon != 1 or spec.reward_mode == "shaped" or spec.dynamics != "expected":
            raise ValueError(
                "env must be the one-step game in expected dynamics (horizon=1, "
                f"dynamics='expected', no shaped reward), got horizon={spec.horizon}, "
                f"dynamics={spec.dynamics!r}, reward_mode={spec.reward_mode!r}"
            )
        system = parallel.system
        design = DetectionProblem(
            system.x0,
            _prior(system, spec),
            system.H,
            system.R,
            defense.assumed_sigma,
            parallel.default_p1,
        )
        return cls(
            design,
            defense.statistic,
            defense.on_detect,
            defense.criterion,
            defense.scale,
            parallel.attack.power,
            parallel.attack.map,
            parallel.default_p1,
            np.array(parallel.default_sigma),
        )

    # --- the players' action maps (the env's) ------------------------------------------------
    def threshold(self, action: Any) -> float:
        """The defender's τ of ``action`` (a number or (1,) array in [-1, 1])."""
        a = _unit("defender action", np.asarray(action, dtype=np.float64).reshape(-1), 1)[0]
        return math.inf if a >= 1.0 else float(self.scale * (1.0 + a) / (1.0 - a))

    def threshold_action(self, threshold: float) -> np.ndarray:
        """The defender's (1,) float32 action of ``threshold`` (negative ones: a = -1)."""
        return threshold_to_action(threshold, self.scale)

    def attack(self, action: Any) -> tuple[float, np.ndarray]:
        """``(p, Σ)`` of an attacker action (``(1 + d,)`` in [-1, 1])."""
        a = _unit("attacker action", np.asarray(action, dtype=np.float64), 1 + self.cov_map.size)
        return 0.5 * (a[0] + 1.0), self.cov_map.to_sigma(a[1:], self.power)

    def attack_action(self, probability: float, sigma: np.ndarray) -> np.ndarray:
        """The attacker's float32 action of ``(probability, sigma)``."""
        p = check_probability("probability", probability)
        cov = self.cov_map.to_action(np.asarray(sigma, dtype=np.float64))
        return np.concatenate([[2.0 * p - 1.0], cov]).astype(np.float32)

    # --- the exact reward --------------------------------------------------------------------
    def detector(self, threshold: float) -> Detector:
        """The defender's test at ``threshold`` as a :class:`Detector` on its model."""
        return Detector("threshold", self.design, self.statistic, threshold, self.on_detect)

    def attacker_reward(self, probability: float, sigma: np.ndarray, threshold: float) -> float:
        """The attacker's exact expected reward (the defender's is minus it).

        Args:
            probability: The attack probability p.
            sigma: (nz, nz) the attacker's Σ.
            threshold: The defender's τ (``inf``: never detect).
        """
        p = check_probability("probability", probability)
        truth = dataclasses.replace(self.design, Pbb=np.asarray(sigma, dtype=np.float64), p1=p)
        detector = self.detector(threshold)
        if self.criterion == "mse":
            return expected_mse(detector, truth)
        return bayes_cost(detector, truth).value

    def reward(self, attacker_action: Any, defender_action: Any) -> float:
        """The attacker's exact expected reward for a pair of env actions."""
        p, sigma = self.attack(attacker_action)
        return self.attacker_reward(p, sigma, self.threshold(defender_action))


@dataclass(frozen=True)
class ThresholdResponse:
    """The defender's best threshold against a fixed attack.

    Attributes:
        action: (1,) float32 defender action; ``value`` is the reward at this (rounded) action.
        threshold: Its τ.
        value: The defender's reward there (minus the expected cost).
        grid: (G,) the grid of actions searched; ``grid_values`` (G,) the defender's reward on it.
    """

    action: np.ndarray
    threshold: float
    value: float
    grid: np.ndarray = field(repr=False)
    grid_values: np.ndarray = field(repr=False)


@dataclass(frozen=True)
class AttackResponse:
    """The attacker's best (p, Σ) against a fixed threshold.

    Attributes:
        action: (1 + d,) float32 attacker action; ``value`` is the reward at this action.
        probability: Its p (0 or 1: the reward is linear in p).
        sigma: Its Σ.
        value: The attacker's reward there.
        no_attack: The reward at p = 0 (whatever Σ).
        evaluations: Reward evaluations spent.
    """

    action: np.ndarray
    probability: float
    sigma: np.ndarray = field(repr=False)
    value: float
    no_attack: float
    evaluations: int


def best_threshold(
    game: DetectionGame, probability: float, sigma: np.ndarray, grid: int = GRID
) -> ThresholdResponse:
    """The defender's best threshold against the attack ``(probability, sigma)``.

    A grid of ``grid`` actions evenly spaced on [-1, 1] (a = 1: never detect), then
    ``scipy.optimize.minimize_scalar(method="bounded")`` between the best grid point's
    neighbours; the answer is the better of the two, rounded to the env's float32 action and
    re-evaluated there.

    Raises:
        ValueError: For ``grid`` not an integer >= 3 (naming it), or a bad probability.
    """
    if isinstance(grid, bool) or not isinstance(grid, numbers.Integral) or grid < 3:
        raise ValueError(f"grid must be an integer >= 3, got {grid!r}")
    check_probability("probability", probability)

    def value(a: float) -> float:
        return -game.attacker_reward(probability, sigma, game.threshold(a))

    actions = np.linspace(-1.0, 1.0, int(grid))
    values = np.array([value(a) for a in actions])
    i = int(np.argmax(values))
    best_a, best_v = float(actions[i]), float(values[i])
    lo, hi = actions[max(i - 1, 0)], actions[min(i + 1, grid - 1)]
    fine = minimize_scalar(lambda a: -value(a), bounds=(lo, hi), method="bounded")
    if -fine.fun > best_v:
        best_a = float(fine.x)
    action = np.array([best_a], dtype=np.float32)
    return ThresholdResponse(
        action, game.threshold(action), value(float(action[0])), actions, values
    )


def best_attack(
    game: DetectionGame,
    threshold: float,
    starts: int = STARTS,
    refine: int = 4,
    seed: int = 0,
) -> AttackResponse:
    """The attacker's best ``(p, Σ)`` against the defender's ``threshold``.

    R1(Σ) (the reward at p = 1) is evaluated at the preset's Σ and ``starts − 1`` seeded uniform
    points of the factor box; the ``refine`` best are refined by bounded Nelder-Mead. p* = 1
    when the best R1 exceeds R0 (the reward at p = 0), else 0.

    Raises:
        ValueError: For ``starts`` or ``refine`` not an integer >= 1 (naming it), or a NaN
            threshold.
    """
    for name, v in (("starts", starts), ("refine", refine)):
        if isinstance(v, bool) or not isinstance(v, numbers.Integral) or v < 1:
            raise ValueError(f"{name} must be an integer >= 1, got {v!r}")
    if math.isnan(float(threshold)):
        raise ValueError("threshold must not be NaN")
    d = game.cov_map.size
    count = 0

    def r1(entries: np.ndarray) -> float:
        nonlocal count
        count += 1
        sigma = game.cov_map.to_sigma(np.clip(entries, -1.0, 1.0), game.power)
        return game.attacker_reward(1.0, sigma, threshold)

    rng = np.random.default_rng(seed)
    points = [game.cov_map.to_action(game.preset_sigma)]
    points += list(rng.uniform(-1.0, 1.0, size=(int(starts) - 1, d)))
    values = [r1(x) for x in points]
    best_x, best_v = points[int(np.argmax(values))], max(values)
    for i in np.argsort(values)[::-1][: int(refine)]:
        res = minimize(
            lambda x: -r1(x),
            points[i],
            method="Nelder-Mead",
            bounds=[(-1.0, 1.0)] * d,
            options={"xatol": 1e-5, "fatol": 1e-9 * max(1.0, abs(values[i])), "maxiter": 400},
        )
        if -res.fun > best_v:
            best_x, best_v = np.clip(res.x, -1.0, 1.0), float(-res.fun)
    no_attack = game.attacker_reward(0.0, game.preset_sigma, threshold)
    count += 1
    p = 1.0 if best_v > no_attack else 0.0
    action = np.concatenate([[2.0 * p - 1.0], best_x]).astype(np.float32)
    p_act, sigma = game.attack(action)
    value = game.attacker_reward(p_act, sigma, threshold)
    return AttackResponse(action, p_act, sigma, value, no_attack, count + 1)


def _unit(name: str, a: np.ndarray, size: int) -> np.ndarray:
    """``a`` if it is ``size`` finite numbers in [-1, 1] (clipped), else a ValueError."""
    if a.shape != (size,) or not np.all(np.isfinite(a)) or np.any(np.abs(a) > 1.0 + 1e-6):
        raise ValueError(f"{name} must be {size} finite number(s) in [-1, 1], got {a.tolist()}")
    return np.clip(a, -1.0, 1.0)


def minimax_threshold(
    game: DetectionGame, grid: int = 21, starts: int = 6, refine: int = 1, seed: int = 0
) -> ThresholdResponse:
    """The threshold whose worst case over every attack is best (a pure security strategy).

    For each of ``grid`` defender actions evenly spaced on [-1, 1] the attacker's
    :func:`best_attack` (with ``starts`` and ``refine``) gives the worst case; the best worst
    case is returned (``value``: the defender's reward there; ``grid_values``: the worst cases).
    A coarse search: the worst case is exact at the grid points only.

    Raises:
        ValueError: For ``grid`` not an integer >= 2, or bad ``starts`` / ``refine``.
    """
    if isinstance(grid, bool) or not isinstance(grid, numbers.Integral) or grid < 2:
        raise ValueError(f"grid must be an integer >= 2, got {grid!r}")
    actions = np.linspace(-1.0, 1.0, int(grid)).astype(np.float32)
    worst = np.array(
        [-best_attack(game, game.threshold(a), starts, refine, seed).value for a in actions]
    )
    i = int(np.argmax(worst))
    action = actions[i : i + 1].copy()
    return ThresholdResponse(action, game.threshold(action), float(worst[i]), actions, worst)
