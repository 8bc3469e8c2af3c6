"""An RLlib RL module as a policy with stable-baselines3's ``predict``, for agents.evaluate.

:class:`RLlibPolicy` runs the module's inference pass on a (batch of) Gymnasium-view
observation(s): the masked players' action masks come from ``predict(action_masks=...)``, which
:func:`agents.evaluate.play` passes, so the learned policy is scored by the same loop, against
the same analytic references, as the SB3 runs.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from agents.rllib.envs import MASK, OBS
from fdia_env.envs.policy import MaskedPolicyBase


class RLlibPolicy(MaskedPolicyBase):
    """Wrap an RLlib (torch) RL module trained with :func:`agents.rllib.config.ppo_config`.

    Args:
        module: The RL module (``Algorithm.get_module(player)``).
        action_space: The player's action space (``Discrete`` or ``Box``).
        masked: Whether the module reads ``{"observations", "action_mask"}``.
        seed: Seed of the draws of :meth:`predict` with ``deterministic=False``.
    """

    def __init__(
        self, module: Any, action_space: spaces.Space, masked: bool, seed: int | None = None
    ) -> None:
        if not isinstance(action_space, spaces.Discrete | spaces.Box):
            raise TypeError(f"action_space must be Discrete or Box, got {action_space}")
        self.module = module
        self.action_space = action_space
        self.masked = masked
        self.rng = np.random.default_rng(seed)
        if masked and isinstance(action_space, spaces.Discrete):
            self.mask_size = int(action_space.n)

    def distribution_inputs(
        self, observation: Any, action_masks: np.ndarray | None = None
    ) -> np.ndarray:
        """(B, k) action distribution inputs (logits; for Box: means then log std)."""
        import torch

        obs = np.asarray(observation, dtype=np.float32)
        batched = obs.ndim == 2
        obs = obs if batched else obs[None]
        if self.masked:
            if action_masks is None:
                action_masks = np.ones((obs.shape[0], int(self.action_space.n)))
            mask = np.asarray(action_masks, dtype=np.float32).reshape(obs.shape[0], -1)
            inputs: Any = {OBS: torch.from_numpy(obs), MASK: torch.from_numpy(mask)}
        else:
            inputs = torch.from_numpy(obs)
        with torch.no_grad():
            out = self.module.forward_inference({"obs": inputs})
        return out["action_dist_inputs"].cpu().numpy().astype(np.float64)

    def action_probs(self, observation: Any, action_masks: np.ndarray | None = None) -> np.ndarray:
        """(B, n) or (n,) action probabilities of a ``Discrete`` player (illegal ones 0)."""
        if not isinstance(self.action_space, spaces.Discrete):
            raise TypeError("action_probs needs a Discrete action space")
        logits = self.distribution_inputs(observation, action_masks)
        logits = logits - logits.max(axis=1, keepdims=True)
        p = np.exp(logits)
        p /= p.sum(axis=1, keepdims=True)
        return p if np.asarray(observation).ndim == 2 else p[0]

    def act(self, observation: Any, deterministic: bool = False, action_masks: Any = None) -> Any:
        """The most likely (``deterministic``) or a sampled action (SB3's ``predict``)."""
        batched = np.asarray(observation).ndim == 2
        space = self.action_space
        if isinstance(space, spaces.Discrete):
            p = np.atleast_2d(self.action_probs(observation, action_masks))
            if deterministic:
                a = p.argmax(axis=1)
            else:
                u = self.rng.random((p.shape[0], 1))
                a = np.minimum((p.cumsum(axis=1) < u).sum(axis=1), p.shape[1] - 1)
            a = (a + int(space.start)).astype(np.int64)
            return a if batched else a[0]
        inputs = self.distribution_inputs(observation)
        d = int(np.prod(space.shape))
        mean, log_std = inputs[:, :d], inputs[:, d:]
        a = mean if deterministic else mean + np.exp(log_std) * self.rng.standard_normal(mean.shape)
        # RLlib's normalize_actions: the module acts in [-1, 1], unsquashed to the bounds
        low, high = space.low.reshape(-1), space.high.reshape(-1)
        a = low + (np.clip(a, -1.0, 1.0) + 1.0) * (high - low) / 2.0
        a = a.reshape(-1, *space.shape).astype(space.dtype)
        return a if batched else a[0]


def policy_of(algorithm: Any, player: str | None, action_space: spaces.Space, masked: bool):
    """The :class:`RLlibPolicy` of ``player`` (None: the single-agent module) of an algorithm."""
    from ray.rllib.core import DEFAULT_MODULE_ID

    module = algorithm.get_module(DEFAULT_MODULE_ID if player is None else player)
    if module is None:
        raise ValueError(f"the algorithm has no RL module {player!r}")
    return RLlibPolicy(module, action_space, masked)
