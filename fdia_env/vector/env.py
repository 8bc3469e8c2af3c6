"""Native Gymnasium vector env: B copies of a single-agent view stepped as one computation.

``gymnasium.make_vec("fdia_env/SparseAttack-v0", num_envs=B,
vectorization_mode="vector_entry_point")`` returns :class:`FdiaVectorEnv`. Member ``i`` follows
the single env exactly: reset with ``seed`` gives member ``i`` the seed ``seed + i`` (as
``SyncVectorEnv`` does), expected dynamics are deterministic, and sampled dynamics draw each
member's noise from its own generator in the single env's order.

Autoreset follows Gymnasium's rules: ``autoreset_mode=AutoresetMode.NEXT_STEP`` (default, as
``SyncVectorEnv``) resets a finished member on the next ``step`` (its action is ignored, reward 0,
not terminated); ``SAME_STEP`` resets it in the same step and puts the last observation in
``infos["final_obs"]`` (what stable-baselines3 expects; see :mod:`fdia_env.vector.sb3`).

A fixed opponent (two-player envs) acts for the whole batch with one ``predict`` call on the
(B, d) observations; a stochastic one draws from its own generator for the batch.
"""

from __future__ import annotations

import importlib
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from fdia_env._validation import check_int
from fdia_env.envs.opponents import FixedMix
from fdia_env.envs.parallel import FdiaParallelEnv
from fdia_env.envs.single_agent import Policy
from fdia_env.vector.simulation import BatchedSimulation


