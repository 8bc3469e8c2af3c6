"""fdia_env under RLlib names: multi-agent envs per module, single-agent Gymnasium views.

:func:`register_envs` registers (``ray.tune.registry.register_env``, idempotent):

- each PettingZoo module (``"sparse_attack_v0"``, ``"sensor_game_v0"``, ...) as an RLlib
  ``MultiAgentEnv`` (:class:`FdiaMultiAgentEnv`, one agent id per player);
- each Gymnasium view (``"fdia_env/SparseAttack-v0"``, ...) as a single-agent env;
- :data:`TASK_ENV`: the env of a single-player benchmark task (``env_config={"task": NAME}``),
  built as the task builds it (:meth:`fdia_env.tasks.Task.make_env`, the system family's entry
  point included).

``env_config`` holds the env kwargs (``scenario``, ``budget``, ...); a view also takes
``opponent``, the other player's fixed mix as a list of probabilities (default uniform).

A masked player's observation is ``{"observations": Box, "action_mask": Box(0, 1, float32)}``,
the form RLlib's ``ActionMaskingTorchRLModule`` reads (PettingZoo's is ``"observation"``, int8).
The registered creators are module-level functions of this module, so remote env runners import
``agents.rllib.envs`` (and with it ``fdia_env``) themselves: ``fdia-env`` must be installed on
every node of a cluster, as every other package the job uses.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from ray.rllib.env.multi_agent_env import MultiAgentEnv
from ray.tune.registry import register_env

from agents.rllib.module import register_default_module
from fdia_env.envs.opponents import FixedMix
from fdia_env.envs.parallel import FdiaParallelEnv
from fdia_env.registration import ENV_NAMES, GYM_IDS, load

MODULES = ENV_NAMES  # the multi-agent env names: every entry of the table of environments
TASK_ENV = "fdia_env/Task"  # a benchmark task's env, named by env_config["task"]
OBS, MASK = "observations", "action_mask"  # RLlib's action-masking module reads these keys


def rllib_space(space: spaces.Space) -> spaces.Space:
    """A player's observation space in RLlib's form (masked Dicts renamed, mask as float32)."""
    if not isinstance(space, spaces.Dict):
        return space
    n = space["action_mask"].shape
    return spaces.Dict(
        {OBS: space["observation"], MASK: spaces.Box(0.0, 1.0, shape=n, dtype=np.float32)}
    )


def rllib_obs(obs: Any) -> Any:
    """A player's observation in RLlib's form (see :func:`rllib_space`)."""
    if isinstance(obs, Mapping) and "action_mask" in obs:
        return {OBS: obs["observation"], MASK: np.asarray(obs["action_mask"], np.float32)}
    return obs


def is_masked(space: spaces.Space) -> bool:
    """Whether an (RLlib-form) observation space carries an action mask."""
    return isinstance(space, spaces.Dict) and MASK in space.spaces


class FdiaMultiAgentEnv(MultiAgentEnv):
    """RLlib ``MultiAgentEnv`` over :class:`FdiaParallelEnv`: one agent id per player.

    Every player acts at every step and every episode ends for all players at once; rewards,
    infos and termination flags are the parallel env's, with ``"__all__"`` added.

    Args:
        parallel: The PettingZoo env.
    """

    def __init__(self, parallel: FdiaParallelEnv) -> None:
        super().__init__()
        self.parallel = parallel
        self.possible_agents = list(parallel.possible_agents)
        self.agents = list(self.possible_agents)
        self.observation_spaces = {
            a: rllib_space(parallel.observation_space(a)) for a in self.possible_agents
        }
        self.action_spaces = {a: parallel.action_space(a) for a in self.possible_agents}
        self.render_mode = parallel.render_mode
        self.metadata = parallel.metadata

    def reset(
        self, *, seed: int | None = None, options: dict | None = None
    ) -> tuple[dict[str, Any], dict[str, Any]]:
        """Reset the parallel env (``seed`` seeds every draw of the episode)."""
        obs, infos = self.parallel.reset(seed=seed, options=options)
        self.agents = list(self.parallel.agents)
        return {a: rllib_obs(o) for a, o in obs.items()}, infos

    def step(self, action_dict: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """One simultaneous step of every player."""
        obs, rewards, terms, truncs, infos = self.parallel.step(action_dict)
        terms = {a: bool(t) for a, t in terms.items()}
        truncs = {a: bool(t) for a, t in truncs.items()}
        terms["__all__"] = all(terms.values())
        truncs["__all__"] = all(truncs.values()) and not terms["__all__"]
        # ``agents`` keeps the players of the episode until the next reset: RLlib checks the
        # final step's observations against it (PettingZoo empties it at the end)
        rewards = {a: float(r) for a, r in rewards.items()}
        return {a: rllib_obs(o) for a, o in obs.items()}, rewards, terms, truncs, infos

    def render(self) -> Any:
        """Delegate to the parallel env."""
        return self.parallel.render()

    def close(self) -> None:
        """Close the parallel env."""
        self.parallel.close()


class MaskedObservation(gym.Wrapper):
    """A masked Gymnasium view whose observation is ``{"observations", "action_mask"}``.

    fdia_env's views return the features and put the mask in ``info["action_mask"]``
    (sb3-contrib's form); RLlib's masking module reads it from the observation.
    """

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        n = int(env.action_space.n)
        self.observation_space = spaces.Dict(
            {
                OBS: env.observation_space,
                MASK: spaces.Box(0.0, 1.0, shape=(n,), dtype=np.float32),
            }
        )

    def _obs(self, obs: np.ndarray, info: dict) -> dict[str, np.ndarray]:
        return {OBS: obs, MASK: np.asarray(info["action_mask"], np.float32)}

    def reset(self, **kwargs: Any) -> tuple[dict[str, np.ndarray], dict]:
        """Reset; the mask of the first step is in the observation."""
        obs, info = self.env.reset(**kwargs)
        return self._obs(obs, info), info

    def step(self, action: Any) -> tuple[dict[str, np.ndarray], float, bool, bool, dict]:
        """Step; the mask of the next step is in the observation."""
        obs, reward, term, trunc, info = self.env.step(action)
        return self._obs(obs, info), reward, term, trunc, info


def _config(env_config: Mapping[str, Any] | None) -> dict[str, Any]:
    # RLlib passes an EnvContext (a dict subclass) and may add "num_envs"
    return {k: v for k, v in dict(env_config or {}).items() if k != "num_envs"}


def make_multi_agent(module: str, env_config: Mapping[str, Any] | None = None) -> MultiAgentEnv:
    """``fdia_env.<module>.parallel_env(**env_config)`` as an RLlib ``MultiAgentEnv``.

    Raises:
        ValueError: For a module that is not one of :data:`MODULES`.
    """
    if module not in MODULES:
        raise ValueError(f"module must be one of {', '.join(MODULES)}, got {module!r}")
    return FdiaMultiAgentEnv(load(module).parallel_env(**_config(env_config)))


def make_view(gym_id: str, env_config: Mapping[str, Any] | None = None) -> gym.Env:
    """The Gymnasium view ``gym_id`` with masked observations in RLlib's form.

    ``env_config["opponent"]``, if given, is the other player's fixed mix: a list of
    probabilities (a :class:`~fdia_env.envs.opponents.FixedMix`) or a policy object.

    ``gym_id`` :data:`TASK_ENV` is :func:`make_task_env`'s.

    Raises:
        ValueError: For an unknown id.
    """
    if gym_id == TASK_ENV:
        return make_task_env(env_config)
    if gym_id not in GYM_IDS:
        raise ValueError(f"gym_id must be one of {', '.join(GYM_IDS)}, got {gym_id!r}")
    kwargs = _config(env_config)
    opponent = kwargs.pop("opponent", None)
    seed = kwargs.pop("opponent_seed", None)
    if opponent is not None and not callable(getattr(opponent, "predict", None)):
        opponent = FixedMix(np.asarray(opponent, dtype=np.float64), seed=seed)
    from fdia_env.envs.single_agent import make_single_agent

    module, agent = GYM_IDS[gym_id]
    env: gym.Env = make_single_agent(module, agent=agent, opponent=opponent, **kwargs)
    if isinstance(env.unwrapped.parallel.observation_space(agent), spaces.Dict):
        env = MaskedObservation(env)
    return env


def make_task_env(env_config: Mapping[str, Any] | None = None) -> gym.Env:
    """The env of the single-player task ``env_config["task"]``, masked as :func:`make_view`.

    The task fixes every option: ``env_config`` holds its name only.

    Raises:
        ValueError: For an unknown task, a game task, or other keys than ``task``.
    """
    from fdia_env import tasks

    config = _config(env_config)
    if set(config) != {"task"}:
        raise ValueError(f"env_config of {TASK_ENV} must be {{'task': NAME}}, got {config!r}")
    task = tasks.get(config["task"])
    if task.is_game:
        raise ValueError(f"{TASK_ENV}: task {task.name} is a game (two players)")
    env = task.make_env()
    if isinstance(env.action_space, spaces.Discrete) and callable(
        getattr(env.unwrapped, "action_masks", None)
    ):
        env = MaskedObservation(env)
    return env


class _Creator:
    """A picklable env creator bound to one name (a module or a Gymnasium id)."""

    def __init__(self, name: str) -> None:
        self.name = name

    def __call__(self, env_config: Mapping[str, Any] | None = None) -> Any:
        # an env runner builds its env, then its RL module: the default module is masked there
        register_default_module()
        if self.name == TASK_ENV:
            return make_task_env(env_config)
        if self.name in GYM_IDS:
            return make_view(self.name, env_config)
        return make_multi_agent(self.name, env_config)


def register_envs() -> list[str]:
    """Register every module and Gymnasium view with RLlib; returns the names registered.

    Also makes RLlib's default PPO module the masked one
    (:func:`agents.rllib.module.register_default_module`), so that a plain
    ``PPOConfig().environment(name)`` runs on every env, masked players included.
    """
    register_default_module()
    names = [*MODULES, *GYM_IDS, TASK_ENV]
    for name in names:
        register_env(name, _Creator(name))
    return names
