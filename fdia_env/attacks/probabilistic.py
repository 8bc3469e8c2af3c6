"""Probabilistic attack: attack with probability p and bias covariance Σ under power a² (ch. 3)."""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from fdia_env.attacks.covariance import CovarianceAttack
from fdia_env.episode import EpisodeSpec
from fdia_env.systems import LinearSystem


class ProbabilisticAttack(CovarianceAttack):
    """Each step nature draws H1 with probability p; under H1 the bias is ``b ~ N(0, Σ)``.

    Action: ``Box(-1, 1, (1 + d,), float32)``: entry 0 maps to ``p = (a₀ + 1) / 2``, the rest to
    Σ exactly as :class:`CovarianceAttack` (per-step power a², ``tr(Ω Σ) = a²``).

    Args:
        power: a² (> 0).
        structure: ``"full"`` or ``"diagonal"`` (see :class:`CovarianceAttack`).
        weight: Power weighting Ω (default :func:`~fdia_env.systems.power_weight`).
    """

    name = "probabilistic"

    def __init__(self, power: float, structure: str = "full", weight: np.ndarray | None = None):
        super().__init__(power, structure=structure, power_mode="per_step", weight=weight)

    def bind(self, system: LinearSystem, spec: EpisodeSpec) -> None:
        """Covariance map plus the probability entry."""
        super().bind(system, spec)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(self.map.size + 1,), dtype=np.float32)

    def to_action(self, probability: float, sigma: np.ndarray) -> np.ndarray:
        """The action that attacks with ``probability`` and covariance ``sigma`` (float32)."""
        if not 0.0 <= float(probability) <= 1.0:
            raise ValueError(f"probability must lie in [0, 1], got {probability}")
        cov = super().sigma_to_action(sigma)
        return np.concatenate([[2.0 * float(probability) - 1.0], cov]).astype(np.float32)

    def batch_reset(self, batch: int, where: Any = None) -> None:
        """Restore the power of the members ``where``; no attack drawn yet (probability 0)."""
        super().batch_reset(batch, where)
        if where is None:
            self.b_probability = self.xp.zeros(batch)
        else:
            self.b_probability[where] = 0.0

    def batch_info(self) -> dict[str, Any]:
        """The covariance attack's infos plus ``attack_probability``."""
        return {**super().batch_info(), "attack_probability": self.xp.copy(self.b_probability)}

    def batch_apply(self, actions: Any) -> tuple[Any, Any]:
        """Attack with the probabilities and covariances the (B, 1 + size) actions map to."""
        xp = self.xp
        a = xp.astype(actions, xp.float64)  # checked by the env (shape, finite, in Box)
        attacked, sigma = super().batch_apply(a[..., 1:])
        self.b_probability = 0.5 * (xp.clip(a[..., 0], -1.0, 1.0) + 1.0)
        return attacked, sigma

    def batch_probability(self) -> Any:
        """(B,) probabilities of the last :meth:`batch_apply`."""
        return self.b_probability
