"""Single-agent Gymnasium view of a two-player env: one player learns, the other is fixed."""

from __future__ import annotations

import importlib
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from fdia_env._validation import check_agent
from fdia_env.envs.opponents import FixedMix
from fdia_env.envs.parallel import FdiaParallelEnv, check_reset_args
from fdia_env.envs.policy import Policy


class SingleAgentEnv(gym.Env):
    """Gymnasium view of :class:`FdiaParallelEnv` for one ``agent``.

    The other player, if the env has one, is played by ``opponent`` (a fixed
    :class:`~fdia_env.envs.policy.Policy`).
    Observations are the agent's feature ``Box``; where the agent has illegal discrete actions
    the mask is in ``info["action_mask"]`` and :meth:`action_masks` (sb3-contrib's MaskablePPO
    reads the latter).

    Args:
        parallel: The two-player env.
        agent: ``"attacker"`` or ``"defender"``.
        opponent: Policy for the other player (required when the env has one).
    """

    def __init__(
        self, parallel: FdiaParallelEnv, agent: str = "attacker", opponent: Policy | None = None
    ) -> None:
        check_agent(agent, parallel.possible_agents)
        others = [a for a in parallel.possible_agents if a != agent]
        if others and opponent is None:
            raise ValueError(f"opponent is required: the env also has {others[0]!r}")
        if others:
            check_opponent(opponent, parallel.action_space(others[0]))
        else:
            check_no_opponent(opponent, parallel.possible_agents)
        self.parallel = parallel
        self.agent = agent
        self.other = others[0] if others else None
        self.opponent = opponent
        self.render_mode = parallel.render_mode
        self.metadata = {
            "render_modes": list(parallel.metadata["render_modes"]),
            "render_fps": parallel.metadata["render_fps"],
        }
        space = parallel.observation_space(agent)
        self._masked = isinstance(space, spaces.Dict)
        self.observation_space = space["observation"] if self._masked else space
        self.action_space = parallel.action_space(agent)
        self._other_obs: Any = None

    def _split(self, obs: Any) -> tuple[np.ndarray, dict]:
        if self._masked:
            return obs["observation"], {"action_mask": obs["action_mask"]}
        return obs, {}

    def reset(
        self, *, seed: int | None = None, options: dict | None = None
    ) -> tuple[np.ndarray, dict]:
        """Reset the underlying env; ``seed`` seeds every draw of the episode."""
        check_reset_args(seed, options, self.parallel.attack.reset_options)
        super().reset(seed=None if seed is None else int(seed))
        obs, infos = self.parallel.reset(seed=seed, options=options)
        if seed is not None and hasattr(self.opponent, "reset"):
            self.opponent.reset(seed=int(seed) + 1)  # the opponent's draws are seeded too
        if self.other is not None:
            self._other_obs = obs[self.other]
        own, extra = self._split(obs[self.agent])
        return own, {**infos[self.agent], **extra}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        """Play ``action`` against the opponent's response for one step."""
        actions = {self.agent: action}
        if self.other is not None:
            actions[self.other], _ = self.opponent.predict(self._other_obs, deterministic=True)
        obs, rewards, terms, truncs, infos = self.parallel.step(actions)
        if self.other is not None:
            self._other_obs = obs[self.other]
        own, extra = self._split(obs[self.agent])
        info = infos[self.agent]  # the agent's own dict (the parallel env makes one each)
        if extra:
            info.update(extra)
        return (
            own,
            float(rewards[self.agent]),
            bool(terms[self.agent]),
            bool(truncs[self.agent]),
            info,
        )

    def action_masks(self) -> np.ndarray:
        """Legal actions now (all legal when the agent's model has no mask)."""
        mask = self.parallel.action_masks(self.agent)
        if mask is None:
            return np.ones(getattr(self.action_space, "n", 1), dtype=bool)
        return mask.astype(bool)

    def render(self) -> str | np.ndarray | None:
        """Delegate to the two-player env."""
        return self.parallel.render()


