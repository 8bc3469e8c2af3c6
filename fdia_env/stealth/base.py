"""What the two stealth PettingZoo envs share: spaces, the episode skeleton, rendering.

:class:`StealthParallelEnv` is the base of ``stealth_attack_v0``'s
:class:`~fdia_env.stealth.env.StealthAttackEnv` and ``stealth_dynamic_v0``'s
:class:`~fdia_env.stealth.dynamic.StealthDynamicEnv`. A subclass sets ``metadata["name"]``,
calls :meth:`_init_agents` at the end of its constructor (after its model is built) and
implements:

- ``_clear()``: the per-episode state (``_k`` and ``_last`` included);
- ``_restart()``: draws at the start of an episode (default: none);
- ``_observe()`` and ``_info()``: one agent's observation and info;
- ``step(actions)``: the model's step, then :meth:`_finish_step` for the PettingZoo tail;
- ``_render_line()`` and ``_draw(fig)``: the ``"ansi"`` line and the ``"rgb_array"`` frame's plot.
"""

from __future__ import annotations

import sys
from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from pettingzoo import ParallelEnv

from fdia_env._validation import check_agent, check_choice, check_int
from fdia_env.envs.parallel import RENDER_FPS, RENDER_MODES, check_reset_args, end_step


class NoResetOptions:
    """What the single-agent view asks of an env's attack model: the reset options it reads."""

    reset_options: tuple[str, ...] = ()


def check_cost(name: str, value: Any) -> float:
    """``value`` as a finite float >= 0 (``ValueError`` naming ``name`` otherwise)."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{name} must be a number >= 0, got {value!r}")
    try:
        number = float(value)  # a Python int beyond int64 is no numpy scalar
    except OverflowError:
        number = np.inf
    if not (np.isfinite(number) and number >= 0.0):
        raise ValueError(f"{name} must be a finite number >= 0, got {value}")
    return number


DEFAULT_ALPHAS = (0.001, 0.01, 0.05, 0.1, 0.2)
"""The defender's false-alarm rates (``defender="threshold"``)."""


def check_alphas(alphas: Any) -> tuple[float, ...]:
    """``alphas`` as a non-empty tuple of false-alarm rates in (0, 1) (``ValueError`` otherwise)."""
    try:
        values = [float(a) for a in alphas]
    except (TypeError, ValueError) as exc:
        raise ValueError(f"alphas must be false-alarm rates in (0, 1), got {alphas!r}") from exc
    if not values or any(
        isinstance(a, bool) or not 0.0 < v < 1.0 for a, v in zip(alphas, values, strict=True)
    ):
        raise ValueError(f"alphas must be a non-empty list of rates in (0, 1), got {alphas!r}")
    return tuple(values)


