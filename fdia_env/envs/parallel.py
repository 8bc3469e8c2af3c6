"""One PettingZoo ``ParallelEnv``: scenario × attack model × defense model × episode spec."""

from __future__ import annotations

import sys
import warnings
from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from pettingzoo import ParallelEnv

from fdia_env._validation import check_agent, check_choice, check_int
from fdia_env.actions import check_step_actions
from fdia_env.attacks.base import AttackModel
from fdia_env.defenses.base import DefenseModel
from fdia_env.envs.render import render_ansi, render_rgb
from fdia_env.envs.simulation import Simulation
from fdia_env.episode import EpisodeSpec
from fdia_env.scenarios import Scenario, resolve
from fdia_env.systems import LinearSystem

RENDER_MODES = ("human", "ansi", "rgb_array")
RENDER_FPS = 4


def end_step(
    env: Any, obs: dict, rewards: dict, infos: dict, done: bool, truncated: bool
) -> tuple[dict, dict, dict, dict, dict]:
    """The PettingZoo end of a step of ``env`` (this module's env or a stealth env).

    The terminations and truncations of the live agents; when the episode ends, ``env`` is
    closed (no live agents; the next :meth:`step` raises); ``render_mode="human"`` renders.

    Returns:
        ``(observations, rewards, terminations, truncations, infos)``.
    """
    agents = env.agents
    terminations = dict.fromkeys(agents, done)
    truncations = dict.fromkeys(agents, truncated)
    if done or truncated:
        env._done = True
        env.agents = []
    if env.render_mode == "human":
        env.render()
    return obs, rewards, terminations, truncations, infos


def attacker_reward(mode: str, phi: Any, phi_prev: Any, done: Any, xp: Any = None) -> Any:
    """The attacker's reward for one step; the defender's is its negative (zero-sum).

    The one reward of every face: the parallel env calls it with floats, the native vector env
    with (B,) arrays of its backend ``xp``.

    Args:
        mode: The episode's ``reward_mode``: ``"terminal"`` (Φ at the window's end, else 0),
            ``"shaped"`` (Φ − Φ of the step before) or ``"per_step"`` (Φ).
        phi: Φ after the step.
        phi_prev: Φ before the step.
        done: Whether the window ended with this step.
        xp: None for floats; the backend of (B,) arrays (the result is then a new array).

    Returns:
        The reward (a float, or a (B,) array).
    """
    if mode == "terminal":
        if xp is None:
            return phi if done else 0.0
        return xp.where(done, phi, 0.0)
    if mode == "shaped":
        return phi - phi_prev
    return phi if xp is None else xp.copy(phi)