class FdiaVectorEnv(gym.vector.VectorEnv):
    """B environments of one fdia_env single-agent view, as batched numpy.

    Args:
        parallel: A two-player env instance; its scenario, models and episode spec are used.
        num_envs: B (>= 1).
        agent: The learning player.
        opponent: Policy of the other player (uniform mix over its actions by default).
        autoreset_mode: ``AutoresetMode.NEXT_STEP`` or ``AutoresetMode.SAME_STEP``.
    """

    def __init__(
        self,
        parallel: FdiaParallelEnv,
        num_envs: int,
        agent: str = "attacker",
        opponent: Policy | None = None,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
    ) -> None:
        self.num_envs = check_int("num_envs", num_envs, minimum=1)
        if agent not in parallel.possible_agents:
            raise ValueError(f"agent must be one of {parallel.possible_agents}, got {agent!r}")
        mode = AutoresetMode(autoreset_mode)
        if mode == AutoresetMode.DISABLED:
            raise ValueError("autoreset_mode must be NEXT_STEP or SAME_STEP, got DISABLED")
        self.metadata = {"autoreset_mode": mode, "render_modes": []}
        self.render_mode = None
        self.parallel = parallel
        self.agent = agent
        others = [a for a in parallel.possible_agents if a != agent]
        self.other = others[0] if others else None
        if self.other is not None and opponent is None:
            opponent = FixedMix.uniform(int(parallel.action_space(self.other).n))
        self.opponent = opponent
        self.attack, self.defense = parallel.attack, parallel.defense
        self.spec_episode = parallel.spec
        space = parallel.observation_space(agent)
        self._masked = isinstance(space, spaces.Dict)
        self.single_observation_space = space["observation"] if self._masked else space
        self.single_action_space = parallel.action_space(agent)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._dims = {
            a: _box(parallel.observation_space(a)).shape[0] for a in parallel.possible_agents
        }
        self._models = {"attacker": self.attack, "defender": self.defense}
        self.sim: BatchedSimulation | None = None
        self._prev_done = np.zeros(self.num_envs, dtype=bool)

    # --- reset ---------------------------------------------------------------------------------
    def reset(self, *, seed: int | list[int] | None = None, options: dict | None = None):
        """Reset every member; an int ``seed`` seeds member i with ``seed + i``."""
        super().reset(seed=seed if isinstance(seed, int) else None)
        B = self.num_envs
        if seed is None:
            seeds = [None] * B
        elif isinstance(seed, int):
            seeds = [seed + i for i in range(B)]
        else:
            if len(seed) != B:
                raise ValueError(f"seed must be an int or a list of {B} seeds, got {len(seed)}")
            seeds = list(seed)
        self._rngs = [seeding.np_random(s)[0] for s in seeds]
        if isinstance(seed, int) and hasattr(self.opponent, "reset"):
            self.opponent.reset(seed=seed + 1)
        if self.sim is None:
            self.sim = BatchedSimulation(self.parallel.sim, B)
        self.sim.rngs = self._rngs
        self.sim.reset(None, self._rngs)
        self.attack.batch_reset(B)
        self.defense.batch_reset(B)
        self._prev_done = np.zeros(B, dtype=bool)
        return self._observe(self.agent), self._infos()

    def _reset_members(self, where: np.ndarray) -> None:
        """Reset the members of the (B,) boolean mask ``where``."""
        rngs = [self._rngs[i] for i in np.flatnonzero(where)] if self.sim.sampled else None
        self.sim.reset(where, rngs)
        self.attack.batch_reset(self.num_envs, where)
        self.defense.batch_reset(self.num_envs, where)

    # --- step ----------------------------------------------------------------------------------
    def step(self, actions: Any):
        """Step every member (NEXT_STEP: members finished last step are reset instead)."""
        if self.sim is None:
            raise RuntimeError("step() called before reset(): call reset() first")
        B = self.num_envs
        resetting = self._prev_done
        actions = {self.agent: actions}
        if self.other is not None:
            actions[self.other], _ = self.opponent.predict(
                self._observe(self.other), deterministic=True
            )
            shape = self.parallel.action_space(self.other).shape or ()
            actions[self.other] = np.asarray(actions[self.other]).reshape(B, *shape)
        attacked, sigma = self.attack.batch_apply(actions["attacker"])
        used, leak, present, steady = self.defense.batch_apply(
            actions.get("defender"), attacked, sigma
        )
        if self.other is not None:
            self.attack.batch_observe_opponent(self.defense)
            self.defense.batch_observe_opponent(self.attack)
        phi_prev = self.sim.phi
        phi = self.sim.step(
            used,
            leak,
            present,
            steady,
            active=~resetting,
            detection=self.defense.batch_detection(),
            probability=getattr(self.attack, "b_probability", None),
        )
        done = self.sim.k >= self.spec_episode.horizon
        mode = self.spec_episode.reward_mode
        if mode == "terminal":
            reward = np.where(done, phi, 0.0)
        elif mode == "shaped":
            reward = phi - phi_prev
        else:
            reward = phi.copy()
        if self.agent == "defender":
            reward = -reward
        truncated = np.zeros(B, dtype=bool)
        infos: dict[str, Any] = {}
        if self.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP:
            if resetting.any():
                self._reset_members(resetting)
                reward[resetting] = 0.0
                done[resetting] = False
            self._prev_done = done.copy()
            obs = self._observe(self.agent)
        else:  # SAME_STEP: finished members restart now; their last observation goes in infos
            obs = self._observe(self.agent)
            if done.any():
                infos["final_obs"] = obs.copy()
                infos["_final_obs"] = done.copy()
                self._reset_members(done.copy())
                obs = self._observe(self.agent)
        infos.update(self._infos())
        return obs, reward, done, truncated, infos

    # --- observations ----------------------------------------------------------------------------
    def _observe(self, agent: str) -> np.ndarray:
        """(B, d) float32 observations of ``agent``, a transposed view of a (d, B) buffer."""
        rows = np.empty((self._dims[agent], self.num_envs), dtype=np.float32)
        col = self.sim.features(rows)
        rows[col:] = self._models[agent].batch_features().T
        return rows.T

    def _infos(self) -> dict[str, Any]:
        # phi is a fresh array every step; k is updated in place, so it is copied
        infos: dict[str, Any] = {"phi": self.sim.phi, "step": self.sim.k.copy()}
        if self._masked:
            infos["action_mask"] = self._models[self.agent].batch_action_mask()
            infos["_action_mask"] = np.ones(self.num_envs, dtype=bool)
        return infos

    def action_masks(self) -> np.ndarray:
        """(B, A) legal actions of the learning player (all legal where unmasked)."""
        mask = self._models[self.agent].batch_action_mask()
        if mask is None:
            return np.ones((self.num_envs, int(getattr(self.single_action_space, "n", 1))), bool)
        return mask.astype(bool)


def _box(space: spaces.Space) -> spaces.Box:
    return space["observation"] if isinstance(space, spaces.Dict) else space


def make_vector(
    module: str,
    num_envs: int,
    agent: str = "attacker",
    opponent: Policy | None = None,
    autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
    **kwargs: Any,
) -> FdiaVectorEnv:
    """Gymnasium ``vector_entry_point``: ``fdia_env.<module>.parallel_env(**kwargs)`` × B."""
    kwargs.pop("max_episode_steps", None)
    if kwargs.get("render_mode") is not None:
        raise ValueError("render_mode is not supported by the native vector env; use SyncVectorEnv")
    kwargs.pop("render_mode", None)
    mod = importlib.import_module(module)
    parallel = mod.parallel_env(**kwargs)
    if opponent is None and hasattr(mod, "default_opponent") and len(parallel.possible_agents) > 1:
        opponent = mod.default_opponent(parallel, agent)
    return FdiaVectorEnv(
        parallel, num_envs, agent=agent, opponent=opponent, autoreset_mode=autoreset_mode
    )
