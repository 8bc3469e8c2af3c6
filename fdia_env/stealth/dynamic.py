"""The dynamic stealthy-attack environment (PettingZoo parallel); see ``stealth_dynamic_v0``."""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces

from fdia_env._validation import (
    MAX_SCALE,
    check_choice,
    check_int,
    check_positions,
    check_positive,
)
from fdia_env.actions import check_step_actions
from fdia_env.scenarios import resolve
from fdia_env.stealth.base import StealthParallelEnv, check_cost
from fdia_env.stealth.dynamic_model import ACTIONS, DynamicModel
from fdia_env.stealth.env import DYNAMICS, ON_DETECT
from fdia_env.stealth.static import check_alpha

MAX_RATIO = 10.0
"""Cap of the observed window statistic, in units of the threshold."""
MAX_LOG_ERROR = 30.0
"""Cap of the observed ``ln(phi / tr P_f)``."""
DEFAULT_HORIZON = 20
DEFENDERS = (None, "threshold", "protect")
"""The defender: none (passive), the detector's false-alarm rate, or the sensors it protects."""


# Largest t_max: the attacked innovation's covariance T P T' + Σ_b spans (1 + t_max)² in scale,
# and its smallest eigenvalues (the KL divergence's log det) are resolved in float64 while that
# times eps stays below ~1e-3; past it they round to zero and the KL to +inf.
MAX_GAIN_SPREAD = 1e6


