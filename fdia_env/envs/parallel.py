"""One PettingZoo ``ParallelEnv``: scenario × attack model × defense model × episode spec."""

from __future__ import annotations

import functools
from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from pettingzoo import ParallelEnv

from fdia_env._validation import check_choice
from fdia_env.attacks.base import AttackModel
from fdia_env.defenses.base import DefenseModel
from fdia_env.envs.render import render_ansi, render_rgb
from fdia_env.envs.simulation import Simulation
from fdia_env.episode import EpisodeSpec
from fdia_env.scenarios import Scenario, resolve
from fdia_env.systems import LinearSystem

RENDER_MODES = ("ansi", "rgb_array")


class FdiaParallelEnv(ParallelEnv):
    """A Kalman filter attacked by ``"attacker"`` and protected by ``"defender"``.

    The attacker is rewarded +Φ and the defender −Φ (zero-sum), Φ being the trace or log-det
    of the filter's actual error covariance (expected dynamics) or the squared estimation
    error (sampled dynamics); see :class:`~fdia_env.episode.EpisodeSpec` for when it is paid.
    A passive defense model (no action) leaves the attacker as the only agent.

    Observations: a ``Box`` of features (see :meth:`Simulation.features` and each model's
    ``features``), wrapped as ``{"observation": Box, "action_mask": Box(0, 1, int8)}`` for a
    player whose model has illegal discrete actions.

    Args:
        scenario: Preset name, :class:`Scenario` or :class:`LinearSystem`.
        attack: A bound-able :class:`AttackModel` instance.
        defense: A :class:`DefenseModel` instance.
        spec: The :class:`EpisodeSpec`.
        render_mode: None, ``"ansi"`` or ``"rgb_array"``.
        name: ``metadata["name"]`` of the env.
    """

    metadata: ClassVar[dict[str, Any]] = {
        "name": "fdia_v0",
        "render_modes": list(RENDER_MODES),
        "is_parallelizable": True,
    }

    def __init__(
        self,
        scenario: str | Scenario | LinearSystem,
        attack: AttackModel,
        defense: DefenseModel,
        spec: EpisodeSpec,
        render_mode: str | None = None,
        name: str = "fdia_v0",
    ) -> None:
        if render_mode is not None:
            check_choice("render_mode", render_mode, RENDER_MODES)
        if not isinstance(attack, AttackModel):
            raise ValueError(f"attack must be an AttackModel, got {type(attack).__name__}")
        if not isinstance(defense, DefenseModel):
            raise ValueError(f"defense must be a DefenseModel, got {type(defense).__name__}")
        self.metadata = {**self.metadata, "name": name}
        self.scenario = resolve(scenario)
        self.system = self.scenario.system
        self.spec = spec
        self.render_mode = render_mode
        self.attack, self.defense = attack, defense
        attack.bind(self.system, spec)
        defense.bind(self.system, spec)
        self.sim = Simulation(self.system, spec)
        self.possible_agents = ["attacker"] if defense.passive else ["attacker", "defender"]
        self.agents: list[str] = []
        self._models = {"attacker": attack, "defender": defense}
        self._observation_spaces = {a: self._build_obs_space(a) for a in self.possible_agents}
        self._action_spaces = {a: self._models[a].action_space for a in self.possible_agents}
        low, high = self.sim.feature_bounds()
        self.state_space = spaces.Box(
            low.astype(np.float32), high.astype(np.float32), dtype=np.float32
        )
        self.np_random, self.np_random_seed = seeding.np_random(None)
        self._done = True
        self._reset_called = False

    def _build_obs_space(self, agent: str) -> spaces.Space:
        model = self._models[agent]
        low, high = self.sim.feature_bounds()
        box = spaces.Box(
            low=np.concatenate([low, model.feature_low]).astype(np.float32),
            high=np.concatenate([high, model.feature_high]).astype(np.float32),
            dtype=np.float32,
        )
        model.reset()
        mask = model.action_mask()
        if mask is None:
            return box
        return spaces.Dict(
            {"observation": box, "action_mask": spaces.Box(0, 1, shape=mask.shape, dtype=np.int8)}
        )

    @functools.cache  # noqa: B019 - spaces are fixed per instance, as PettingZoo requires
    def observation_space(self, agent: str) -> spaces.Space:
        """The observation space of ``agent`` (the same object on every call)."""
        return self._observation_spaces[agent]

    @functools.cache  # noqa: B019
    def action_space(self, agent: str) -> spaces.Space:
        """The action space of ``agent`` (the same object on every call)."""
        return self._action_spaces[agent]

    def reset(self, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        """Start an episode at the window start; ``seed`` makes every draw reproducible."""
        if seed is not None:
            self.np_random, self.np_random_seed = seeding.np_random(seed)
        self.agents = list(self.possible_agents)
        self.attack.reset()
        self.defense.reset()
        self.sim.reset(self.np_random)
        self._done = False
        self._reset_called = True
        self._last_effect = None
        obs = {a: self._observe(a) for a in self.agents}
        infos = {a: {"phi": self.sim.phi[-1], "step": 0} for a in self.agents}
        return obs, infos

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """Apply both players' actions for one window step.

        Raises:
            RuntimeError: Before :meth:`reset` or after the episode ended.
            ValueError: For a missing agent's action or an action outside its space.
        """
        if not self._reset_called:
            raise RuntimeError("step() called before reset(): call reset() first")
        if self._done:
            raise RuntimeError(
                "step() called after the episode ended: call reset() to start a new one"
            )
        missing = [a for a in self.agents if a not in actions]
        if missing:
            raise ValueError(f"actions must include every live agent; missing {missing}")
        effect = self.attack.apply(actions["attacker"])
        filter_input = self.defense.apply(actions.get("defender"), effect)
        self._last_effect = effect
        if not self.defense.passive:
            self.attack.observe_opponent(self.defense)
            self.defense.observe_opponent(self.attack)
        phi_prev = self.sim.phi[-1]
        phi = self.sim.step(filter_input, self.np_random)
        done = self.sim.k >= self.spec.horizon
        reward = self._reward(phi, phi_prev, done)
        agents = self.agents
        obs = {a: self._observe(a) for a in agents}
        rewards = {"attacker": reward, "defender": -reward}
        rewards = {a: rewards[a] for a in agents}
        terminations = dict.fromkeys(agents, done)
        truncations = dict.fromkeys(agents, False)
        info = {"phi": phi, "step": self.sim.k, **self.attack.info(), **self.sim.info()}
        infos = {a: dict(info) for a in agents}
        if done:
            self._done = True
            self.agents = []
        return obs, rewards, terminations, truncations, infos

    def _reward(self, phi: float, phi_prev: float, done: bool) -> float:
        mode = self.spec.reward_mode
        if mode == "terminal":
            return phi if done else 0.0
        if mode == "shaped":
            return phi - phi_prev
        return phi

    def _observe(self, agent: str) -> Any:
        model = self._models[agent]
        box = np.array(self.sim.features() + model.features(), dtype=np.float32)
        mask = model.action_mask()
        if mask is None:
            return box
        return {"observation": box, "action_mask": mask}

    def action_masks(self, agent: str = "attacker") -> np.ndarray | None:
        """Legal actions of ``agent`` now (sb3-contrib's MaskablePPO convention)."""
        return self._models[agent].action_mask()

    def render(self) -> str | np.ndarray | None:
        """``"ansi"``: a line for the last step; ``"rgb_array"``: Φ over time, error ellipse."""
        if self.render_mode is None:
            return None
        if self.render_mode == "ansi":
            return render_ansi(self)
        return render_rgb(self)

    def close(self) -> None:
        """Nothing to release."""

    def state(self) -> np.ndarray:
        """Global state: the common features (the same information every player sees)."""
        return np.array(self.sim.features(), dtype=np.float32)
