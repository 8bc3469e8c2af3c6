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

Decision order (``order``): ``"time"`` (default), time-major as the filter runs (all picks of
window step K+1, stop, then K+2, ...), so a decision sees the covariance it acts on; or
``"plan"``, plan-first: the attacker first picks (sensor, window step) pairs of the whole
horizon, action ``1 + k·M + (j - 1)`` = sensor j at window step K+1+k (``Discrete(N·M + 1)``),
then stops; the filter then plays the plan one window step per decision (stop is the only legal
action there), each paying that step's reward. The mask of ``"plan"`` allows a pair while it is
not in the plan and the plan is smaller than the budget. ``"increasing"`` is ``"plan"`` with the
picks in increasing order: the same actions, observation and rewards, and the mask also forbids
every pair at or below the last pick (stop as in ``"plan"``). A plan of c pairs can be picked in
c! orders in ``"plan"`` and in one order here, so a policy's randomness (an entropy bonus) goes
into trying other plans rather than into reordering one; every plan stays reachable (by its
pairs in increasing order) and returns the same value. A decision whose only legal action is stop
(the budget is spent, or every sensor is in the set) is played by the env itself
(``skip_forced=True``, default): an episode takes at most ``N + c`` decisions, and once the
budget is spent it ends at once. Pass ``skip_forced=False`` to take every stop yourself.

State groups (``groups="state"``, plan-first orders only): the action space gains N·n group
actions after the pairs' (``Discrete(N·M + 1 + N·n)``); action ``N·M + 1 + k·n + j`` adds, in
one decision, every pair of window step K+1+k whose sensor sees state j (a nonzero of the
sensor's rows of ``H`` in column j: :func:`state_groups`). These are the smallest sets that bias
one state without touching any other measurement (the stealthy attack ``a = H c`` with ``c``
nonzero at one state), and an objective can pay for such a set only once all of it is attacked:
on the ``dc-ieee14-50`` preset the proved optimum holds the four meters that see bus 8's angle,
which are worth at most 69 % of it one to three at a time, so a learner that builds its plan pair
by pair stops at SFS's set (98.5 %), and reaches the optimum with the groups. A group is legal
while the plan is not committed, above the last group picked (groups go in increasing order;
pairs and groups may alternate) and when it adds between 1 and the budget left new pairs (pairs
already in the plan count once). The observation is unchanged (the plan's N·M entries show what
a group added); the mask has ``N·M + 1 + N·n`` entries. Every plan of the pair actions stays
reachable by them alone and returns the same value; a plan built with groups returns what the
same pairs return picked one by one.

Dynamics and rewards are those of the wrapped env: a pick pays 0, and a stop pays the wrapped
env's reward of the window step it commits (with ``skip_forced``, the sum over the window steps
it plays), so an episode's return equals the return of the same attack set played in the
``"bitmask"`` or ``"multibinary"`` format, and every set of those formats is reachable.

Illegal actions (``illegal_action``): an action outside the mask (a sensor already in the step's
set, or any sensor once the set uses up the budget left; ``"increasing"``: also a pair at or below
the last pick; a group that is closed) raises ``ValueError`` with
``"error"``, and acts as stop with ``"trim"`` (default) and ``"noop"``, so that every decision
either grows the set or advances the filter. An action outside ``Discrete(M + 1)`` is always a
``ValueError``.