class StealthDynamicEnv(StealthParallelEnv):
    """An attacker against a Kalman filter with a windowed χ² detector (``stealth_dynamic_v0``).

    Args: as :func:`fdia_env.stealth.stealth_dynamic_v0.parallel_env`.
    """

    metadata: ClassVar[dict[str, Any]] = {
        **StealthParallelEnv.metadata,
        "name": "stealth_dynamic_v0",
    }

    def __init__(
        self,
        scenario: Any = "ch4-position",
        *,
        sensors: Any = None,
        horizon: int | None = None,
        window: int = 5,
        action: str = "bias",
        a_max: float = 5.0,
        t_max: float = 4.0,
        b_max: float = 2.0,
        dynamics: str = "sampled",
        alpha: float = 0.05,
        on_detect: str = "zero",
        penalty: float = 1.0,
        protected: Any = None,
        render_mode: str | None = None,
        max_cycles: int | None = None,
        defender: str | None = None,
        alphas: Any = None,
        false_alarm_cost: float = 1.0,
        protect_budget: int = 1,
    ) -> None:
        sc = resolve(scenario)
        system = sc.system
        self.scenario = sc
        self.sensors = _sensor_positions(system, sensors, "sensors", default_all=True)
        if self.sensors.size == 0:
            raise ValueError("sensors must name at least one sensor to attack, got none")
        self.protected = _sensor_positions(system, protected, "protected", default_all=False)
        self._init_episode(horizon, max_cycles, default_horizon=DEFAULT_HORIZON)
        window = check_int("window", window, minimum=1, maximum=1000)
        self.action_kind = check_choice("action", action, ACTIONS)
        self.dynamics = check_choice("dynamics", dynamics, DYNAMICS)
        self.alpha = check_alpha(alpha)
        self.on_detect = check_choice("on_detect", on_detect, ON_DETECT)
        self.penalty = check_cost("penalty", penalty)
        self._init_players(render_mode, defender, DEFENDERS, alphas, false_alarm_cost)
        self.protect_budget = check_int(
            "protect_budget", protect_budget, minimum=1, maximum=system.M
        )
        row_sensor = np.asarray(system.row_sensor)
        rows = np.flatnonzero(np.isin(row_sensor, self.sensors))
        free = ~np.isin(row_sensor[rows], self.protected)
        self._row_sensor = row_sensor[rows]
        self.model = DynamicModel(
            system=system,
            rows=rows,
            free=free,
            action=self.action_kind,
            window=window,
            a_max=check_positive("a_max", a_max, MAX_SCALE),
            t_max=check_positive("t_max", t_max, MAX_GAIN_SPREAD),
            b_max=check_positive("b_max", b_max, MAX_SCALE),
        )
        self.window = window
        # the attacker alone faces alpha; with a defender, the rate it picks among alphas
        self._rates = self.alphas if defender == "threshold" else (self.alpha,)
        self._tau = self.model.thresholds(self._rates)
        act = spaces.Box(-1.0, 1.0, shape=self.model.action_shape, dtype=np.float32)
        guard = (
            spaces.MultiBinary(system.M)
            if defender == "protect"
            else spaces.Discrete(len(self.alphas))
        )
        low = np.zeros(4, dtype=np.float32)
        high = np.array([1.0, 1.0, MAX_RATIO, MAX_LOG_ERROR], dtype=np.float32)
        self._init_agents(
            defender, {"attacker": act, "defender": guard}, spaces.Box(low, high, dtype=np.float32)
        )

    # --- episode ------------------------------------------------------------------------
    def _clear(self) -> None:
        self._state = self.model.new_state(1)
        self._k = 0
        self._last = {
            "phi": self.model.clean,
            "error": self.model.clean,
            "detected": False,
            "detection_probability": 0.0,
            "statistic": 0.0,
            "threshold": float(self._tau[self._default_rate(), 0]),
            "kl": 0.0,
            "alpha": float(self._rates[self._default_rate()]),
            "protected": self._protected_indicator(self.protected),
        }
        self._history: list[tuple[float, float]] = []

    def _default_rate(self) -> int:
        return int(np.argmin(np.abs(np.asarray(self._rates) - self.alpha)))

    def _restart(self) -> None:
        """Draw the clean filter's error (sampled dynamics) for the new episode."""
        sampled = self.dynamics == "sampled"
        self.model.restart(self._state, np.ones(1, dtype=bool), self.np_random, sampled)

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """One filter step under the attacker's injection and the defender's threshold.

        Raises:
            RuntimeError: Before :meth:`reset` or after the episode ended.
            ValueError: For a missing or unknown agent's action, or one outside its space.
        """
        actions = check_step_actions(
            actions, self.agents, self._action_spaces, self._reset_called, self._done
        )
        rate, free, guarded = self._default_rate(), None, self.protected
        if self.defender == "threshold":
            rate = int(np.asarray(actions["defender"]).reshape(()))
        elif self.defender == "protect":
            guarded = self.protection(actions["defender"])
            free = ~np.isin(self._row_sensor, guarded)[None]
        act = np.asarray(actions["attacker"], dtype=np.float64).reshape(self.model.action_shape)
        alpha = self._rates[rate]
        out = self.model.step(
            self._state,
            act[None],
            np.array([alpha]),
            self._tau[[rate]],
            self.dynamics == "sampled",
            self.np_random,
            free,
        )
        o = {key: value[0] for key, value in out.items()}
        caught = self.detected_reward
        detected = bool(o["detected"])
        p = float(o["p"])
        if self.dynamics == "sampled":
            reward = caught if detected else float(o["error"])
        else:
            reward = (1.0 - p) * float(o["phi"]) + p * caught
        self._k += 1
        self._last = {
            "phi": float(o["phi"]),
            "error": float(o["error"]),
            "detected": detected,
            "detection_probability": p,
            "statistic": float(o["statistic"]),
            "threshold": float(o["threshold"]),
            "kl": float(o["kl"]),
            "alpha": float(alpha),
            "protected": self._protected_indicator(guarded),
        }
        self._history.append((self._last["phi"], self._last["statistic"] / self._last["threshold"]))
        return self._finish_step(reward, alpha, detected)

    def _observe(self) -> np.ndarray:
        last = self._last
        ratio = min(last["statistic"] / last["threshold"], MAX_RATIO)
        grown = min(float(np.log(max(last["phi"] / self.model.clean, 1.0))), MAX_LOG_ERROR)
        return np.array(
            [(self.horizon - self._k) / self.horizon, float(last["detected"]), ratio, grown],
            dtype=np.float32,
        )

    def _info(self) -> dict[str, Any]:
        info = {"step": int(self._k), **self._last}
        info["protected"] = self._last["protected"].copy()
        return info

    def protection(self, action: Any) -> np.ndarray:
        """Sensors protected this step (sorted positions).

        The fixed ``protected`` ones and, with ``defender="protect"``, the first
        ``protect_budget`` sensors the action's bits select (lowest positions first; bits
        beyond the budget are ignored).
        """
        bits = np.flatnonzero(np.asarray(action).reshape(-1))[: self.protect_budget]
        return np.union1d(self.protected, bits)

    def _protected_indicator(self, sensors: np.ndarray) -> np.ndarray:
        out = np.zeros(self.scenario.system.M, dtype=np.int8)
        out[np.asarray(sensors, dtype=np.int64)] = 1
        return out

    def _render_line(self) -> str:
        """The ``"ansi"`` line: the error covariance's trace, g/τ, the alarm."""
        last = self._last
        return (
            f"step {self._k}/{self.horizon}  tr error cov = {last['phi']:.6g}  "
            f"g/τ = {last['statistic'] / last['threshold']:.3f}  detected: {last['detected']}\n"
        )

    def _draw(self, fig: Any) -> None:
        """The ``"rgb_array"`` frame's plot: the error trace and the statistic over the steps."""
        left, right = fig.subplots(1, 2)
        steps = np.arange(1, len(self._history) + 1)
        hist = np.array(self._history).reshape(-1, 2)
        left.plot(steps, hist[:, 0], marker="o")
        left.axhline(self.model.clean, color="grey", linestyle="--", label="no attack")
        left.set_xlabel("step")
        left.set_ylabel("tr error covariance")
        left.legend(loc="upper left")
        right.bar(steps, hist[:, 1])
        right.axhline(1.0, color="red", linestyle="--", label="threshold")
        right.set_xlabel("step")
        right.set_ylabel("g / τ")
        right.legend(loc="upper left")
        fig.suptitle(f"step {self._k}/{self.horizon}, detected: {self._last['detected']}")


def _sensor_positions(system: Any, sensors: Any, param: str, *, default_all: bool) -> np.ndarray:
    """Sorted unique positions of the system's sensors named by ``sensors`` (positions/names)."""
    M = system.M
    if sensors is None:
        return np.arange(M) if default_all else np.zeros(0, dtype=np.int64)
    names = {s.name: i for i, s in enumerate(system.sensors) if s.name}
    return check_positions(param, sensors, names, M, "sensor")
