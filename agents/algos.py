"""The stable-baselines3 algorithms a run can use, and building a fresh model of one."""

from __future__ import annotations

from typing import Any

from sb3_contrib import MaskablePPO
from stable_baselines3 import A2C, DQN, PPO, SAC
from stable_baselines3.common.base_class import BaseAlgorithm

ALGO_CLASSES: dict[str, type[BaseAlgorithm]] = {
    "PPO": PPO,
    "MaskablePPO": MaskablePPO,
    "A2C": A2C,
    "DQN": DQN,
    "SAC": SAC,
}


def build_model(
    algo: str,
    env: Any,
    kwargs: dict[str, Any],
    seed: int | None,
    device: str = "cpu",
    verbose: int = 0,
) -> BaseAlgorithm:
    """A new SB3 ``algo`` model with an MLP policy on ``env`` (a gym env or a vector env).

    Raises:
        ValueError: For an unknown algorithm, or hyperparameters stable-baselines3 rejects (its
            own assertion message, naming the algorithm).
    """
    if algo not in ALGO_CLASSES:
        raise ValueError(f"unknown algorithm {algo!r}; valid algorithms: {', '.join(ALGO_CLASSES)}")
    try:
        return ALGO_CLASSES[algo](
            "MlpPolicy", env, seed=seed, device=device, verbose=verbose, **kwargs
        )
    except AssertionError as exc:  # SB3 checks some hyperparameters with assert
        raise ValueError(f"invalid hyperparameters for {algo}: {exc}") from None
