"""The defense-model interface: which data the filter trusts."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from gymnasium import spaces

from fdia_env.attacks.base import AttackEffect, BatchOfOneModel, check_space
from fdia_env.backend import NUMPY, Backend
from fdia_env.episode import EpisodeSpec
from fdia_env.systems import LinearSystem


class FilterInput(NamedTuple):
    """What reaches the filter in one step.

    Attributes:
        used: Bitmask of the sensors whose measurements the filter incorporates with its nominal
            gain (bit i set = sensor i, 0-based).
        leaked_sigma: (nz, nz) covariance of the bias that reaches the filter through used
            sensors, or None if no bias gets through.
        steady: The filter has been running on ``used`` long enough to be in its steady state
            before this step (the one-shot setting of the sensor-selection game): P and the
            actual error covariance restart there.
        detection: A detector that decides, from the measurement, whether the filter uses it
            (the detection game); None for the other models.
        attack_probability: Probability that the bias is present this step.
    """

    used: int
    leaked_sigma: np.ndarray | None = None
    steady: bool = False
    detection: Detection | None = None
    attack_probability: float = 1.0


@dataclass(frozen=True)
class Detection:
    """A detector on the innovation ``y = z − H x̂[k|k−1]`` (docs/math.md §3).

    Attributes:
        statistic: ``"chi2"`` (``y' Pzz0⁻¹ y``) or ``"quadratic"`` (``y'(Pzz0⁻¹ − Pzz1⁻¹)y``).
        threshold: τ: D1 when the statistic exceeds it (may be ``inf``).
        on_detect: ``"discard"`` (keep the prediction) or ``"incorporate"`` (update with the
            attack model, ``Pzz1 = Pzz0 + assumed_sigma``).
        assumed_sigma: (nz, nz) the defender's model of the bias covariance.
        fresh_prior: Every step starts from the system's prior (a static parameter estimated
            afresh each round) instead of continuing the filter.
        criterion: What a step costs: ``"mse"`` (the squared error) or ``"bayes_cost"`` (the
            fixed cost c1..c4 of the case, docs/math.md §3).
    """

    statistic: str
    threshold: float
    on_detect: str
    assumed_sigma: np.ndarray
    fresh_prior: bool = False
    criterion: str = "mse"


@dataclass(frozen=True)
class BatchDetection:
    """:class:`Detection` for a batch: one threshold per member, the rest shared."""

    statistic: str
    thresholds: np.ndarray
    on_detect: str
    assumed_sigma: np.ndarray
    fresh_prior: bool
    criterion: str

    def member(self, i: int) -> Detection:
        """The single-env rule of member ``i`` (the batch of one holds one threshold)."""
        t = self.thresholds
        return Detection(
            self.statistic,
            float(t if np.ndim(t) == 0 else t[i]),
            self.on_detect,
            self.assumed_sigma,
            self.fresh_prior,
            self.criterion,
        )


class DefenseModel(ABC, BatchOfOneModel):
    """Owns the defender's action space (if any) and turns an attack into the filter's input.

    A *passive* model takes no action; its environments have only the attacker.

    As for :class:`~fdia_env.attacks.base.AttackModel`, a model has one implementation, its
    ``batch_*`` methods over (B, ...) arrays of the backend :attr:`xp`; the single-env calls
    (:meth:`reset`, :meth:`features`, :meth:`action_mask`, :meth:`apply`,
    :meth:`observe_opponent`) run them on the batch of one (:data:`~fdia_env.backend.ONE`)
    and no subclass overrides them.
    """

    name: str = "defense"
    passive: bool = True
    action_space: spaces.Space | None = None
    feature_low: np.ndarray = np.zeros(0, dtype=np.float32)
    feature_high: np.ndarray = np.zeros(0, dtype=np.float32)

    @abstractmethod
    def bind(self, system: LinearSystem, spec: EpisodeSpec) -> None:
        """Attach to a system and episode; build spaces (and lookup tables) here, once."""

    def info_defaults(self, sampled: bool) -> dict[str, Any]:
        """The per-step info keys this defense adds, with their values before the first step.

        The same keys come after every step (see ``AttackModel.info``); the engine fills them.
        """
        return {}

    _SINGLE_ENV_CALLS = (
        "reset",
        "features",
        "observe_opponent",
        "action_mask",
        "apply",
        "apply_checked",
    )

    # --- the single env: the batch of one ---------------------------------------------------
    def features(self) -> list[float]:
        """Model-specific observation features."""
        values = self.batch_features()
        return values if type(values) is list else values.tolist()

    def observe_opponent(self, other: Any) -> None:
        """Called after each step with the other player's model (repeated games use it)."""
        self.batch_observe_opponent(other)

    def action_mask(self) -> np.ndarray | None:
        """Legal discrete actions or None."""
        return self.batch_action_mask()

    def apply(self, action: Any, effect: AttackEffect) -> FilterInput:
        """Decide what the filter uses given the defender's action (checked) and the attack."""
        if self.action_space is not None:
            action = check_space(self.action_space, action, "defender")
        return self.apply_checked(action, effect)

    def apply_checked(self, action: Any, effect: AttackEffect) -> FilterInput:
        """:meth:`apply` for an action already checked against :attr:`action_space`."""
        used, leak, present, steady = self.batch_apply(action, effect.attacked, effect.sigma)
        rule = self.batch_detection()
        return FilterInput(
            int(used),
            leak if present else None,
            bool(steady),
            None if rule is None else rule.member(0),
            effect.probability,
        )

    # --- the one implementation, over batches ------------------------------------------------
    # As for AttackModel: ``xp`` is the batch arrays' backend, ``batch_backends`` those supported.

    xp: Backend = NUMPY
    batch_backends: tuple[str, ...] = ("numpy",)
    _batch: int = 0

    def batch_detection(self) -> BatchDetection | None:
        """The detector of the last :meth:`batch_apply`, for the detection game; else None."""
        return None

    def batch_reset(self, batch: int, where: np.ndarray | None = None) -> None:
        """Start episodes for the batch members ``where`` (all when None); records B."""
        self._batch = batch

    def batch_observe_opponent(self, other: Any) -> None:
        """Called after each step with the other player's model (repeated games use it)."""

    def batch_action_mask(self) -> np.ndarray | None:
        """(B, A) legal actions (int8, a new array) or None (every action legal)."""
        return None

    def batch_features(self) -> np.ndarray:
        """(B, f) features of every batch member (none by default)."""
        return self.xp.zeros((self._batch, 0))

    @abstractmethod
    def batch_apply(
        self, actions: np.ndarray | None, attacked: np.ndarray, sigma: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None, bool]:
        """What the filter of each member uses, given the checked actions and the attack.

        Returns:
            ``(used bits (B,), leaked Σ (B, nz, nz) or None, leak present (B,) bool or None,
            steady restart)``; "present" marks the members whose filter gets the leaked bias
            (the others' Σ rows are ignored).
        """
