"""The static stealthy-attack environment (PettingZoo parallel); see ``stealth_attack_v0``."""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces

from fdia_env._validation import MAX_SCALE, check_choice, check_int, check_positive
from fdia_env.actions import check_step_actions
from fdia_env.stealth.base import StealthParallelEnv, check_cost
from fdia_env.stealth.static import (
    StaticEstimation,
    check_alpha,
    sidak_threshold,
    static_estimation,
)

ACTIONS = ("shift", "box_shift", "free")
DYNAMICS = ("expected", "sampled")
ON_DETECT = ("zero", "penalty", "end")
DEFENDERS = (None, "threshold")
TESTS = ("chi2", "lnr")
MAX_RATIO = 10.0
"""Cap of the observed χ² statistic, in units of the threshold."""


class StealthAttackEnv(StealthParallelEnv):
    """One attacker against WLS state estimation with a bad-data test (see ``stealth_attack_v0``).

    Args: as :func:`fdia_env.stealth.stealth_attack_v0.parallel_env`.
    """

    metadata: ClassVar[dict[str, Any]] = {
        **StealthParallelEnv.metadata,
        "name": "stealth_attack_v0",
    }

    def __init__(
        self,
        scenario: Any = "grid-ieee14",
        *,
        budget: int = 6,
        horizon: int | None = None,
        action: str = "shift",
        magnitude: float = 0.05,
        a_max: float = 0.5,
        dynamics: str = "sampled",
        test: str = "chi2",
        alpha: float | None = None,
        on_detect: str = "zero",
        penalty: float = 1.0,
        protected: Any = None,
        render_mode: str | None = None,
        max_cycles: int | None = None,
        defender: str | None = None,
        alphas: Any = None,
        false_alarm_cost: float = 1.0,
    ) -> None:
        if isinstance(scenario, StaticEstimation):
            est = scenario
            if alpha is not None and check_alpha(alpha) != est.alpha:
                # same model (R, meters) at another false-alarm rate; Šidák's LNR threshold
                est = dataclasses.replace(
                    est, alpha=float(alpha), lnr_threshold=sidak_threshold(float(alpha), est.m)
                )
        else:
            est = _estimation(scenario, check_alpha(0.05 if alpha is None else alpha))
        self.estimation = est
        self.budget = check_int("budget", budget, minimum=1, maximum=est.m)
        self._init_episode(horizon, max_cycles, default_horizon=1)  # one snapshot
        self.action_kind = check_choice("action", action, ACTIONS)
        self.magnitude = check_positive("magnitude", magnitude, MAX_SCALE)
        self.a_max = check_positive("a_max", a_max, MAX_SCALE)
        self.dynamics = check_choice("dynamics", dynamics, DYNAMICS)
        check_choice("test", test, TESTS)
        if test == "lnr" and self.dynamics == "expected":
            raise ValueError(
                "test='lnr' needs dynamics='sampled': the largest-normalised-residual test has "
                "no closed-form detection probability"
            )
        self.test = test
        self.on_detect = check_choice("on_detect", on_detect, ON_DETECT)
        self.penalty = check_cost("penalty", penalty)
        self.protected = est.meter_positions(protected, "protected")
        self._init_players(render_mode, defender, DEFENDERS, alphas, false_alarm_cost)
        self._estimations = [
            est
            if a == est.alpha
            else dataclasses.replace(est, alpha=a, lnr_threshold=sidak_threshold(a, est.m))
            for a in self.alphas
        ]
        if self.action_kind in ("shift", "box_shift"):
            act: spaces.Space = spaces.MultiBinary(est.n)
        else:
            act = spaces.Box(-1.0, 1.0, shape=(est.m,), dtype=np.float32)
        self._action_space = act
        low = np.zeros(3, dtype=np.float32)
        high = np.array([1.0, 1.0, MAX_RATIO], dtype=np.float32)
        self._L = np.linalg.cholesky(est.R)
        self._init_agents(
            defender,
            {"attacker": act, "defender": spaces.Discrete(len(self.alphas))},
            spaces.Box(low, high, dtype=np.float32),
        )

    # --- the model ----------------------------------------------------------------------
    def injection(self, action: Any) -> np.ndarray:
        """(m,) the injection an action makes: shift or free, protected meters zeroed, trimmed.

        ``"box_shift"`` scales the shift ``H bits`` so that its largest ``|a_i|`` is ``a_max``
        (:func:`box_scale`). The attacker holds ``budget`` meters: when the action would corrupt
        more, only the ``budget`` largest ``|a_i|`` (ties: the lower position) are written.
        """
        est = self.estimation
        if self.action_kind == "shift":
            a = est.H @ (self.magnitude * np.asarray(action, dtype=np.float64).reshape(est.n))
        elif self.action_kind == "box_shift":
            a = est.H @ np.asarray(action, dtype=np.float64).reshape(est.n)
            a = a * box_scale(a[None, :], self.a_max)[0]
        else:
            a = self.a_max * np.clip(np.asarray(action, dtype=np.float64).reshape(est.m), -1, 1)
        a[self.protected] = 0.0
        scale = float(np.max(np.abs(a))) if a.size else 0.0
        a[np.abs(a) <= 1e-12 * max(scale, 1e-300)] = 0.0
        nonzero = np.flatnonzero(a)
        if nonzero.size > self.budget:
            order = np.argsort(-np.abs(a), kind="stable")
            a[order[self.budget :]] = 0.0
        return a

    def damage(self, a: np.ndarray) -> float:
        """The largest change the injection makes to any state's estimate, ``|K a|_∞``."""
        return float(np.max(np.abs(self.estimation.estimate_shift(a))))

    def _clear(self) -> None:
        self._k = 0
        self._last = {
            "phi": 0.0,
            "detected": False,
            "detection_probability": 0.0,
            "statistic": 0.0,
            "meters_used": 0,
            "attacked": np.zeros(self.estimation.m, dtype=np.int8),
            "alpha": float(self.estimation.alpha),
        }
        self._last_a = np.zeros(self.estimation.m)

    # --- PettingZoo API -----------------------------------------------------------------
    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """Inject, run the estimator and its bad-data test on one snapshot.

        Raises:
            RuntimeError: Before :meth:`reset` or after the episode ended.
            ValueError: For a missing or unknown agent's action, or one outside its space.
        """
        actions = check_step_actions(
            actions, self.agents, self._action_spaces, self._reset_called, self._done
        )
        est = self.estimation
        if self.defender is not None:
            est = self._estimations[int(np.asarray(actions["defender"]).reshape(()))]
        a = self.injection(actions["attacker"])
        damage = self.damage(a)
        p = float(est.detection_probability(a)) if self.test == "chi2" else float("nan")
        if self.dynamics == "sampled":
            e = self._L @ self.np_random.standard_normal(est.m)
            # the residual of e + a (it does not depend on the true state)
            z = est.attacked_residual(e, a)
            detected = bool(est.alarm(z, self.test))
            statistic = float(est.statistic(z))
            reward = self.detected_reward if detected else damage
        else:
            detected = False
            statistic = float(est.noncentrality(a) + est.dof)  # E[J] under the injection
            reward = (1.0 - p) * damage + p * self.detected_reward
        self._k += 1
        self._last_a = a
        self._last = {
            "phi": damage,
            "detected": detected,
            "detection_probability": 0.0 if np.isnan(p) else p,
            "statistic": statistic,
            "meters_used": int(np.count_nonzero(a)),
            "attacked": (a != 0.0).astype(np.int8),
            "alpha": float(est.alpha),
        }
        return self._finish_step(reward, est.alpha, detected)

    def _observe(self) -> np.ndarray:
        ratio = min(self._last["statistic"] / self.estimation.threshold, MAX_RATIO)
        return np.array(
            [(self.horizon - self._k) / self.horizon, float(self._last["detected"]), ratio],
            dtype=np.float32,
        )

    def _info(self) -> dict[str, Any]:
        info = {"step": int(self._k), **self._last}
        info["attacked"] = self._last["attacked"].copy()
        return info

    def _render_line(self) -> str:
        """The ``"ansi"`` line: the meters injected, the shift, the alarm."""
        names = [self.estimation.meters[i] for i in np.flatnonzero(self._last_a)]
        return (
            f"step {self._k}/{self.horizon}  meters: {', '.join(names) or 'none'}  "
            f"shift = {self._last['phi']:.6g}  detected: {self._last['detected']}\n"
        )

    def _draw(self, fig: Any) -> None:
        """The ``"rgb_array"`` frame's plot: the injection per meter."""
        ax = fig.subplots()
        ax.bar(np.arange(self.estimation.m), self._last_a)
        ax.set_xlabel("meter")
        ax.set_ylabel("injection (pu)")
        ax.set_title(f"step {self._k}/{self.horizon}, detected: {self._last['detected']}")


