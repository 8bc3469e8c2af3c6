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
    kwargs = dict(kwargs)
    stop_prob = kwargs.pop("stop_prob", None)
    try:
        model = ALGO_CLASSES[algo](
            "MlpPolicy", env, seed=seed, device=device, verbose=verbose, **kwargs
        )
    except AssertionError as exc:  # SB3 checks some hyperparameters with assert
        raise ValueError(f"invalid hyperparameters for {algo}: {exc}") from None
    if stop_prob is not None:
        set_stop_prob(model, stop_prob)
    return model


def set_stop_prob(model: BaseAlgorithm, prob: float) -> None:
    """Bias a new policy so that action 0 has probability ``prob`` when all actions are legal.

    SB3 initialises the action head with tiny weights (orthogonal, gain 0.01), so the logits
    start at its bias: setting action 0's bias to ``log(prob / (1 − prob) · (n − 1))`` and
    the others' to 0 gives ``prob`` to action 0 and the rest evenly to the others. In the
    sequential format action 0 is stop: a high ``prob`` lets early episodes keep budget for
    the window's last steps, where the grid presets' optimal attacks are.

    Raises:
        ValueError: For a policy whose actions are not one ``Discrete`` choice, or ``prob``
            outside (0, 1).
    """
    import math

    import torch
    from gymnasium import spaces

    if not 0 < prob < 1:
        raise ValueError(f"stop_prob must be in (0, 1), got {prob!r}")
    space = model.action_space
    if not isinstance(space, spaces.Discrete) or int(space.n) < 2:
        raise ValueError(
            f"stop_prob applies to a Discrete action space of 2 or more actions (the "
            f"sequential format's), got {space}"
        )
    head = model.policy.action_net
    with torch.no_grad():
        head.bias.zero_()
        head.bias[0] = math.log(prob / (1 - prob) * (int(space.n) - 1))
