"""Copies of a Gymnasium env as the torch vector env :mod:`agents.torch_ppo` trains on.

For an env without a native torch vector env (the system family, whose env is an entry point
of its own): ``num_envs`` copies step in this process in Gymnasium's ``SyncVectorEnv``
(``SAME_STEP`` autoreset), and :class:`TorchVectorOf` hands torch-ppo tensors on its device,
as a native torch vector env does: observations (float64), rewards (float64), the termination
and truncation flags (bool), ``infos["final_obs"]`` as a (B, d) tensor and
:meth:`TorchVectorOf.action_masks` as a (B, n) bool tensor. Each step crosses to the host and
back, so it is as fast as the copies, not as a batched env on the device.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, SyncVectorEnv


class TorchVectorOf(gym.vector.VectorEnv):
    """``num_envs`` copies of ``make()`` with torch tensors on ``device`` in and out.

    Args:
        make: Builds one copy (a Gymnasium env with a flat ``Box`` observation; a
            ``Discrete`` one needs ``action_masks()`` where its actions are masked).
        num_envs: Copies, B.
        device: The torch device of the tensors.

    Raises:
        ValueError: For ``num_envs`` < 1, or an observation space that is not a ``Box``.
    """

    backend = "torch"

    def __init__(self, make: Callable[[], gym.Env], num_envs: int, device: str) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
            raise ValueError(f"num_envs must be an integer >= 1, got {num_envs!r}")
        self.envs = SyncVectorEnv(
            [make] * num_envs, copy=False, autoreset_mode=AutoresetMode.SAME_STEP
        )
        obs_space = self.envs.single_observation_space
        if not isinstance(obs_space, spaces.Box):
            self.close()
            raise ValueError(f"the env's observation space must be a Box, got {obs_space}")
        self.num_envs = num_envs
        self.device = str(torch.device(device))
        self.single_observation_space = obs_space
        self.single_action_space = self.envs.single_action_space
        self.observation_space = self.envs.observation_space
        self.action_space = self.envs.action_space
        self.metadata = {
            "autoreset_mode": AutoresetMode.SAME_STEP,
            "render_modes": [],
            "backend": "torch",
        }
        self._masked = isinstance(self.single_action_space, spaces.Discrete) and callable(
            getattr(self.envs.envs[0].unwrapped, "action_masks", None)
        )

    def _tensor(self, value: Any, dtype: torch.dtype) -> torch.Tensor:
        return torch.as_tensor(np.asarray(value), dtype=dtype, device=self.device)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[torch.Tensor, dict[str, Any]]:
        """Reset every copy (copy ``i`` with ``seed + i``); observations as a (B, d) tensor."""
        obs, infos = self.envs.reset(seed=seed, options=options)
        return self._tensor(obs, torch.float64), infos

    def step(
        self, actions: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, dict[str, Any]]:
        """Step every copy; an ended copy is reset at once (its last observation in the infos).

        ``infos["final_obs"]`` is a (B, d) float64 tensor (zero rows where
        ``infos["_final_obs"]``, a (B,) bool tensor, is False), present when a copy ended.
        """
        host = actions.detach().cpu().numpy()
        obs, rewards, terminated, truncated, infos = self.envs.step(host)
        if "_final_obs" in infos:
            ended = np.asarray(infos["_final_obs"], dtype=bool)
            final = np.zeros((self.num_envs, *self.single_observation_space.shape))
            for i in np.flatnonzero(ended):
                final[i] = infos["final_obs"][i]
            infos = {
                **infos,
                "final_obs": self._tensor(final, torch.float64),
                "_final_obs": self._tensor(ended, torch.bool),
            }
        return (
            self._tensor(obs, torch.float64),
            self._tensor(rewards, torch.float64),
            self._tensor(terminated, torch.bool),
            self._tensor(truncated, torch.bool),
            infos,
        )

    def action_masks(self) -> torch.Tensor:
        """(B, n) bool tensor of each copy's legal actions (all legal for an unmasked env)."""
        if not self._masked:
            n = int(self.single_action_space.n)
            return torch.ones((self.num_envs, n), dtype=torch.bool, device=self.device)
        return self._tensor(np.stack(self.envs.call("action_masks")), torch.bool)

    def close_extras(self, **kwargs: Any) -> None:
        """Close the copies (:meth:`close` calls it once)."""
        envs = getattr(self, "envs", None)  # None: refused before the copies were built
        if envs is not None:
            envs.close()
