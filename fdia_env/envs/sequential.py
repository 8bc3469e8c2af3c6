"""The sequential, masked action format: a set built one element per decision, or a stop.

:class:`SequentialSetEnv` wraps a sparse-attack env (``sparse_attack_v0``) whose attacker picks
a set of sensors every window step, and lets the attacker build that set one sensor per
decision instead. ``sparse_attack_v0.parallel_env(action="sequential")`` builds it; the AEC view
(``sparse_attack_v0.env(action="sequential")``) and the Gymnasium view
(``gymnasium.make("fdia_env/SparseAttack-v0", action="sequential")``) wrap it as they wrap the
other formats.

Action space ``Discrete(M + 1)``: action ``j`` (1..M) adds sensor j to the set of the current
window step; action ``0`` (stop) commits the set, so the filter takes its window step with those
sensors attacked. The action mask (``(M + 1,)`` int8, in the observation dict and from
:meth:`SequentialSetEnv.action_masks`) allows stop always, and sensor j only while it is not yet
in the step's set and the set is smaller than the budget left.

Decision order: time-major, as the filter runs (all picks of window step K+1, stop, then K+2,
...), so a decision sees the covariance it acts on. A decision whose only legal action is stop
(the budget is spent, or every sensor is in the set) is played by the env itself
(``skip_forced=True``, default): an episode takes at most ``N + c`` decisions, and once the
budget is spent it ends at once. Pass ``skip_forced=False`` to take every stop yourself.

Dynamics and rewards are those of the wrapped env: a pick pays 0, and a stop pays the wrapped
env's reward of the window step it commits (with ``skip_forced``, the sum over the window steps
it plays), so an episode's return equals the return of the same attack set played in the
``"bitmask"`` or ``"multibinary"`` format, and every set of those formats is reachable.

Illegal actions (``illegal_action``): an action outside the mask (a sensor already in the step's
set, or any sensor once the set uses up the budget left) raises ``ValueError`` with
``"error"``, and acts as stop with ``"trim"`` (default) and ``"noop"``, so that every decision
either grows the set or advances the filter. An action outside ``Discrete(M + 1)`` is always a
``ValueError``.

Observation: ``{"observation": Box, "action_mask": Box(0, 1, (M + 1,), int8)}``; the ``Box`` is
the wrapped env's features (see ``sparse_attack_v0``) followed by M entries (1 = sensor in the
set being built) and the budget that would be left after the set, as a fraction of ``budget``.
Infos are the wrapped env's (of its last window step; at a pick, unchanged).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from fdia_env._validation import check_choice
from fdia_env.attacks.sparse import ILLEGAL_ACTIONS, SparseAttack
from fdia_env.envs.actions import check_action
from fdia_env.envs.parallel import FdiaParallelEnv

STOP = 0
"""The stop action: commit the set built so far and take the window step."""


class SequentialSetEnv(ParallelEnv):
    """Sparse attacker's sequential format over a ``"multibinary"`` sparse-attack env.

    See the module docstring for the action, mask, observation and reward contract.

    Args:
        inner: A single-player :class:`FdiaParallelEnv` whose attack model is a
            :class:`SparseAttack` in the ``"multibinary"`` format (any over-budget rule: the
            wrapper sends only sets that fit the budget left).
        illegal_action: ``"trim"`` (default), ``"noop"`` (an action outside the mask stops) or
            ``"error"`` (it raises ``ValueError``).
        skip_forced: Play the decisions whose only legal action is stop (default True).

    Raises:
        TypeError: If ``inner`` is not such an env.
        ValueError: For a budget of 0 (there would be no decision to make) or a bad
            ``illegal_action``.
    """

    metadata: ClassVar[dict[str, Any]] = dict(FdiaParallelEnv.metadata)

    def __init__(
        self, inner: FdiaParallelEnv, illegal_action: str = "trim", skip_forced: bool = True
    ) -> None:
        if not isinstance(inner, FdiaParallelEnv) or not isinstance(inner.attack, SparseAttack):
            raise TypeError(
                "inner must be a sparse-attack FdiaParallelEnv (sparse_attack_v0.parallel_env), "
                f"got {type(inner).__name__}"
            )
        if inner.attack.format != "multibinary" or inner.possible_agents != ["attacker"]:
            raise TypeError(
                "inner must be a single-player sparse attack in the 'multibinary' format, got "
                f"format {inner.attack.format!r} with agents {inner.possible_agents}"
            )
        if inner.attack.budget < 1:
            raise ValueError(
                "budget must be >= 1 for action='sequential' (with budget 0 there is no "
                "decision to make; use another format), got 0"
            )
        if not isinstance(skip_forced, bool):
            raise TypeError(f"skip_forced must be a bool, got {type(skip_forced).__name__}")
        self.illegal_action = check_choice("illegal_action", illegal_action, ILLEGAL_ACTIONS)
        self.skip_forced = skip_forced
        self.inner = inner
        self.attack = inner.attack
        self.M = inner.system.M
        self.metadata = dict(inner.metadata)
        self.render_mode = inner.render_mode
        self.possible_agents = list(inner.possible_agents)
        self.agents: list[str] = []
        self.state_space = inner.state_space
        box = inner.observation_space("attacker")
        extra = self.M + 1
        self._obs_space = spaces.Dict(
            {
                "observation": spaces.Box(
                    low=np.concatenate([box.low, np.zeros(extra, np.float32)]),
                    high=np.concatenate([box.high, np.ones(extra, np.float32)]),
                    dtype=np.float32,
                ),
                "action_mask": spaces.Box(0, 1, shape=(self.M + 1,), dtype=np.int8),
            }
        )
        self._action_space = spaces.Discrete(self.M + 1)
        self._chosen = np.zeros(self.M, dtype=np.int8)
        self._box: np.ndarray | None = None
        self._info: dict[str, Any] = {}

    # --- PettingZoo API ------------------------------------------------------------------
    @property
    def max_cycles(self) -> int | None:
        """The wrapped env's ``max_cycles`` (counted in window steps, not decisions)."""
        return self.inner.max_cycles

    @max_cycles.setter
    def max_cycles(self, value: int | None) -> None:
        self.inner.max_cycles = value

    def observation_space(self, agent: str) -> spaces.Space:
        """The observation space of ``agent`` (the same object on every call)."""
        self._check_agent(agent)
        return self._obs_space

    def action_space(self, agent: str) -> spaces.Space:
        """``Discrete(M + 1)``: 0 = stop, j = add sensor j (the same object on every call)."""
        self._check_agent(agent)
        return self._action_space

    def _check_agent(self, agent: str) -> None:
        if agent not in self.possible_agents:
            raise ValueError(f"agent must be one of {self.possible_agents}, got {agent!r}")

    def reset(self, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        """Reset the wrapped env; the first decision is the first pick of window step K+1."""
        obs, infos = self.inner.reset(seed=seed, options=options)
        self.np_random = self.inner.np_random
        self._chosen[:] = 0
        self._box = obs["attacker"]
        self._info = infos["attacker"]
        self.agents = list(self.inner.agents)
        return {"attacker": self._observe()}, {"attacker": dict(self._info)}

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """Take one decision: add a sensor to the step's set, or stop and take the window step.

        Raises:
            RuntimeError: Before :meth:`reset` or after the episode ended.
            ValueError: For a missing or unknown agent's action, an action outside
                ``Discrete(M + 1)``, or (with ``illegal_action="error"``) outside the mask.
        """
        if self._box is None:
            raise RuntimeError("step() called before reset(): call reset() first")
        if not self.agents:
            raise RuntimeError(
                "step() called after the episode ended: call reset() to start a new one"
            )
        if not isinstance(actions, dict) or set(actions) != {"attacker"}:
            raise ValueError(
                "actions must be a dict with exactly one entry per live agent ['attacker'], "
                f"got {actions!r}"
            )
        action = actions["attacker"]
        check_action(self._action_space, action, "attacker")
        j = int(action)
        mask = self.action_mask()
        if not mask[j]:
            if self.illegal_action == "error":
                raise ValueError(
                    f"attacker action {j} (add sensor {j}) is illegal: "
                    + (
                        f"sensor {j} is already in this step's set"
                        if self._chosen[j - 1]
                        else f"the step's set already uses the budget left ({self._left()})"
                    )
                    + f"; legal actions are those with action_mask[a] = 1: "
                    f"{np.flatnonzero(mask).tolist()}"
                )
            j = STOP
        reward, term, trunc = 0.0, False, False
        if j != STOP:
            self._chosen[j - 1] = 1
        if j == STOP or (self.skip_forced and self._forced()):
            reward, term, trunc = self._commit()
            while self.skip_forced and not (term or trunc) and self._forced():
                r, term, trunc = self._commit()
                reward += r
        obs = {"attacker": self._observe()}
        infos = {"attacker": dict(self._info)}
        if term or trunc:
            self.agents = []
        return obs, {"attacker": reward}, {"attacker": term}, {"attacker": trunc}, infos

    def _commit(self) -> tuple[float, bool, bool]:
        """Take the window step with the set built so far; start an empty set."""
        obs, rewards, terms, truncs, infos = self.inner.step({"attacker": self._chosen.copy()})
        self._chosen[:] = 0
        self._box = obs["attacker"]
        self._info = infos["attacker"]
        return float(rewards["attacker"]), bool(terms["attacker"]), bool(truncs["attacker"])

    def _left(self) -> int:
        """Budget left after the set being built."""
        return int(self.attack.remaining) - int(self._chosen.sum())

    def _forced(self) -> bool:
        """True when stop is the only legal action."""
        return self._left() <= 0 or bool(self._chosen.all())

    def action_mask(self) -> np.ndarray:
        """(M + 1,) int8: 1 = legal now (stop always; sensor j if new and within budget)."""
        mask = np.empty(self.M + 1, dtype=np.int8)
        mask[STOP] = 1
        mask[1:] = (self._chosen == 0) & (self._left() > 0)
        return mask

    def action_masks(self, agent: str = "attacker") -> np.ndarray:
        """Legal actions now (sb3-contrib's MaskablePPO convention)."""
        self._check_agent(agent)
        return self.action_mask()

    def _observe(self) -> dict[str, np.ndarray]:
        budget = self.attack.budget
        box = np.concatenate(
            [self._box, self._chosen.astype(np.float32), [max(self._left(), 0) / budget]]
        ).astype(np.float32)
        return {"observation": box, "action_mask": self.action_mask()}

    def render(self, mode: str | None = None) -> str | np.ndarray | None:
        """The wrapped env's rendering of its last window step."""
        return self.inner.render(mode)

    def state(self) -> np.ndarray:
        """Global state: the wrapped env's."""
        return self.inner.state()

    def close(self) -> None:
        """Close the wrapped env."""
        self.inner.close()


def play_plan(env: SequentialSetEnv, plan: list[list[int]], seed: int | None = None) -> float:
    """Play ``plan`` (per window step, the 1-based sensors) in ``env``; return the return.

    Each step's sensors are picked in increasing order, then stop, skipping what the env plays
    itself; the episode's rewards are summed.

    Raises:
        ValueError: If ``plan`` spends more than the budget or is shorter than the episode.
    """
    env.reset(seed=seed)
    total = 0.0
    for k, sensors in enumerate(plan):
        if not env.agents:
            if any(len(s) for s in plan[k:]):
                raise ValueError(f"plan attacks after the episode ended (window step {k + 1})")
            return total
        for j in sorted(int(s) for s in sensors):
            if not env.action_mask()[j]:
                raise ValueError(
                    f"plan is not legal: sensor {j} at window step {k + 1} (action mask "
                    f"{env.action_mask().tolist()})"
                )
            r = env.step({"attacker": j})[1]
            total += r["attacker"]
        if env.agents and int(env.inner.sim.k) == k:  # the step is not committed yet
            r = env.step({"attacker": STOP})[1]
            total += r["attacker"]
    if env.agents:
        raise ValueError(f"plan has {len(plan)} window steps; the episode is longer")
    return total
