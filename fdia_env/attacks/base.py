"""The attack-model interface: what the attacker's action means."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces

from fdia_env.episode import EpisodeSpec
from fdia_env.systems import LinearSystem


@dataclass(frozen=True)
class AttackEffect:
    """What an attack does to one filter step.

    Attributes:
        attacked: (M,) bool, sensors whose measurement carries a bias this step.
        sigma: (nz, nz) bias covariance over the stacked measurement, or None when the bias
            value never matters (e.g. it is always detected and dropped) or is zero.
    """

    attacked: np.ndarray
    sigma: np.ndarray | None = None


class AttackModel(ABC):
    """Owns the attacker's action space, its observation features and how an action acts.

    Models are built with their own parameters only; the environment calls :meth:`bind`
    once with the system and episode spec, which builds the spaces.
    """

    name: str = "attack"
    action_space: spaces.Space
    feature_low: np.ndarray
    feature_high: np.ndarray

    @abstractmethod
    def bind(self, system: LinearSystem, spec: EpisodeSpec) -> None:
        """Attach to a system and episode; build spaces here, once."""

    @abstractmethod
    def reset(self) -> None:
        """Start an episode."""

    @abstractmethod
    def features(self) -> np.ndarray:
        """Model-specific observation features, scaled to order one."""

    def action_mask(self) -> np.ndarray | None:
        """Legal discrete actions (int8, 1 = legal) or None when every action is legal."""
        return None

    @abstractmethod
    def apply(self, action: Any) -> AttackEffect:
        """Validate ``action`` (raise ``ValueError`` if outside the space) and act."""

    def info(self) -> dict[str, Any]:
        """Per-step information for the ``infos`` dict."""
        return {}