Observation: ``{"observation": Box, "action_mask": Box(0, 1, (A,), int8)}`` (A = M + 1, or
N·M + 1 with ``"plan"`` or ``"increasing"``); the ``Box`` is the wrapped env's features (see
``sparse_attack_v0``) followed by M entries (1 = sensor in the set being built; plan-first
orders: N·M entries, the plan,
step-major) and the budget that would be left after the set (the plan's steps not yet played),
as a fraction of ``budget``.
Infos are the wrapped env's (of its last window step; at a pick, unchanged).
"""

from __future__ import annotations

from collections import deque
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from fdia_env._validation import check_choice, check_int
from fdia_env.actions import check_action
from fdia_env.attacks.sparse import ILLEGAL_ACTIONS, SparseAttack
from fdia_env.attacks.subsets import SubsetChoice, game_sizes
from fdia_env.envs.parallel import FdiaParallelEnv, check_reset_args, end_step
from fdia_env.envs.policy import PolicyBase, observation_array
from fdia_env.episode import EpisodeSpec
from fdia_env.scenarios import Scenario
from fdia_env.systems import LinearSystem

STOP = 0
"""The stop action: commit the set built so far and take the window step."""

ORDERS = ("time", "plan", "increasing")
"""Decision orders of the sparse attacker's sequential format (see the module docstring)."""

PLAN_FIRST_ORDERS = ("plan", "increasing")
"""The orders that pick the whole horizon's (sensor, window step) pairs first."""

GROUPINGS = ("state",)
"""Group actions of the plan-first orders (``groups``; see the module docstring)."""


def check_groups(groups: Any, order: str) -> str | None:
    """``groups`` if it is None or one of :data:`GROUPINGS` with a plan-first ``order``.

    Raises:
        ValueError: For another value, or a grouping with the ``"time"`` order.
    """
    if groups is None:
        return None
    check_choice("groups", groups, GROUPINGS)
    if order not in PLAN_FIRST_ORDERS:
        raise ValueError(
            f"groups={groups!r} applies to the plan-first orders {list(PLAN_FIRST_ORDERS)} "
            f"only, got order={order!r}"
        )
    return groups


def group_illegal(
    j: int, slots: int, n: int, playing: bool, last_group: int, new: int, left: int
) -> tuple[str, str]:
    """What group action ``j`` is and why it is illegal (the single and vector envs' errors).

    Args:
        j: The action (``slots + 1 + k·n + state``).
        slots: The pair actions' count (N·M).
        n: The state size.
        playing: The plan is committed.
        last_group: The last group picked (0: none).
        new: The group's pairs not in the plan.
        left: The budget left.
    """
    k, state = divmod(j - slots - 1, n)
    what = f"the sensors that see state {state + 1} at window step {k + 1}"
    if playing:
        why = "the plan is committed and plays out: stop (0) is the only legal action"
    elif j <= last_group:
        why = f"groups are picked in increasing order and the last group is {last_group}"
    elif new == 0:
        why = "every pair of the group is already in the plan"
    else:
        why = f"its {new} new pairs exceed the budget left ({left})"
    return what, why


def state_groups(system: LinearSystem, horizon: int) -> np.ndarray:
    """(N·n, N·M) bool: group ``k·n + j``, the pairs of window step k whose sensor sees state j.

    A sensor sees state j where its rows of ``H`` are nonzero in column j.

    Every sensor that sees a state has to be attacked for a bias of that state alone to leave
    every other measurement untouched (the stealthy attack ``a = H c`` of a DC grid with ``c``
    nonzero at one state), so these are the smallest sets that move one state unseen.
    """
    sees = np.zeros((system.M, system.n), dtype=bool)
    np.logical_or.at(sees, system.row_sensor, system.H != 0)
    M, n = system.M, system.n
    groups = np.zeros((horizon, n, horizon, M), dtype=bool)
    for k in range(horizon):
        groups[k, :, k, :] = sees.T
    return groups.reshape(horizon * n, horizon * M)


def _fresh(info: dict[str, Any]) -> dict[str, Any]:
    """A decision's info: a new dict with its arrays copied.

    The wrapped env's info stays the same over the decisions of one window step (or round), and
    a user who keeps the infos (a rollout buffer) must not hold one array that later changes.
    """
    return {k: v.copy() if isinstance(v, np.ndarray) else v for k, v in info.items()}


class SequentialBase(ParallelEnv):
    """What the sequential wrappers share: the wrapped env's delegation and the checks.

    A subclass builds its ``Dict(observation, action_mask)`` spaces per player into
    ``self._obs_spaces`` and calls :meth:`_reset_inner` from its ``reset``.

    Args:
        inner: The wrapped :class:`FdiaParallelEnv` (the subclass checks its attack model).
        illegal_action: ``"trim"``, ``"noop"`` or ``"error"``.
        skip_forced: Play the decisions whose only legal action is stop.

    Raises:
        TypeError: If ``skip_forced`` is not a bool.
        ValueError: For a bad ``illegal_action``.
    """

    metadata: ClassVar[dict[str, Any]] = dict(FdiaParallelEnv.metadata)

    def __init__(self, inner: FdiaParallelEnv, illegal_action: str, skip_forced: bool) -> None:
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
        self._action_space = spaces.Discrete(self.M + 1)
        self._obs_spaces: dict[str, spaces.Dict] = {}
        self._box: Any = None
        self._max_cycles = inner.max_cycles  # counted in decisions here, not in the inner env
        inner.max_cycles = None
        self._decisions = 0

    def _masked_space(self, box: spaces.Box, extra: int) -> spaces.Dict:
        """``Dict(observation, action_mask)``: ``box`` followed by ``extra`` entries in [0, 1]."""
        n_actions = int(self._action_space.n)
        return spaces.Dict(
            {
                "observation": spaces.Box(
                    low=np.concatenate([box.low, np.zeros(extra, np.float32)]),
                    high=np.concatenate([box.high, np.ones(extra, np.float32)]),
                    dtype=np.float32,
                ),
                "action_mask": spaces.Box(0, 1, shape=(n_actions,), dtype=np.int8),
            }
        )

    # --- PettingZoo API ------------------------------------------------------------------
    @property
    def max_cycles(self) -> int | None:
        """PettingZoo's episode-length limit, counted in decisions (None: no limit).

        An episode still running after this many decisions is truncated (as PettingZoo's
        ``max_cycles`` counts a parallel env's steps); the wrapped env has no limit of its own.
        """
        return self._max_cycles

    @max_cycles.setter
    def max_cycles(self, value: int | None) -> None:
        self._max_cycles = None if value is None else check_int("max_cycles", value, minimum=1)

    def _limit(self, ended: bool) -> bool:
        """Count a decision; whether it truncates an episode that has not ``ended``."""
        self._decisions += 1
        limit = self._max_cycles
        return not ended and limit is not None and self._decisions >= limit

    @property
    def spec(self) -> EpisodeSpec:
        """The wrapped env's episode spec."""
        return self.inner.spec

    @property
    def scenario(self) -> Scenario:
        """The wrapped env's scenario."""
        return self.inner.scenario

    @property
    def system(self) -> LinearSystem:
        """The wrapped env's system."""
        return self.inner.system

    def observation_space(self, agent: str) -> spaces.Space:
        """The observation space of ``agent`` (the same object on every call)."""
        self._check_agent(agent)
        return self._obs_spaces[agent]

    def action_space(self, agent: str) -> spaces.Space:
        """``Discrete(M + 1)``: 0 = stop, j = pick sensor j (the same object on every call).

        The sparse attacker's ``order="plan"`` (and ``"increasing"``): ``Discrete(N·M + 1)``,
        0 = stop, 1 + k·M + j - 1 = sensor j at window step k + 1; with ``groups="state"``
        ``Discrete(N·M + 1 + N·n)``, N·M + 1 + k·n + j = the sensors that see state j + 1 at
        window step k + 1.
        """
        self._check_agent(agent)
        return self._action_space

    def _check_agent(self, agent: str) -> None:
        if agent not in self.possible_agents:
            raise ValueError(f"agent must be one of {self.possible_agents}, got {agent!r}")

    def reset(self, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        """Reset the wrapped env; the first decision is the first pick of its first step.

        Options the env does not read draw one ``UserWarning`` naming the caller's line (see
        :func:`~fdia_env.envs.parallel.check_reset_args`).

        Raises:
            ValueError: For a bad seed or a bad value of an option the env reads.
        """
        check_reset_args(seed, options, self.attack.reset_options)
        return self._reset(seed, options)

    def _reset(self, seed: int | None, options: dict | None) -> tuple[dict, dict]:
        """Reset with arguments already checked: the wrapped env gets the options it reads."""
        known = self.attack.reset_options
        kept = None if options is None else {k: v for k, v in options.items() if k in known}
        obs, infos = self.inner.reset(seed=seed, options=kept)
        self.np_random = self.inner.np_random
        self.agents = list(self.inner.agents)
        self._decisions = 0
        return self._start(obs, infos)

    def _start(self, obs: dict, infos: dict) -> tuple[dict, dict]:
        """Start the first decision from the wrapped env's reset; the wrapper's obs and infos."""
        raise NotImplementedError

    def _check_step(self, actions: Any) -> None:
        """Raise for a step before reset, after the episode, or without one action per agent."""
        if self._box is None:
            raise RuntimeError("step() called before reset(): call reset() first")
        if not self.agents:
            raise RuntimeError(
                "step() called after the episode ended: call reset() to start a new one"
            )
        if not isinstance(actions, dict) or set(actions) != set(self.agents):
            raise ValueError(
                f"actions must be a dict with exactly one entry per live agent {self.agents}, "
                f"got {actions!r}"
            )

    def render(self, mode: str | None = None) -> str | np.ndarray | None:
        """The wrapped env's rendering of its last step."""
        return self.inner.render(mode)

    def state(self) -> np.ndarray:
        """Global state: the wrapped env's."""
        return self.inner.state()

    def close(self) -> None:
        """Close the wrapped env."""
        self.inner.close()


class SequentialSetEnv(SequentialBase):
    """Sparse attacker's sequential format over a ``"multibinary"`` sparse-attack env.

    See the module docstring for the action, mask, observation and reward contract.

    Args:
        inner: A single-player :class:`FdiaParallelEnv` whose attack model is a
            :class:`SparseAttack` in the ``"multibinary"`` format (any over-budget rule: the
            wrapper sends only sets that fit the budget left).
        illegal_action: ``"trim"`` (default), ``"noop"`` (an action outside the mask stops) or
            ``"error"`` (it raises ``ValueError``).
        skip_forced: Play the decisions whose only legal action is stop (default True).
        order: ``"time"`` (default: each window step's set, in the filter's order) or
            ``"plan"`` (the (sensor, window step) pairs of the whole horizon first) or
            ``"increasing"`` (as ``"plan"``, the pairs picked in increasing order).
        groups: None (default) or ``"state"`` (plan-first orders only): also offer group
            actions, each adding every pair of one window step whose sensor sees one state
            (see the module docstring).

    Raises:
        TypeError: If ``inner`` is not such an env.
        ValueError: For a budget of 0 (there would be no decision to make), a bad
            ``illegal_action``, ``order`` or ``groups``.
    """

    def __init__(
        self,
        inner: FdiaParallelEnv,
        illegal_action: str = "trim",
        skip_forced: bool = True,
        order: str = "time",
        groups: str | None = None,
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
        self.order = check_choice("order", order, ORDERS)
        self.groups = check_groups(groups, order)
        super().__init__(inner, illegal_action, skip_forced)
        self.horizon = N = int(inner.spec.horizon)
        self.plan_first = order in PLAN_FIRST_ORDERS
        self.increasing = order == "increasing"
        slots = N * self.M if self.plan_first else self.M
        # group actions slots + 1 .. slots + G: (G, slots) 0/1, the pairs each one adds
        grouped = state_groups(inner.system, N) if groups else np.zeros((0, slots), bool)
        self._groups = grouped.astype(np.int64)
        self._group_sizes = self._groups.sum(1)
        self._slots = slots
        self._action_space = spaces.Discrete(slots + 1 + len(grouped))
        self._obs_spaces = {
            "attacker": self._masked_space(inner.observation_space("attacker"), slots + 1)
        }
        # the pairs picked: (M,) for the current window step, or (N, M) for the plan
        self._chosen = np.zeros((N, self.M) if self.plan_first else self.M, dtype=np.int8)
        self._flat = self._chosen.reshape(-1)  # a view: slot j - 1 of action j
        self._played = 0  # window steps played ("plan": > 0 once the plan is committed)
        self._last = STOP  # "increasing": the last pick (the pairs up to it are closed)
        self._last_group = STOP  # groups: the last group picked (the groups up to it are closed)
        self._box: np.ndarray | None = None
        self._info: dict[str, Any] = {}
        # the decision's state, kept up to date by _refresh (each decision reads it several
        # times: the step's check, the observation, MaskablePPO's action_masks)
        self._pending = 0  # pairs in the set being built ("plan": in the steps not yet played)
        self._remaining = 0  # the wrapped env's budget left
        self._mask = np.zeros(int(self._action_space.n), dtype=np.int8)
        self._obs = np.zeros(self._obs_spaces["attacker"]["observation"].shape, np.float32)
        self._n_box = int(inner.observation_space("attacker").shape[0])

    def _start(self, obs: dict, infos: dict) -> tuple[dict, dict]:
        """The first decision is the first pick of window step K+1 (``"plan"``: of the plan)."""
        self._chosen[:] = 0
        self._played = 0
        self._last = STOP
        self._last_group = STOP
        self._pending = 0
        self._box = obs["attacker"]
        self._info = infos["attacker"]
        self._obs[self._n_box : -1] = 0.0
        self._played_out()
        return {"attacker": self._observe()}, {"attacker": _fresh(self._info)}

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """Take one decision: add a sensor (pair) to the set, or stop and take the window step.

        Raises:
            RuntimeError: Before :meth:`reset` or after the episode ended.
            ValueError: For a missing or unknown agent's action, an action outside the action
                space, or (with ``illegal_action="error"``) outside the mask.
        """
        self._check_step(actions)
        j = check_action(self._action_space, actions["attacker"], "attacker")
        if not self._mask[j]:
            if self.illegal_action == "error":
                raise ValueError(self._illegal_message(j, self.action_mask()))
            j = STOP
        reward, term, trunc = 0.0, False, False
        if j > self._slots:  # a group: its pairs not yet in the plan
            new = np.flatnonzero(self._groups[j - self._slots - 1] > self._flat)
            self._flat[new] = 1
            self._last_group = j
            self._obs[self._n_box + new] = 1.0
            self._pending += new.size
            self._refresh()
        elif j != STOP:
            self._flat[j - 1] = 1
            if self.increasing:
                self._last = j
            self._obs[self._n_box + j - 1] = 1.0
            self._pending += 1
            self._refresh()
        if j == STOP or (self.skip_forced and self._forced()):
            reward, term, trunc = self._commit()
            while self.skip_forced and not (term or trunc) and self._forced():
                r, term, trunc = self._commit()
                reward += r
            self._played_out()
        trunc = trunc or self._limit(term)
        obs = {"attacker": self._observe()}
        infos = {"attacker": _fresh(self._info)}
        if term or trunc:
            self.agents = []
        return obs, {"attacker": reward}, {"attacker": term}, {"attacker": trunc}, infos

    def _illegal_message(self, j: int, mask: np.ndarray) -> str:
        legal = (
            f"; legal actions are those with action_mask[a] = 1: {np.flatnonzero(mask).tolist()}"
        )
        if not self.plan_first:
            why = (
                f"sensor {j} is already in this step's set"
                if self._chosen[j - 1]
                else f"the step's set already uses the budget left ({self._left()})"
            )
            return f"attacker action {j} (add sensor {j}) is illegal: {why}" + legal
        if j > self._slots:
            return self._illegal_group(j) + legal
        k, i = divmod(j - 1, self.M)
        if self._played:
            why = "the plan is committed and plays out: stop (0) is the only legal action"
        elif self._flat[j - 1]:
            why = "this pair is already in the plan"
        elif self.increasing and j <= self._last:
            why = (
                f"order='increasing' picks the pairs in increasing order and the last pick is "
                f"action {self._last}"
            )
        else:
            why = f"the plan already uses the budget ({self.attack.budget})"
        return (
            f"attacker action {j} (sensor {i + 1} at window step {k + 1}) is illegal: {why}" + legal
        )

    def _illegal_group(self, j: int) -> str:
        g = j - self._slots - 1
        new = int(self._group_sizes[g] - self._groups[g] @ self._flat)
        state = (bool(self._played), self._last_group, new, self._left())
        what, why = group_illegal(j, self._slots, self.system.n, *state)
        return f"attacker action {j} ({what}) is illegal: {why}"

    def _current(self) -> np.ndarray:
        """The set of the window step to play: (M,) int8."""
        return self._chosen[self._played] if self.plan_first else self._chosen

    def _commit(self) -> tuple[float, bool, bool]:
        """Take the window step with its set; (``"time"``) start an empty set.

        The wrapped env's observation and infos are read by :meth:`_played_out`, once the
        decision's last window step is played (with ``render_mode="human"`` each step is the
        wrapped env's full ``step``, which draws it).
        """
        current = self._current()
        if self.inner.render_mode == "human":
            _, rewards, terms, truncs, _ = self.inner.step({"attacker": current.copy()})
            reward, term, trunc = rewards["attacker"], terms["attacker"], truncs["attacker"]
        else:  # the set is in the action space and within the budget left: checked here
            reward, term, trunc = self.inner._advance({"attacker": current.copy()})
            if term or trunc:  # the wrapped env's episode ends (its outputs: _played_out)
                end_step(self.inner, {}, {}, {}, term, trunc)
        self._pending -= int(current.sum())
        self._remaining = int(self.attack.remaining)
        if not self.plan_first:
            self._chosen[:] = 0
        self._played += 1
        return float(reward), bool(term), bool(trunc)

    def _played_out(self) -> None:
        """Read the wrapped env's observation, infos and budget after its window steps."""
        inner = self.inner
        self._box = inner._observe("attacker")
        self._info = inner._infos(["attacker"])["attacker"]
        self._remaining = int(self.attack.remaining)  # (after a reset)
        self._obs[: self._n_box] = self._box
        if not self.plan_first:
            self._obs[self._n_box : -1] = 0.0
        self._refresh()

    def _refresh(self) -> None:
        """The mask and the observation's budget entry of the decision now."""
        left = self._left()
        self._obs[-1] = max(left, 0) / self.attack.budget
        mask = self._mask
        S = self._slots
        if left > 0 and not (self.plan_first and self._played):
            np.equal(self._flat, 0, out=mask[1 : S + 1])
            if self._last:  # "increasing": the pairs up to the last pick are closed
                mask[1 : self._last + 1] = 0
            if len(self._groups):  # groups: above the last group, adding 1..left new pairs
                new = self._group_sizes - self._groups @ self._flat
                mask[S + 1 :] = (new > 0) & (new <= left)
                mask[S + 1 : self._last_group + 1] = 0
        else:
            mask[1:] = 0
        mask[STOP] = 1

    def _left(self) -> int:
        """Budget left after the set being built (``"plan"``: after its steps not yet played)."""
        return self._remaining - self._pending

    def _forced(self) -> bool:
        """True when stop is the only legal action."""
        if self.plan_first and self._played:
            return True
        if len(self._groups):  # (plan-first: a pick's _refresh has the mask up to date)
            return not self._mask[1:].any()
        if self.increasing and self._last == self._flat.size:  # no pair above the last pick
            return True
        return self._left() <= 0 or bool(self._chosen.all())

    def action_mask(self) -> np.ndarray:
        """(A,) int8: 1 = legal now (stop always; a new sensor or pair within the budget)."""
        return self._mask.copy()

    def action_masks(self, agent: str = "attacker") -> np.ndarray:
        """Legal actions now (sb3-contrib's MaskablePPO convention)."""
        self._check_agent(agent)
        return self.action_mask()

    def _observe(self) -> dict[str, np.ndarray]:
        return {"observation": self._obs.copy(), "action_mask": self._mask.copy()}


def plan_actions(env: SequentialSetEnv, plan: list[list[int]]) -> list[int]:
    """Plan-first orders: the actions (pairs in increasing order, then stop) that play ``plan``.

    Raises:
        ValueError: If ``env`` is not in a plan-first order (``"plan"``, ``"increasing"``), or
            ``plan`` names a window step beyond the horizon or a sensor outside 1..M.
    """
    if not env.plan_first:
        raise ValueError(
            f"env must be in a plan-first order {list(PLAN_FIRST_ORDERS)}, got order={env.order!r}"
        )
    if len(plan) > env.horizon:
        raise ValueError(f"plan has {len(plan)} window steps; the horizon is {env.horizon}")
    actions = []
    for k, sensors in enumerate(plan):
        for j in sorted(int(s) for s in sensors):
            if not 1 <= j <= env.M:
                raise ValueError(
                    f"plan names sensor {j} at window step {k + 1}: sensors are 1..{env.M}"
                )
            actions.append(1 + k * env.M + j - 1)
    return [*actions, STOP]


class PlanOrderPolicy(PolicyBase):
    """Plays a fixed attack set in a plan-first order (stable-baselines3 signature).

    At each decision: the lowest-numbered pair of the set not yet in the plan (read from the
    observation's N·M plan entries, before its last entry), else stop (0), which plays the plan
    out. Takes one (d,) observation or a (B, d) batch (a dict observation: its
    ``"observation"``).

    Args:
        attacks: The set's 0-based (window step, sensor) pairs, e.g. a solver's
            ``SparseResult.attacks``.
        num_sensors: M.
        horizon: N.

    Raises:
        ValueError: For a pair outside the N x M window.

    Example:
        >>> policy = PlanOrderPolicy([(1, 0), (0, 2)], num_sensors=3, horizon=2)
        >>> int(policy.predict(np.zeros(4 + 6 + 1))[0])  # sensor 3 at window step 1
        3
    """

    def __init__(self, attacks: Any, num_sensors: int, horizon: int) -> None:
        M = check_int("num_sensors", num_sensors, minimum=1)
        N = check_int("horizon", horizon, minimum=1)
        self.size = N * M
        self.todo = np.zeros(self.size, dtype=bool)
        for k, i in attacks:
            if not (0 <= int(k) < N and 0 <= int(i) < M):
                raise ValueError(
                    f"attacks must be (step, sensor) pairs in [0, {N}) x [0, {M}), got ({k}, {i})"
                )
            self.todo[int(k) * M + int(i)] = True

    @classmethod
    def from_result(cls, result: Any) -> PlanOrderPolicy:
        """The policy of a solver's answer (``attacks``, ``num_sensors``, ``horizon``)."""
        return cls(result.attacks, int(result.num_sensors), int(result.horizon))

    def act(self, observation: Any, deterministic: bool = False) -> Any:
        """1 + the next pair's slot, or 0 (stop): ``np.int64``, or (B,) for a batch."""
        plan = observation_array(observation)[..., -(self.size + 1) : -1] > 0.5
        todo = self.todo & ~plan
        action = np.where(todo.any(-1), todo.argmax(-1) + 1, 0).astype(np.int64)
        return np.int64(action) if action.ndim == 0 else action


def play_plan(env: SequentialSetEnv, plan: list[list[int]], seed: int | None = None) -> float:
    """Play ``plan`` (per window step, the 1-based sensors) in ``env``; return the return.

    ``"time"`` order: each step's sensors are picked in increasing order, then stop, skipping
    what the env plays itself. Plan-first orders: the pairs of :func:`plan_actions`, then stop
    until the episode ends. The episode's rewards are summed.

    Raises:
        ValueError: If ``plan`` spends more than the budget or is shorter than the episode.
    """
    env.reset(seed=seed)
    total = 0.0
    if env.plan_first:
        for a in plan_actions(env, plan):
            if not env.agents:  # the env committed the plan when it used the budget
                if a == STOP:
                    break
                raise ValueError("plan spends more than the budget (the episode ended)")
            if a != STOP and not env.action_mask()[a]:
                raise ValueError(f"plan is not legal: action {a} (action mask forbids it)")
            total += env.step({"attacker": a})[1]["attacker"]
        while env.agents:
            total += env.step({"attacker": STOP})[1]["attacker"]
        return total
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


# --- The sensor game: both players build their subset one sensor per decision ----------------


class SequentialSubsetEnv(SequentialBase):
    """Sensor game (``sensor_game_v0``) with both players' subsets built one sensor per decision.

    ``sensor_game_v0.parallel_env(action="sequential")`` builds it; its AEC view
    (``sensor_game_v0.env(action="sequential")``) and Gymnasium views
    (``gymnasium.make("fdia_env/SensorGameAttacker-v0", action="sequential")``, ...Defender...)
    wrap it as they wrap the subset format.

    Both players decide at every decision (the game stays simultaneous: neither sees the other's
    picks of the round). Action space ``Discrete(M + 1)`` for each: ``0`` = stop, ``j`` (1..M) =
    pick sensor j. The attacker picks the sensors it attacks (the set A); the defender picks the
    sensors it leaves out (D is the rest), so that with ``max_subset_size=k`` it takes at most
    k decisions, as the attacker does. A round of the wrapped game is played once both players
    have stopped; until then the player that stopped waits (its only legal action is stop).

    Masks (``(M + 1,)`` int8, in the observation dict and from :meth:`action_masks`): a sensor is
    legal while it is not picked and the player has picks left (attacker: ``k`` with
    ``max_subset_size=k``, else M; defender: ``min(k, M - 1)``, else ``M - 1``, so D is never
    empty); stop is legal once the attacker's set is non-empty (the defender may stop at once:
    D = every sensor). Every subset of the ``Discrete`` subset format is reachable, and only
    those. With ``skip_forced=True`` (default) a player whose only legal action is stop has
    stopped (its stop is played by the env): it then waits, sending stop.

    Rewards: 0 at a decision that plays no round; at the decision that plays one, the wrapped
    env's rewards of that round, so an episode's returns equal those of the same subsets played
    in the subset format. Infos are the wrapped env's of its last round.

    Illegal actions (``illegal_action``): with ``"error"`` an action outside the mask raises
    ``ValueError``; with ``"trim"`` (default) or ``"noop"`` a pick outside the mask acts as stop,
    and an illegal stop (the attacker's, with nothing picked) or a waiting player's pick is
    ignored for that decision. An action outside ``Discrete(M + 1)`` is always a ``ValueError``.

    Observation per player: ``{"observation": Box, "action_mask": Box(0, 1, (M + 1,), int8)}``,
    the ``Box`` being the wrapped env's features of that player followed by M entries
    (1 = sensor picked this round by this player).

    Args:
        inner: A sensor-game :class:`FdiaParallelEnv` (``sensor_game_v0.parallel_env()``, any
            ``max_subset_size``, ``types``, ``rounds``).
        illegal_action: ``"trim"`` (default), ``"noop"`` or ``"error"``.
        skip_forced: Stop for a player whose only legal action is stop (default True).

    Raises:
        TypeError: If ``inner`` is not a sensor-game env, or ``skip_forced`` not a bool.
        ValueError: For a bad ``illegal_action``.
    """

    def __init__(
        self, inner: FdiaParallelEnv, illegal_action: str = "trim", skip_forced: bool = True
    ) -> None:
        if (
            not isinstance(inner, FdiaParallelEnv)
            or not isinstance(inner.attack, SubsetChoice)
            or not isinstance(inner.defense, SubsetChoice)
        ):
            raise TypeError(
                "inner must be a sensor-game FdiaParallelEnv (sensor_game_v0.parallel_env), "
                f"got {type(inner).__name__}"
            )
        super().__init__(inner, illegal_action, skip_forced)
        self.defense = inner.defense
        M = self.M
        self.models = {"attacker": inner.attack, "defender": inner.defense}
        self.drops = {"attacker": False, "defender": True}
        k = inner.attack.max_subset_size
        self.max_picks = {"attacker": M if k is None else k}
        self.max_picks["defender"] = M - game_sizes(M, k, "defender")[0]
        self.min_picks = {"attacker": 1, "defender": 0}
        self.index = {
            p: {s: j for j, s in enumerate(m.subsets)} for p, m in self.models.items()
        }  # fmt: skip
        self._obs_spaces = {
            p: self._masked_space(inner.observation_space(p), M) for p in self.possible_agents
        }
        self._chosen = {p: np.zeros(M, dtype=np.int8) for p in self.possible_agents}
        self._stopped = dict.fromkeys(self.possible_agents, False)
        self._box: dict[str, np.ndarray] | None = None
        self._infos: dict[str, dict] = {}
        self.committed = False
        """Whether the last :meth:`step` (or :meth:`reset`) started a new round."""
        self.rounds_started = 0
        """Rounds started since the env was made (never reset: identifies a round)."""

    def _start(self, obs: dict, infos: dict) -> tuple[dict, dict]:
        """The first decision is the first pick of round 1."""
        self._new_round(obs, infos)
        return self._observe_all(), {p: _fresh(self._infos[p]) for p in self.agents}

    def _new_round(self, obs: dict, infos: dict) -> None:
        self._box = dict(obs)
        self._infos = dict(infos)
        for p in self.possible_agents:
            self._chosen[p][:] = 0
            self._stopped[p] = self.skip_forced and self._forced(p)
        self.committed = True
        self.rounds_started += 1

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """Take one decision of both players; play the round once both have stopped.

        Raises:
            RuntimeError: Before :meth:`reset` or after the episode ended.
            ValueError: For a missing or unknown agent's action, an action outside
                ``Discrete(M + 1)``, or (with ``illegal_action="error"``) outside the mask.
        """
        self._check_step(actions)
        moves = {}
        for p in self.agents:
            j = check_action(self._action_space, actions[p], p)
            mask = self.action_mask(p)
            if not mask[j]:
                if self.illegal_action == "error":
                    raise ValueError(self._illegal_message(p, j, mask))
                j = STOP if (j != STOP and not self._stopped[p]) else -1  # -1: ignored
            moves[p] = j
        for p, j in moves.items():
            if j == STOP:
                self._stopped[p] = True
            elif j > 0:
                self._chosen[p][j - 1] = 1
                if self.skip_forced and self._forced(p):
                    self._stopped[p] = True
        self.committed = False
        rewards = dict.fromkeys(self.agents, 0.0)
        terms = dict.fromkeys(self.agents, False)
        truncs = dict.fromkeys(self.agents, False)
        if all(self._stopped[p] for p in self.agents):
            played = {p: self.index[p][self.subset(p)] for p in self.agents}
            obs, rewards, terms, truncs, infos = self.inner.step(played)
            rewards = {p: float(r) for p, r in rewards.items()}
            self._new_round(obs, infos)
        if self._limit(any(terms.values()) or any(truncs.values())):
            truncs = dict.fromkeys(truncs, True)
        out = (
            self._observe_all(),
            rewards,
            {p: bool(t) for p, t in terms.items()},
            {p: bool(t) for p, t in truncs.items()},
            {p: _fresh(self._infos[p]) for p in self.agents},
        )
        if any(terms.values()) or any(truncs.values()):
            self.agents = []
        return out

    def _illegal_message(self, p: str, j: int, mask: np.ndarray) -> str:
        if self._stopped[p]:
            why = f"{p} has stopped this round and waits: its only legal action is stop (0)"
        elif j == STOP:
            why = "the attacker's set is empty (it attacks at least one sensor)"
        elif self._chosen[p][j - 1]:
            why = f"sensor {j} is already picked this round"
        else:
            why = f"{p} has used its {self.max_picks[p]} picks of the round"
        legal = np.flatnonzero(mask).tolist()
        return f"{p} action {j} is illegal: {why}; legal actions (action_mask = 1): {legal}"

    def subset(self, agent: str) -> tuple[int, ...]:
        """The 0-based subset ``agent`` plays with its picks so far (the defender's: the rest)."""
        picked = self._chosen[agent].astype(bool)
        return tuple(np.flatnonzero(~picked if self.drops[agent] else picked).tolist())

    def _forced(self, p: str) -> bool:
        """True when stop is the only legal action of ``p`` (``p`` has used its picks)."""
        return int(self._chosen[p].sum()) >= self.max_picks[p]

    def action_mask(self, agent: str) -> np.ndarray:
        """(M + 1,) int8: 1 = legal now for ``agent`` (see the class docstring)."""
        n = int(self._chosen[agent].sum())
        mask = np.zeros(self.M + 1, dtype=np.int8)
        if self._stopped[agent]:
            mask[STOP] = 1
            return mask
        mask[STOP] = n >= self.min_picks[agent]
        mask[1:] = (self._chosen[agent] == 0) & (n < self.max_picks[agent])
        return mask

    def action_masks(self, agent: str) -> np.ndarray:
        """Legal actions of ``agent`` now (sb3-contrib's MaskablePPO convention)."""
        self._check_agent(agent)
        return self.action_mask(agent)

    def gymnasium_view(self, agent: str = "attacker", opponent: Any = None) -> SequentialGameView:
        """The Gymnasium view for ``agent`` (what ``gymnasium.make`` returns for this format)."""
        return SequentialGameView(self, agent, opponent)

    def inner_observation(self, agent: str) -> np.ndarray:
        """``agent``'s observation in the wrapped (subset-format) env after its last round."""
        self._check_agent(agent)
        if self._box is None:
            raise RuntimeError("inner_observation() called before reset(): call reset() first")
        return self._box[agent]

    def _observe_all(self) -> dict[str, dict[str, np.ndarray]]:
        return {
            p: {
                "observation": np.concatenate(
                    [self._box[p], self._chosen[p].astype(np.float32)]
                ).astype(np.float32),
                "action_mask": self.action_mask(p),
            }
            for p in self.agents or self.possible_agents
        }


def subset_actions(env: SequentialSubsetEnv, agent: str, subset: tuple[int, ...]) -> list[int]:
    """The picks (1-based, increasing) that make ``agent`` play the 0-based ``subset``."""
    chosen = set(subset)
    if env.drops[agent]:
        return [i + 1 for i in range(env.M) if i not in chosen]
    return [i + 1 for i in sorted(chosen)]


class SequentialGameView(gym.Env):
    """Gymnasium view of :class:`SequentialSubsetEnv` for one player, the other fixed.

    The other player is a policy of the subset format (``Discrete`` subset index, e.g.
    :class:`~fdia_env.envs.opponents.FixedMix`, default the uniform mix), asked once per round
    with its subset-format observation, exactly as the subset format's view asks it; its subset
    is then picked one sensor per decision, then stop. So a learner and opponent play the same
    rounds as in the subset format. The mask is in ``info["action_mask"]`` and
    :meth:`action_masks` (sb3-contrib's MaskablePPO).

    Args:
        parallel: The sequential sensor game.
        agent: ``"attacker"`` or ``"defender"``.
        opponent: The other player's subset-format policy (None: the uniform mix).
    """

    def __init__(
        self, parallel: SequentialSubsetEnv, agent: str = "attacker", opponent: Any = None
    ) -> None:
        from fdia_env.envs.opponents import FixedMix
        from fdia_env.envs.single_agent import check_agent, check_opponent

        check_agent(agent, parallel.possible_agents)
        self.parallel = parallel
        self.agent = agent
        self.other = next(p for p in parallel.possible_agents if p != agent)
        n_other = len(parallel.models[self.other].subsets)
        if opponent is None:
            opponent = FixedMix.uniform(n_other)
        check_opponent(opponent, spaces.Discrete(n_other))
        self.opponent = opponent
        self.render_mode = parallel.render_mode
        self.metadata = {
            "render_modes": list(parallel.metadata["render_modes"]),
            "render_fps": parallel.metadata["render_fps"],
        }
        self.observation_space = parallel.observation_space(agent)["observation"]
        self.action_space = parallel.action_space(agent)
        self._plan: list[int] = []
        self._first_round = False
        self.first_subsets: deque[int] = deque(maxlen=100_000)
        """The learner's subset index (subset format) in the first round of the last episodes."""

    def _plan_round(self) -> None:
        obs = self.parallel.inner_observation(self.other)
        a, _ = self.opponent.predict(obs, deterministic=True)
        subset = self.parallel.models[self.other].subsets[int(a)]
        self._plan = subset_actions(self.parallel, self.other, subset)

    def reset(
        self, *, seed: int | None = None, options: dict | None = None
    ) -> tuple[np.ndarray, dict]:
        """Reset the sequential game; ``seed`` seeds every draw (the opponent's too)."""
        check_reset_args(seed, options, self.parallel.attack.reset_options)
        super().reset(seed=None if seed is None else int(seed))
        obs, infos = self.parallel._reset(seed, options)  # checked: one warning, naming the caller
        if seed is not None and hasattr(self.opponent, "reset"):
            self.opponent.reset(seed=int(seed) + 1)  # as the subset format's view
        self._plan_round()
        self._first_round = True
        own = obs[self.agent]
        return own["observation"], {**infos[self.agent], "action_mask": own["action_mask"]}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        """Take one decision against the opponent's next pick (or stop)."""
        other = self._plan.pop(0) if self._plan else STOP
        obs, rewards, terms, truncs, infos = self.parallel.step(
            {self.agent: action, self.other: other}
        )
        term, trunc = bool(terms[self.agent]), bool(truncs[self.agent])
        if self.parallel.committed and self._first_round:
            self._first_round = False
            self.first_subsets.append(int(self.parallel.models[self.agent].last))
        if self.parallel.committed and not (term or trunc):
            self._plan_round()
        own = obs[self.agent]
        return (
            own["observation"],
            float(rewards[self.agent]),
            term,
            trunc,
            {**infos[self.agent], "action_mask": own["action_mask"]},
        )

    def action_masks(self) -> np.ndarray:
        """Legal actions now (bool, sb3-contrib's MaskablePPO convention)."""
        return self.parallel.action_masks(self.agent).astype(bool)

    def subset_player(self, policy: Any) -> SubsetPlayer:
        """``policy`` of the subset format (e.g. an equilibrium mix) as a player of this view."""
        return SubsetPlayer(policy, self)

    def is_subset_policy(self, policy: Any) -> bool:
        """Whether ``policy`` is a subset-format mix (``probs`` over the learner's subsets)."""
        probs = getattr(policy, "probs", None)
        return probs is not None and np.size(probs) == len(self.parallel.models[self.agent].subsets)

    def subset_strategy(
        self,
        policy: Any,
        seed: int = 0,
        deterministic: bool = True,
        played: list[Any] | None = None,
    ) -> np.ndarray:
        """The learner's one-shot strategy over the subset format's subsets.

        A subset-format mix: its ``probs``. A trained SB3 model played deterministically: the
        subset it builds in one round from ``reset(seed=seed)`` (it sees nothing that changes
        within a round but its own picks, so that subset is its pure strategy; the mask is
        passed as ``action_masks`` where ``predict`` takes it). Otherwise the frequencies of the
        subsets built in the first rounds of the last ``len(played)`` episodes of this view.

        Raises:
            ValueError: When none of these applies, or a deterministic model does not end the
                round within ``2 * (M + 1)`` decisions (an illegal stop repeated by an unmasked
                policy).
        """
        n = len(self.parallel.models[self.agent].subsets)
        if self.is_subset_policy(policy):
            return np.asarray(policy.probs, dtype=np.float64)
        if deterministic and hasattr(policy, "policy") and hasattr(policy, "learn"):
            import inspect

            masked = "action_masks" in inspect.signature(policy.predict).parameters
            obs, _ = self.reset(seed=seed)
            for _ in range(2 * (self.parallel.M + 1)):
                extra = {"action_masks": self.action_masks()} if masked else {}
                action, _ = policy.predict(obs, deterministic=True, **extra)
                obs, *_ = self.step(int(np.asarray(action).reshape(-1)[0]))
                if self.parallel.committed:
                    return np.eye(n)[int(self.parallel.models[self.agent].last)]
            raise ValueError(
                f"the policy did not end the round within {2 * (self.parallel.M + 1)} "
                "decisions (an illegal action repeated: train with the mask, e.g. MaskablePPO)"
            )
        if played and len(self.first_subsets) >= len(played):
            last = list(self.first_subsets)[-len(played) :]
            return np.bincount(last, minlength=n) / len(played)
        raise ValueError(
            "the strategy of this policy over the subsets needs played episodes of this view "
            "(or a subset-format mix with probs, or an SB3 model played deterministically)"
        )

    def render(self) -> str | np.ndarray | None:
        """Delegate to the sequential game."""
        return self.parallel.render()


class SubsetPlayer:
    """A subset-format policy playing the learner's side of a :class:`SequentialGameView`.

    At a round's first decision it asks ``policy`` for a subset index with the subset-format
    observation, then sends that subset's picks one per decision, then stop. ``probs`` (the
    mix, where ``policy`` has one) and ``reset`` are passed through.

    Args:
        policy: A policy with SB3's ``predict`` over the subset format's ``Discrete`` actions.
        view: The view whose learner it plays.
    """

    def __init__(self, policy: Any, view: SequentialGameView) -> None:
        self.policy = policy
        self.view = view
        self.probs = getattr(policy, "probs", None)
        self._plan: list[int] = []
        self._round = -1

    def reset(self, seed: int | None = None) -> None:
        """Reset the wrapped policy's draws (where it has any)."""
        if hasattr(self.policy, "reset"):
            self.policy.reset(seed=seed)

    def predict(
        self, observation: Any, state: Any = None, episode_start: Any = None, **kwargs: Any
    ) -> tuple[int, Any]:
        """The next pick of the subset drawn at the round's start, or stop."""
        parallel, agent = self.view.parallel, self.view.agent
        if parallel.rounds_started != self._round:  # a new round: draw its subset
            self._round = parallel.rounds_started
            a, _ = self.policy.predict(parallel.inner_observation(agent), deterministic=True)
            subset = parallel.models[agent].subsets[int(a)]
            self._plan = subset_actions(parallel, agent, subset)
        return (self._plan.pop(0) if self._plan else STOP), state
