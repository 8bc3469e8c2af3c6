"""PettingZoo wrappers for client libraries that need one space shape for every player.

- :func:`flatten_observation_v0`: a masked player's ``Dict(observation, action_mask)`` as one
  ``Box`` (features then the mask as 0/1 floats), for pipelines that only take ``Box``
  observations (SuperSuit's ``flatten_v0`` and ``concat_vec_envs_v1`` with an ``MlpPolicy``).
- :func:`shared_policy_v0`: every player with the same spaces, so one policy can play both
  sides: observations padded with zeros to the longest and followed by a one-hot player
  indicator (in ``possible_agents`` order), ``Box`` actions padded to the longest (each player
  reads its own first entries and ignores the rest). ``Discrete`` action spaces must already
  agree (the sensor game's do).

Both keep ``render``, ``state`` and the infos of the wrapped env; both pass PettingZoo's
``parallel_api_test``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv
from pettingzoo.utils.wrappers import BaseParallelWrapper


class FlattenObservation(BaseParallelWrapper):
    """See :func:`flatten_observation_v0`."""

    def __init__(self, env: ParallelEnv) -> None:
        super().__init__(env)
        self._spaces: dict[str, spaces.Space] = {}
        for agent in env.possible_agents:
            space = env.observation_space(agent)
            if isinstance(space, spaces.Dict):
                box, mask = space["observation"], space["action_mask"]
                space = spaces.Box(
                    np.concatenate([box.low, np.zeros(mask.shape, np.float32)]),
                    np.concatenate([box.high, np.ones(mask.shape, np.float32)]),
                    dtype=np.float32,
                )
            self._spaces[agent] = space

    def observation_space(self, agent: str) -> spaces.Space:
        """A ``Box`` for every player (the same object on every call)."""
        return self._spaces[agent]

    def _flat(self, obs: dict[str, Any]) -> dict[str, Any]:
        return {
            a: np.concatenate([o["observation"], o["action_mask"].astype(np.float32)])
            if isinstance(o, dict)
            else o
            for a, o in obs.items()
        }

    def reset(self, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        """Reset and flatten."""
        obs, infos = self.env.reset(seed=seed, options=options)
        return self._flat(obs), infos

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """Step and flatten."""
        obs, *rest = self.env.step(actions)
        return (self._flat(obs), *rest)


class SharedPolicy(BaseParallelWrapper):
    """See :func:`shared_policy_v0`."""

    def __init__(self, env: ParallelEnv) -> None:
        super().__init__(env)
        agents = list(env.possible_agents)
        boxes = [env.observation_space(a) for a in agents]
        if any(not isinstance(b, spaces.Box) for b in boxes):
            raise ValueError(
                "shared_policy_v0 needs Box observations; wrap masked envs with "
                "flatten_observation_v0 first"
            )
        width = max(b.shape[0] for b in boxes)
        low = np.full(width + len(agents), 0.0, np.float32)
        high = np.full(width + len(agents), 1.0, np.float32)
        for b in boxes:
            low[: b.shape[0]] = np.minimum(low[: b.shape[0]], b.low)
            high[: b.shape[0]] = np.maximum(high[: b.shape[0]], b.high)
        self._obs_space = spaces.Box(low, high, dtype=np.float32)
        self._width = width
        self._own = {a: env.action_space(a) for a in agents}
        acts = list(self._own.values())
        if all(isinstance(s, spaces.Discrete) for s in acts):
            if len({int(s.n) for s in acts}) != 1:
                raise ValueError(
                    f"shared_policy_v0 needs Discrete action spaces of one size, got {acts}"
                )
            self._act_space = acts[0]
        elif all(isinstance(s, spaces.Box) and s.shape and len(s.shape) == 1 for s in acts):
            size = max(s.shape[0] for s in acts)
            self._act_space = spaces.Box(-1.0, 1.0, shape=(size,), dtype=np.float32)
        else:
            raise ValueError(
                f"shared_policy_v0 needs every action space Discrete or 1-D Box, got {acts}"
            )

    def observation_space(self, agent: str) -> spaces.Space:
        """Padded features + one-hot player indicator (one space for every player)."""
        return self._obs_space

    def action_space(self, agent: str) -> spaces.Space:
        """One action space for every player."""
        return self._act_space

    def _pad(self, obs: dict[str, Any]) -> dict[str, np.ndarray]:
        out = {}
        for agent, o in obs.items():
            row = np.zeros(self._obs_space.shape, dtype=np.float32)
            row[: o.shape[0]] = o
            row[self._width + self.env.possible_agents.index(agent)] = 1.0
            out[agent] = row
        return out

    def reset(self, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        """Reset and pad."""
        obs, infos = self.env.reset(seed=seed, options=options)
        return self._pad(obs), infos

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """Cut each player's padded action to its own space, step, pad."""
        own = {}
        for agent, action in actions.items():
            space = self._own.get(agent)
            if isinstance(space, spaces.Box):
                action = np.asarray(action)
                if action.shape != self._act_space.shape:
                    raise ValueError(
                        f"{agent} action must have shape {self._act_space.shape} "
                        f"(the shared space), got {action.shape}"
                    )
                action = action[: space.shape[0]]
            own[agent] = action
        obs, *rest = self.env.step(own)
        return (self._pad(obs), *rest)


def flatten_observation_v0(env: ParallelEnv) -> FlattenObservation:
    """Masked players' ``Dict`` observations as one ``Box`` (see the module docstring)."""
    return FlattenObservation(env)


def shared_policy_v0(env: ParallelEnv) -> SharedPolicy:
    """One observation and action space for every player (see the module docstring)."""
    return SharedPolicy(env)