def check_opponent(opponent: Any, space: spaces.Space) -> None:
    """Raise ``TypeError``/``ValueError`` unless ``opponent`` can play actions of ``space``.

    Anything with a callable ``predict`` (an SB3 model, a baseline's policy) is accepted; a
    policy that declares ``n_actions`` (e.g. :class:`FixedMix`) must match a ``Discrete``
    space's size, so a wrong mix fails here rather than at a random later step.
    """
    if not callable(getattr(opponent, "predict", None)):
        raise TypeError(
            "opponent must be a policy with stable-baselines3's predict(observation, state, "
            "episode_start, deterministic) method (an SB3 model, a baselines policy, "
            f"fdia_env.envs.opponents.FixedMix), got {type(opponent).__name__}"
        )
    n = getattr(opponent, "n_actions", None)
    if n is not None and isinstance(space, spaces.Discrete) and int(n) != int(space.n):
        raise ValueError(
            f"opponent plays {n} actions but the other player's action space is {space} "
            f"({space.n} actions): e.g. FixedMix needs {space.n} probabilities"
        )


def check_no_opponent(opponent: Any, possible_agents: list[str]) -> None:
    """Raise ``ValueError`` if an ``opponent`` is given to an env that has a single player.

    A one-player env (the sparse and covariance attacks) has nobody for it to play, so it
    would be ignored silently.
    """
    if opponent is not None:
        raise ValueError(
            f"opponent must be None: this env has a single player {possible_agents} and no "
            f"other player for it to act as, got {type(opponent).__name__}"
        )


def make_single_agent(
    module: str, agent: str = "attacker", opponent: Policy | None = None, **kwargs: Any
) -> SingleAgentEnv:
    """Gymnasium entry point: ``fdia_env.<module>.parallel_env(**kwargs)`` seen by ``agent``.

    When the env has another player and no ``opponent`` is given, it plays the uniform mixed
    strategy over its discrete actions (:class:`~fdia_env.envs.opponents.FixedMix`).

    Raises:
        ValueError: For ``backend``/``device`` other than numpy on the CPU: the single env (and
            so ``gymnasium.make`` and ``make_vec``'s ``"sync"``/``"async"`` modes) runs numpy;
            the torch backend is the native vector env's.
    """
    backend, device = kwargs.pop("backend", "numpy"), kwargs.pop("device", "cpu")
    numpy_backend = isinstance(backend, str) and backend == "numpy"
    if not numpy_backend or not (device is None or (isinstance(device, str) and device == "cpu")):
        raise ValueError(
            f"backend={backend!r}, device={device!r}: the single env runs numpy on the CPU "
            "(backend='numpy', device='cpu'); for torch tensors on a device use "
            "gymnasium.make_vec(id, num_envs=B, vectorization_mode='vector_entry_point', "
            "backend='torch', device=...)"
        )
    from fdia_env.registration import view_kwargs

    for name, value in view_kwargs(module, agent).items():
        kwargs.setdefault(name, value)  # the view's fixed options (the table's view_kwargs)
    mod = importlib.import_module(module)
    parallel = mod.parallel_env(**kwargs)
    check_agent(agent, parallel.possible_agents)
    if hasattr(parallel, "gymnasium_view"):  # a wrapper with its own view (sensor game sequential)
        return parallel.gymnasium_view(agent, opponent)
    others = [a for a in parallel.possible_agents if a != agent]
    if not others:
        check_no_opponent(opponent, parallel.possible_agents)
    if others and opponent is None and hasattr(mod, "default_opponent"):
        opponent = mod.default_opponent(parallel, agent)
    if others and opponent is None:
        space = parallel.action_space(others[0])
        if not hasattr(space, "n"):
            raise ValueError(f"opponent is required: {others[0]!r} has no discrete action space")
        opponent = FixedMix.uniform(int(space.n))
    return SingleAgentEnv(parallel, agent=agent, opponent=opponent)