class FdiaParallelEnv(ParallelEnv):
    """A Kalman filter attacked by ``"attacker"`` and protected by ``"defender"``.

    The attacker is rewarded +Φ and the defender −Φ (zero-sum), Φ being the trace or log-det
    of the filter's actual error covariance (expected dynamics) or the squared estimation
    error (sampled dynamics); see :class:`~fdia_env.episode.EpisodeSpec` for when it is paid.
    A passive defense model (no action) leaves the attacker as the only agent.

    Observations: a ``Box`` of features (see :meth:`Simulation.features` and each model's
    ``features``), wrapped as ``{"observation": Box, "action_mask": Box(0, 1, int8)}`` for a
    player whose model has illegal discrete actions.

    Infos: the same keys after :meth:`reset` and after every step, each value a Python scalar
    or a fixed-shape numpy array: ``phi`` (Φ now), ``step`` (window steps taken), the attack
    model's keys (e.g. ``attacked`` as an (M,) 0/1 int8 array) and the defense's (the detector's
    probabilities or decision); before the first step they describe "nothing happened yet".

    Args:
        scenario: Preset name, :class:`Scenario` or :class:`LinearSystem`.
        attack: A bound-able :class:`AttackModel` instance.
        defense: A :class:`DefenseModel` instance.
        spec: The :class:`EpisodeSpec`.
        render_mode: None, ``"human"`` (the ``"ansi"`` line printed to stdout; no window),
            ``"ansi"`` or ``"rgb_array"``.
        name: ``metadata["name"]`` of the env.
        max_cycles: PettingZoo's episode-length limit: an episode still running after this
            many steps ends by truncation (``truncations`` True, no terminal reward). The env
            modules also make it the window length when ``horizon`` (``rounds``) is not given.
    """

    metadata: ClassVar[dict[str, Any]] = {
        "name": "fdia_v0",
        "render_modes": list(RENDER_MODES),
        "render_fps": RENDER_FPS,
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
        max_cycles: int | None = None,
    ) -> None:
        if render_mode is not None:
            check_choice("render_mode", render_mode, RENDER_MODES)
        if not isinstance(attack, AttackModel):
            raise TypeError(f"attack must be an AttackModel, got {type(attack).__name__}")
        if not isinstance(defense, DefenseModel):
            raise TypeError(f"defense must be a DefenseModel, got {type(defense).__name__}")
        self.max_cycles = (
            None if max_cycles is None else check_int("max_cycles", max_cycles, minimum=1)
        )
        self.metadata = {**self.metadata, "name": name}
        self.scenario = resolve(scenario)
        self.system = self.scenario.system
        self.spec = spec
        self.render_mode = render_mode
        self.attack, self.defense = attack, defense
        attack.bind(self.system, spec)
        defense.bind(self.system, spec)
        self.sim = Simulation(self.system, spec)
        self._info_defaults = defense.info_defaults(self.sim.sampled)
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

    def observation_space(self, agent: str) -> spaces.Space:
        """The observation space of ``agent`` (the same object on every call)."""
        return self._observation_spaces[check_agent(agent, self.possible_agents)]

    def action_space(self, agent: str) -> spaces.Space:
        """The action space of ``agent`` (the same object on every call)."""
        return self._action_spaces[check_agent(agent, self.possible_agents)]

    def reset(self, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        """Start an episode at the window start; ``seed`` makes every draw reproducible.

        Raises:
            ValueError: For a seed that is not a non-negative integer, or a bad value of an
                option the env reads (only the typed sensor game reads one, ``attacker_type``;
                other keys draw a warning, see :func:`check_reset_args`). Nothing changes
                before the checks pass.
        """
        check_reset_args(seed, options, self.attack.reset_options)
        self.attack.check_reset_options(dict(options or {}))
        if seed is not None:
            self.np_random, self.np_random_seed = seeding.np_random(int(seed))
        self.agents = list(self.possible_agents)
        self.attack.reset()
        self.defense.reset()
        self.sim.reset(self.np_random)
        self.attack.draw_nature(self.np_random, dict(options or {}))
        self._done = False
        self._reset_called = True
        self._last_effect = None
        obs = {a: self._observe(a) for a in self.agents}
        return obs, self._infos(self.agents)

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """Apply both players' actions for one window step.

        Raises:
            RuntimeError: Before :meth:`reset` or after the episode ended.
            ValueError: For a missing or unknown agent's action, or an action outside its
                space; nothing changes before every action has passed.
        """
        actions = check_step_actions(
            actions, self.agents, self._action_spaces, self._reset_called, self._done
        )
        reward, done, truncated = self._advance(actions)
        agents = self.agents
        obs = {a: self._observe(a) for a in agents}
        rewards = {"attacker": reward, "defender": -reward} if len(agents) == 2 else {}
        if len(agents) == 1:
            rewards[agents[0]] = reward if agents[0] == "attacker" else -reward
        return end_step(self, obs, rewards, self._infos(agents), done, truncated)

    def _advance(self, actions: dict[str, Any]) -> tuple[float, bool, bool]:
        """The window step of :meth:`step` for actions already checked, without its outputs.

        Returns the attacker's reward, termination and truncation; the caller ends the step
        with :func:`end_step`. The observations and infos are those of :meth:`_observe` and
        :meth:`_infos` afterwards; a wrapper that plays several window steps in one decision
        (the sequential format's plan) reads them once, after the last.
        """
        effect = self.attack.apply_checked(actions["attacker"])
        filter_input = self.defense.apply_checked(actions.get("defender"), effect)
        self._last_effect = effect
        if not self.defense.passive:
            self.attack.observe_opponent(self.defense)
            self.defense.observe_opponent(self.attack)
        phi_prev = self.sim.phi[-1]
        phi = self.sim.step(filter_input, self.np_random)
        done = self.sim.k >= self.spec.horizon
        truncated = not done and self.max_cycles is not None and self.sim.k >= self.max_cycles
        return attacker_reward(self.spec.reward_mode, phi, phi_prev, done), done, truncated

    def _info(self) -> dict[str, Any]:
        """The step's info: the same keys at reset and at every step (see the class doc)."""
        info: dict[str, Any] = {"phi": float(self.sim.phi[-1]), "step": int(self.sim.k)}
        info.update(self.attack.info())
        if self._info_defaults:
            engine = self.sim.info()
            for key, default in self._info_defaults.items():  # the defaults' types, always
                info[key] = type(default)(engine.get(key, default))
        return info

    def _infos(self, agents: list[str]) -> dict[str, dict[str, Any]]:
        """Each agent's info: the common one, plus the attack's private keys for the attacker."""
        info = self._info()
        if len(agents) == 1:
            infos = {agents[0]: info}
        else:  # each agent its own dict
            infos = {a: dict(info) if i else info for i, a in enumerate(agents)}
        if "attacker" in infos:
            infos["attacker"].update(self.attack.private_info())
        return infos

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

    def render(self, mode: str | None = None) -> str | np.ndarray | None:
        """Draw the last step in ``mode`` (default: ``render_mode``).

        ``"ansi"``: a line for the last step; ``"rgb_array"``: Φ over time and the error
        ellipse; ``"human"``: the ansi line printed to stdout (returns None).

        Args:
            mode: Render in this mode instead of ``render_mode`` (RLlib's
                ``ParallelPettingZooEnv`` passes one); one of ``metadata["render_modes"]``.
        """
        mode = self.render_mode if mode is None else check_choice("mode", mode, RENDER_MODES)
        if mode is None:
            return None
        if mode == "ansi":
            return render_ansi(self)
        if mode == "human":
            sys.stdout.write(render_ansi(self))
            return None
        return render_rgb(self)

    def close(self) -> None:
        """Nothing to release."""

    def state(self) -> np.ndarray:
        """Global state: the common features (the same information every player sees)."""
        return np.array(self.sim.features(), dtype=np.float32)


def check_reset_args(seed: Any, options: Any, known: tuple[str, ...] = ()) -> None:
    """``reset``'s arguments: a seed in [0, 2**64) or None; options the env reads (``known``).

    Only the typed sensor game reads an option (``attacker_type``, which forces nature's draw).
    Other options are not an error, because PettingZoo's own ``api_test`` and
    ``parallel_api_test`` reset with ``options={"options": 1}`` (that probe key, ``"options"``,
    is accepted silently); other keys outside ``known`` draw a ``UserWarning`` naming them, so a
    setting passed there by mistake (instead of to the constructor) is not silently lost.
    """
    if seed is not None:
        if isinstance(seed, bool) or not isinstance(seed, int | np.integer):
            raise ValueError(f"seed must be a non-negative integer or None, got {seed!r}")
        if not 0 <= int(seed) < 2**64:
            raise ValueError(f"seed must be in [0, 2**64), got {seed}")
    if options is not None and not isinstance(options, dict):
        raise TypeError(f"options must be a dict or None, got {type(options).__name__}")
    unknown = sorted(str(k) for k in (options or {}) if k not in known and k != "options")
    if unknown:
        reads = f"this env reads only {list(known)}" if known else "this env reads none"
        warnings.warn(
            f"reset options {unknown} are ignored: {reads} (pass settings such as budget or "
            "horizon to the constructor)",
            UserWarning,
            stacklevel=3,
        )
