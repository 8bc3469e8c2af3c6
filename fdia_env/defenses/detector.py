"""Threshold detector: the defender chooses the threshold of a test on the innovation (ch. 3)."""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from fdia_env._validation import as_matrix, check_choice, check_positive, check_psd
from fdia_env.attacks.base import same_sensors
from fdia_env.defenses.base import BatchDetection, DefenseModel
from fdia_env.detection.statistics import STATISTICS
from fdia_env.episode import EpisodeSpec
from fdia_env.systems import LinearSystem

ON_DETECT = ("discard", "incorporate")
CRITERIA = ("mse", "bayes_cost")


def threshold_to_action(threshold: float, scale: float) -> np.ndarray:
    """The (1,) float32 defender action of ``threshold`` under ``τ = s (1 + a) / (1 − a)``.

    Negative thresholds map to a = -1 (declare every measurement an attack), ``inf`` to 1.

    Raises:
        ValueError: For a NaN threshold.
    """
    t = float(threshold)
    if np.isnan(t):
        raise ValueError("threshold must not be NaN")
    if t == np.inf:
        return np.ones(1, dtype=np.float32)
    t = max(t, 0.0)
    return np.array([(t - scale) / (t + scale)], dtype=np.float32)


class ThresholdDetector(DefenseModel):
    """Decide "attacked" when the statistic of the innovation exceeds the chosen threshold τ.

    Action: ``Box(-1, 1, (1,), float32)`` mapped to ``τ = s (1 + a) / (1 − a)``: a bijection of
    [-1, 1] onto [0, ∞] (a = 0 gives τ = s; a = 1 never detects). ``s`` is ``threshold_scale``,
    by default nz for ``"chi2"`` (the statistic's mean under H0) and 1 for ``"quadratic"``.
    :meth:`threshold_to_action` inverts the map.

    Args:
        statistic: A name of :data:`fdia_env.detection.statistics.STATISTICS`: ``"chi2"`` or
            ``"quadratic"`` (the optimal Bayesian one of docs/math.md §3).
        on_detect: ``"discard"`` or ``"incorporate"``.
        assumed_sigma: The defender's model of the bias covariance (nz, nz), PSD; used by the
            quadratic statistic and by ``"incorporate"``.
        fresh_prior: Start every step from the system's prior (static estimation).
        threshold_scale: s (> 0).
        criterion: ``"mse"`` pays the squared estimation error; ``"bayes_cost"`` the fixed cost
            of the (hypothesis, decision) case, ``tr`` of its error covariance (docs/math.md §3).
    """

    name = "threshold_detector"
    passive = False

    def __init__(
        self,
        assumed_sigma: np.ndarray,
        statistic: str = "quadratic",
        on_detect: str = "discard",
        fresh_prior: bool = False,
        threshold_scale: float | None = None,
        criterion: str = "mse",
    ) -> None:
        self.statistic = check_choice("statistic", statistic, tuple(STATISTICS))
        self.on_detect = check_choice("on_detect", on_detect, ON_DETECT)
        self._assumed = assumed_sigma
        self.fresh_prior = bool(fresh_prior)
        self.criterion = check_choice("criterion", criterion, CRITERIA)
        self._scale = (
            None if threshold_scale is None else check_positive("threshold_scale", threshold_scale)
        )

    def bind(self, system: LinearSystem, spec: EpisodeSpec) -> None:
        """Check the assumed covariance against the stacked measurement."""
        assumed = as_matrix("assumed_sigma", self._assumed)
        if assumed.shape != (system.nz, system.nz):
            raise ValueError(
                f"assumed_sigma must be ({system.nz}, {system.nz}), got shape {assumed.shape}"
            )
        check_psd("assumed_sigma", assumed)
        self.assumed_sigma = assumed
        self.scale = self._scale or STATISTICS[self.statistic].scale(system.nz)
        self._all = (1 << system.M) - 1
        self._M = system.M
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)

    def action_to_threshold(self, action: Any) -> float:
        """``τ = s (1 + a) / (1 − a)``; validates the action."""
        try:
            a = np.asarray(action, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError) as exc:
            raise ValueError(
                f"defender action must be a number in [-1, 1], got {action!r}"
            ) from exc
        if a.size != 1 or not np.isfinite(a[0]) or abs(a[0]) > 1.0 + 1e-6:
            raise ValueError(
                f"defender action must be one finite number in [-1, 1], got {action!r}"
            )
        x = float(np.clip(a[0], -1.0, 1.0))
        return float("inf") if x >= 1.0 else self.scale * (1.0 + x) / (1.0 - x)

    def threshold_to_action(self, threshold: float) -> np.ndarray:
        """The action whose threshold is ``threshold`` (negative thresholds map to a = -1)."""
        return threshold_to_action(threshold, self.scale)

    def info_defaults(self, sampled: bool) -> dict[str, Any]:
        """The detector's info keys (zeros before the first step).

        Expected dynamics: ``p_false_alarm``, ``p_detection``, ``threshold``; sampled:
        ``attacked_now``, ``detected``, ``statistic``, ``threshold``.
        """
        if sampled:
            return {"attacked_now": False, "detected": False, "statistic": 0.0, "threshold": 0.0}
        return {"p_false_alarm": 0.0, "p_detection": 0.0, "threshold": 0.0}

    # --- batched (see DefenseModel) --------------------------------------------------------
    batch_backends = ("numpy", "torch")

    def batch_apply(self, actions, attacked, sigma):
        """Every sensor is measured; the per-member thresholds go to :meth:`batch_detection`."""
        xp = self.xp
        a = xp.astype(actions, xp.float64)  # (B, 1), checked by the env (finite, in the Box)
        x = xp.clip(a[..., 0], -1.0, 1.0)
        with np.errstate(divide="ignore"):
            tau = xp.where(x >= 1.0, np.inf, self.scale * (1.0 + x) / (1.0 - x))
        self._b_rule = BatchDetection(
            self.statistic,
            tau,
            self.on_detect,
            self.assumed_sigma,
            self.fresh_prior,
            self.criterion,
        )
        present = None if sigma is None else xp.ones(self._batch, dtype=xp.bool)
        return same_sensors(xp, self._batch, self._all, self._M), sigma, present, False

    @property
    def last_threshold(self) -> float:
        """The single env's threshold τ of the last step (NaN before the first)."""
        rule = getattr(self, "_b_rule", None)
        return float("nan") if rule is None else rule.member(0).threshold

    def batch_detection(self) -> BatchDetection:
        """The per-member thresholds of the last batched step."""
        return self._b_rule