def box_scale(a: np.ndarray, a_max: float) -> np.ndarray:
    """(B, 1) the factor that brings each row of (B, m) ``a`` to ``max_i |a_i| = a_max`` (0: 1).

    ``action="box_shift"``'s shift ``c = s · bits``: the largest one whose injection ``H c``
    stays inside the meters' bound, ``s = a_max / max_i |(H bits)_i|``.
    """
    size = np.max(np.abs(a), axis=1, keepdims=True)
    return a_max / np.where(size > 0.0, size, a_max)


def _estimation(scenario: Any, alpha: float) -> StaticEstimation:
    """:func:`static_estimation` of ``scenario``, or ``ValueError`` naming ``scenario``.

    ``alpha`` is already checked, so every error of the call is about ``scenario``.
    """
    from fdia_env.systems.grid import CASES

    allowed = (
        f"a grid case {sorted(CASES)}, a grid preset ('grid-ieee14', ...), a GridModel, a "
        "StaticEstimation or an (m, n) matrix H (m > n, full column rank)"
    )
    if scenario is None or isinstance(scenario, bool | bytes | dict):  # not read as an H
        raise ValueError(f"scenario must be {allowed}, got {scenario!r}")
    try:
        return static_estimation(scenario, alpha=alpha)
    except (TypeError, ValueError) as exc:
        why = "" if isinstance(scenario, str) else f" ({exc})"
        raise ValueError(f"scenario must be {allowed}, got {scenario!r}{why}") from exc