class StealthParallelEnv(ParallelEnv):
    """The PettingZoo scaffolding of the stealth envs (see the module docstring)."""

    metadata: ClassVar[dict[str, Any]] = {
        "name": "stealth",
        "render_modes": list(RENDER_MODES),
        "render_fps": RENDER_FPS,
        "is_parallelizable": True,
    }
    horizon: int
    max_cycles: int | None
    on_detect: str
    penalty: float
    false_alarm_cost: float
    render_mode: str | None
    _k: int

    @property
    def detected_reward(self) -> float:
        """The attacker's reward in a step where it is detected: ``-penalty`` or 0.

        ``-penalty`` with ``on_detect="penalty"``, else 0 (``"zero"``, and ``"end"``, which also
        ends the episode).
        """
        return -self.penalty if self.on_detect == "penalty" else 0.0

    def _init_players(
        self,
        render_mode: str | None,
        defender: str | None,
        defenders: tuple[str | None, ...],
        alphas: Any,
        false_alarm_cost: float,
    ) -> None:
        """Check and set the render mode and the defender's options (start of ``__init__``).

        ``defender`` is one of ``defenders``; ``alphas`` its false-alarm rates (None:
        :data:`DEFAULT_ALPHAS`).
        """
        if render_mode is not None:
            check_choice("render_mode", render_mode, RENDER_MODES)
        self.render_mode = render_mode
        if defender is not None and not (isinstance(defender, str) and defender in defenders):
            raise ValueError(f"defender must be one of {list(defenders)}, got {defender!r}")
        self.defender = defender
        self.alphas = check_alphas(DEFAULT_ALPHAS if alphas is None else alphas)
        self.false_alarm_cost = check_cost("false_alarm_cost", false_alarm_cost)

    def _init_episode(self, horizon: Any, max_cycles: Any, default_horizon: int) -> None:
        """Check and set ``max_cycles`` and ``horizon`` (start of ``__init__``).

        ``horizon`` None: PettingZoo's ``max_cycles`` when given, else ``default_horizon``.
        """
        self.max_cycles = (
            None if max_cycles is None else check_int("max_cycles", max_cycles, minimum=1)
        )
        if horizon is None:
            horizon = default_horizon if self.max_cycles is None else self.max_cycles
        self.horizon = check_int("horizon", horizon, minimum=1)

    def _init_agents(
        self,
        defender: str | None,
        action_spaces: dict[str, spaces.Space],
        observation_space: spaces.Space,
    ) -> None:
        """Agents, spaces, the random generator and a cleared episode (end of ``__init__``)."""
        self.attack = NoResetOptions()
        self.possible_agents = ["attacker"] if defender is None else ["attacker", "defender"]
        self.agents: list[str] = []
        self._action_spaces = action_spaces
        self._observation_space = observation_space
        self.state_space = observation_space
        self.np_random, self.np_random_seed = seeding.np_random(None)
        self._reset_called = False
        self._done = True
        self._clear()

    # --- spaces -------------------------------------------------------------------------
    def observation_space(self, agent: str) -> spaces.Space:
        """The observation space of ``agent`` (the same object on every call)."""
        check_agent(agent, self.possible_agents)
        return self._observation_space

    def action_space(self, agent: str) -> spaces.Space:
        """The action space of ``agent`` (the same object on every call)."""
        return self._action_spaces[check_agent(agent, self.possible_agents)]

    def action_masks(self, agent: str = "attacker") -> None:
        """No action mask (every action is legal)."""
        check_agent(agent, self.possible_agents)
        return None

    # --- episode ------------------------------------------------------------------------
    def _clear(self) -> None:  # pragma: no cover - every subclass defines it
        raise NotImplementedError

    def _restart(self) -> None:
        """Draws at the start of an episode (none by default)."""

    def _observe(self) -> np.ndarray:  # pragma: no cover - every subclass defines it
        raise NotImplementedError

    def _info(self) -> dict[str, Any]:  # pragma: no cover - every subclass defines it
        raise NotImplementedError

    def reset(self, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        """Start an episode; ``seed`` makes every noise draw reproducible."""
        check_reset_args(seed, options)
        if seed is not None:
            self.np_random, self.np_random_seed = seeding.np_random(int(seed))
        self.agents = list(self.possible_agents)
        self._clear()
        self._restart()
        self._done = False
        self._reset_called = True
        return self._per_agent(self._observe()), self._per_agent(self._info())

    def _per_agent(self, value: Any) -> dict[str, Any]:
        return {a: (dict(value) if isinstance(value, dict) else value.copy()) for a in self.agents}

    def _finish_step(
        self, reward: float, alpha: float, detected: bool
    ) -> tuple[dict, dict, dict, dict, dict]:
        """The PettingZoo tail of a step, after ``_k`` and ``_last`` were updated.

        The attacker gets ``reward``; the defender its negative minus ``false_alarm_cost · α``.
        """
        done = self._k >= self.horizon or (detected and self.on_detect == "end")
        truncated = not done and self.max_cycles is not None and self._k >= self.max_cycles
        agents = self.agents
        obs = self._per_agent(self._observe())
        infos = self._per_agent(self._info())
        rewards = {"attacker": reward, "defender": -reward - self.false_alarm_cost * alpha}
        rewards = {a: rewards[a] for a in agents}
        return end_step(self, obs, rewards, infos, done, truncated)

    def state(self) -> np.ndarray:
        """Global state: the attacker's observation (the defender sees the same)."""
        return self._observe()

    # --- rendering ----------------------------------------------------------------------
    def render(self, mode: str | None = None) -> str | np.ndarray | None:
        """``"ansi"``: a line for the last step; ``"rgb_array"``: a frame of the last steps."""
        mode = self.render_mode if mode is None else check_choice("mode", mode, RENDER_MODES)
        if mode is None:
            return None
        if mode == "rgb_array":
            return self._render_rgb()
        line = self._render_line()
        if mode == "human":
            sys.stdout.write(line)
            return None
        return line

    def _render_line(self) -> str:  # pragma: no cover - every subclass defines it
        raise NotImplementedError

    def _render_rgb(self) -> np.ndarray:
        """The ``"rgb_array"`` frame: :meth:`_draw`'s plot as (256, 640, 3) uint8 pixels."""
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        fig = Figure(figsize=(8, 3.2), dpi=80)
        canvas = FigureCanvasAgg(fig)
        self._draw(fig)
        fig.tight_layout()
        canvas.draw()
        return np.asarray(canvas.buffer_rgba())[..., :3].copy()

    def _draw(self, fig: Any) -> None:  # pragma: no cover - every subclass defines it
        raise NotImplementedError

    def close(self) -> None:
        """Nothing to release."""
