"""The sparse attacker's sequential, masked action format in the native vector env.

``gymnasium.make_vec("fdia_env/SparseAttack-v0", num_envs=B,
vectorization_mode="vector_entry_point", action="sequential")`` returns
:class:`SequentialVectorEnv`: B members of the single env's sequential format
(:class:`fdia_env.envs.sequential.SequentialSetEnv`, its Gymnasium view) stepped as one array
computation, on numpy or on torch (``backend="torch", device=...``).

Each member decides on its own: at a decision it adds a sensor to the set of its current window
step (action ``j`` in 1..M) or stops (action 0), which takes that member's window step. Members
therefore finish a set, and an episode, at different decisions: a window step is computed for
the members that commit at this decision only; the others keep their filter, budget and infos
unchanged. With ``skip_forced=True`` (default, as the single env) a member whose only legal
action is stop has it played by the env in the same decision (its rewards summed), so a member's
episode takes at most ``N + c`` decisions.

Member ``i`` follows the single env's Gymnasium view seeded ``seed + i`` exactly on numpy
(observations, rewards, terminations, truncations, infos and masks, expected and sampled
dynamics: each member draws from its own generator in the single env's order); on torch,
expected dynamics match to rounding and sampled dynamics in distribution (one device generator).

Observations are the view's ``Box`` (the wrapped env's features, the M entries of the set being
built, the budget left after it as a fraction of ``budget``); the (B, M + 1) masks are in
``infos["action_mask"]`` and :meth:`SequentialVectorEnv.action_masks` (1 = legal: stop always,
sensor j while it is not in the set and the set is smaller than the budget left). The single
env's ``order="plan"`` is served too: (B, N·M + 1) masks over the (sensor, window step) pairs,
and each member plays its plan out once it stops (see :mod:`fdia_env.envs.sequential`), and its
``order="increasing"`` (``"plan"`` with each member's picks in increasing order: its mask also
closes the pairs at or below its last pick), each with the state groups (``groups="state"``:
(B, N·M + 1 + N·n) masks, a group adds its pairs not yet in the member's plan). Autoreset
and ``max_episode_steps`` (counted in decisions, as Gymnasium's ``TimeLimit`` over the view)
follow :mod:`fdia_env.vector.env`.

Cost: the engine steps the whole batch, so the members that do not take a window step are held
(their state saved, then put back) once per run of window steps by the same members, e.g. once
for a plan's N window steps, not once per window step; the budget left, the forced stops and the
masks are computed once per change of the decision state (``infos["action_mask"]`` and
:meth:`SequentialVectorEnv.action_masks` after a step share one computation). Neither changes a
value; ``benchmarks/seq_throughput.py`` measures the training rate (docs/benchmarks.md).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from fdia_env.actions import check_vector_actions
from fdia_env.backend import NUMPY
from fdia_env.envs.parallel import attacker_reward
from fdia_env.envs.sequential import STOP, SequentialSetEnv, group_illegal
from fdia_env.vector import env as vector_env

SEQUENTIAL_MODULES = (
    "fdia_env.sparse_attack_v0",
    "fdia_env.sparse_attack_v1",
    "fdia_env.sparse_attack_v2",
)
"""The modules whose ``action="sequential"`` has a native vector env (v1 and v2: also their
default ``"auto"``, which is the sequential format above 16 sensors)."""

# the engine's per-member state, held for the members that do not commit at a decision
_SIM_STATE = ("_comp", "_P", "_M", "consistent", "k", "nis", "phi", "x", "x_hat")


class PartialStep:
    """Hold some members of a batch through an engine step: save their state, put it back.

    For a native vector env whose members take their window steps at different decisions (the
    engine and the models step the whole batch): an engine step in a ``with`` :meth:`_holding`
    block leaves the members it does not step as they were. :meth:`_adopt` sets what such an
    env takes from its engine (``self.inner``) and single env, :meth:`_begin` opens its step
    (the checked actions, the next-step autoreset) and :meth:`_finish` ends it (the same-step
    autoreset); :meth:`reset` resets the engine and the seeding, then the format's own decision
    state (:meth:`_reset_decisions`).
    """

    xp: Any
    num_envs: int
    attack: Any
    defense: Any
    inner: Any

    def reset(self, *, seed: int | list[int] | None = None, options: dict | None = None):
        """Reset every member (an int ``seed`` seeds member i with ``seed + i``, as the engine)."""
        self.inner.reset(seed=seed, options=options)
        if seed is not None and not isinstance(seed, list | tuple):
            super().reset(seed=int(seed))  # the next class in the env's MRO: VectorEnv
        self._reset_decisions()
        self._started = True
        return self._observe(), self._infos()

    def _reset_decisions(self) -> None:
        """Every member's decision state at a reset (each format's own)."""
        raise NotImplementedError

    def _infos(self) -> dict[str, Any]:
        """The engine's infos with the members' action masks (``action_mask``, int8)."""
        infos = self.inner._infos()
        infos["action_mask"] = self.xp.astype(self.action_masks(), self.xp.int8)
        infos["_action_mask"] = self.inner._all
        return infos

    def _save(self, sim: Any) -> dict[str, Any]:
        """Copies of the engine's and the models' per-member state (before a partial step)."""
        xp = self.xp
        if getattr(sim, "_lr_on", False):  # the low-rank form is shared by the batch: off
            sim._lr_on = False
        state = {name: getattr(sim, name, None) for name in _SIM_STATE}
        if state["_M"] is None:  # M is P while no bias leaked
            state["_M"] = sim.P
        saved = {name: None if v is None else xp.copy(v) for name, v in state.items()}
        saved["_clean"] = sim._clean
        for who, model in (("attack", self.attack), ("defense", self.defense)):
            for name, value in vars(model).items():
                if name.startswith("b_") and _batched(value, self.num_envs):
                    saved[f"{who}.{name}"] = xp.copy(value)
        return saved

    @contextmanager
    def _holding(self, stepping: Any) -> Iterator[Any]:
        """Step the batch inside the block; the members not ``stepping`` keep their state.

        Yields the engine. On leaving, the held members get back what they had on entering:
        the engine's and the models' state (:meth:`_save`, :meth:`_restore`) and the engine's
        detection info.
        """
        sim = self.inner.sim
        saved = self._hold(stepping)
        yield sim
        self._merge_detection(stepping)
        if saved is not None:
            self._restore(sim, saved, ~stepping)

    def _hold(self, stepping: Any) -> dict[str, Any] | None:
        """The saved state of the members not ``stepping`` (:meth:`_save`), None if none is held."""
        return self._save(self.inner.sim) if not bool(self.xp.all(stepping)) else None

    def _merge_detection(self, stepping: Any) -> None:
        """The engine's detection info of the members ``stepping``; the others keep theirs."""
        inner = self.inner
        if inner._det_defaults:
            held = ~stepping
            for key, values in inner.sim.detection_info.items():
                inner._det_info[key] = self.xp.where(held, inner._det_info[key], values)

    def _restore(self, sim: Any, saved: dict[str, Any], held: Any) -> None:
        """Put the held members' state back (the stepping members keep the new one)."""
        xp = self.xp
        for name in _SIM_STATE:
            old, new = saved[name], getattr(sim, name, None)
            if old is None or new is None:
                continue
            if name == "_comp":  # (3, B) components
                setattr(sim, name, xp.where(held[None, :], old, new))
            else:
                setattr(sim, name, xp.where(_expand(held, new.ndim), old, new))
        sim._clean = bool(saved["_clean"] and sim._clean)
        for key, old in saved.items():
            if "." in key:
                who, name = key.split(".", 1)
                model = self.attack if who == "attack" else self.defense
                new = getattr(model, name)
                setattr(model, name, xp.where(_expand(held, new.ndim), old, new))

    def _adopt(
        self,
        parallel: Any,
        agent: str,
        autoreset_mode: AutoresetMode | str,
        max_episode_steps: int | None,
        backend: str,
    ) -> None:
        """What a sequential vector env takes from its engine (``self.inner``) and single env.

        The backend, batch, models, episode options and metadata, ``agent``'s batched spaces,
        and the per-member decision counters.

        Raises:
            ValueError: For a bad ``autoreset_mode`` or ``max_episode_steps``.
        """
        inner = self.inner
        self.xp = xp = inner.xp
        self.num_envs = B = inner.num_envs
        mode, self.max_episode_steps = vector_env.check_episode_options(
            autoreset_mode, max_episode_steps
        )
        self.metadata = {"autoreset_mode": mode, "render_modes": [], "backend": backend}
        self.render_mode = None
        self.parallel, self.agent = parallel, agent
        self.illegal_action = parallel.illegal_action
        self.skip_forced = parallel.skip_forced
        self.backend, self.device = inner.backend, inner.device
        self.attack, self.defense = inner.attack, inner.defense
        self.spec_episode = parallel.spec
        self.M = parallel.M
        self.single_observation_space = parallel.observation_space(agent)["observation"]
        self.single_action_space = parallel.action_space(agent)
        self.observation_space = batch_space(self.single_observation_space, B)
        self.action_space = batch_space(self.single_action_space, B)
        self._decisions = xp.zeros(B, dtype=xp.int64)
        self._prev_done = xp.zeros(B, dtype=xp.bool)
        self._started = False

    @property
    def autoreset_mode(self) -> AutoresetMode:
        """Gymnasium's autoreset mode of this env (also in ``metadata["autoreset_mode"]``)."""
        return self.metadata["autoreset_mode"]

    def _begin(self, actions: Any, agent: str) -> tuple[Any, Any]:
        """A step's checked actions (int64) and the (B,) members that play this decision.

        The members that ended at the last step (NEXT_STEP) restart here; their actions are
        ignored. Needs the env's ``_started``, ``_prev_done``, ``single_action_space`` and
        ``_reset_members``.

        Raises:
            RuntimeError: Before the env's ``reset()``.
            ValueError: For actions that are not one valid action of ``agent`` per member.
        """
        if not self._started:
            raise RuntimeError("step() called before reset(): call reset() first")
        xp, B = self.xp, self.num_envs
        actions = check_vector_actions(self.single_action_space, actions, B, agent, xp)
        actions = xp.astype(actions, xp.int64)
        resetting = self._prev_done
        if xp.any(resetting):  # NEXT_STEP: their action is ignored; they start a new episode
            self._reset_members(resetting)
        return actions, ~resetting

    def _finish(self, reward: Any, done: Any, truncated: Any) -> tuple[Any, ...]:
        """The step's return: observations and infos after the ended members' autoreset.

        NEXT_STEP marks them to restart at the next step; SAME_STEP restarts them now, with
        their last observation and infos under ``final_obs`` / ``final_info``. Needs the env's
        ``autoreset_mode``, ``_observe``, ``_infos`` and ``_reset_members``.
        """
        xp, B = self.xp, self.num_envs
        infos: dict[str, Any] = {}
        ended = done | truncated
        if self.autoreset_mode == AutoresetMode.NEXT_STEP:
            self._prev_done = ended
            obs = self._observe()
        else:
            obs = self._observe()
            if xp.any(ended):
                if xp is NUMPY:
                    final = np.full(B, None, dtype=object)
                    for i in np.flatnonzero(ended):
                        final[i] = obs[i].copy()
                else:
                    final = xp.where(ended[:, None], obs, 0.0)
                infos = {
                    "final_obs": final,
                    "_final_obs": xp.copy(ended),
                    "final_info": vector_env._masked(self._infos(), ended, xp),
                    "_final_info": xp.copy(ended),
                }
                self._reset_members(xp.copy(ended))
                obs = self._observe()
        infos.update(self._infos())
        return obs, reward, done, truncated, infos


class SequentialVectorEnv(PartialStep, gym.vector.VectorEnv):
    """B members of the sparse attacker's sequential format, as batched numpy or torch.

    Args:
        parallel: The single env's sequential format (``sparse_attack_v0.parallel_env(
            action="sequential")``); its spaces, budget and ``illegal_action`` are used.
        num_envs: B.
        autoreset_mode: ``AutoresetMode.NEXT_STEP`` (default) or ``SAME_STEP``.
        max_episode_steps: Truncate each member's episode after this many decisions, or None.
        backend: ``"numpy"`` (default) or ``"torch"``.
        device: torch only: ``"cpu"`` (default) or ``"cuda"``.

    Raises:
        TypeError: If ``parallel`` is not a :class:`SequentialSetEnv`.
        ValueError: For a bad ``num_envs``, ``autoreset_mode``, ``max_episode_steps``,
            ``backend`` or ``device``.
    """

    def __init__(
        self,
        parallel: SequentialSetEnv,
        num_envs: int,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        max_episode_steps: int | None = None,
        backend: str = "numpy",
        device: Any = None,
    ) -> None:
        if not isinstance(parallel, SequentialSetEnv):
            raise TypeError(
                "parallel must be a SequentialSetEnv (sparse_attack_v0.parallel_env("
                f"action='sequential')), got {type(parallel).__name__}"
            )
        # the engine of the wrapped "multibinary" env; its own autoreset is never used
        self.inner = vector_env.FdiaVectorEnv(
            parallel.inner, num_envs, backend=backend, device=device
        )
        self._adopt(parallel, "attacker", autoreset_mode, max_episode_steps, backend)
        xp, B, M = self.xp, self.num_envs, self.M
        self.budget = int(self.attack.budget)
        self.order, self.plan_first = parallel.order, parallel.plan_first
        self.increasing = parallel.increasing
        self.horizon = N = parallel.horizon
        self._slots = S = N * M if self.plan_first else M  # the pick actions 1..S
        self._arange = xp.asarray(np.arange(1, S + 1, dtype=np.int64))
        self._slot_steps = xp.asarray(np.repeat(np.arange(N, dtype=np.int64), M))  # "plan"
        self._rows = xp.asarray(np.arange(B, dtype=np.int64))
        self._chosen = xp.zeros((B, S), dtype=xp.bool)  # "plan": (B, N·M), step-major
        self._playing = xp.zeros(B, dtype=xp.bool)  # "plan": the plan is committed
        self._last = xp.zeros(B, dtype=xp.int64)  # "increasing": each member's last pick
        # groups: (G, S) the pairs of each group action S + 1 + g; each member's last group
        # picked (0: none)
        self._groups = xp.asarray(parallel._groups.astype(bool))
        self._n_groups = G = int(parallel._groups.shape[0])
        self._group_sizes = xp.asarray(parallel._group_sizes.astype(np.float64))
        self._groups_f = xp.asarray(parallel._groups.T.astype(np.float64))  # (S, G)
        self._group_ids = xp.asarray(np.arange(S + 1, S + 1 + G, dtype=np.int64))
        self._last_group = xp.zeros(B, dtype=xp.int64)
        # what the decision state gives (budget left, forced stops, masks), computed once per
        # change of it (see _changed)
        self._cache: dict[str, Any] = {}

    # --- reset ---------------------------------------------------------------------------------
    def _reset_decisions(self) -> None:
        """Every member's decision state at a reset: nothing chosen, nothing playing."""
        xp, B = self.xp, self.num_envs
        self._chosen = xp.zeros((B, self._slots), dtype=xp.bool)
        self._playing = xp.zeros(B, dtype=xp.bool)
        self._last = xp.zeros(B, dtype=xp.int64)
        self._last_group = xp.zeros(B, dtype=xp.int64)
        self._decisions = xp.zeros(B, dtype=xp.int64)
        self._prev_done = xp.zeros(B, dtype=xp.bool)
        self._changed()

    def _reset_members(self, where: Any) -> None:
        self.inner._reset_members(where)
        self._chosen = self._chosen & ~where[:, None]
        self._playing = self._playing & ~where
        self._last = self.xp.where(where, 0, self._last)
        if self._n_groups:
            self._last_group = self.xp.where(where, 0, self._last_group)
        self._decisions = self.xp.where(where, 0, self._decisions)
        self._changed()

    def _changed(self) -> None:
        """Forget what was computed from the decision state (after a change of it).

        :meth:`_left`, :meth:`_forced` and :meth:`action_masks` read ``_chosen``,
        ``_playing``, ``_last``, the engine's window steps and the attack's budget left; every
        method that changes one of them calls this.
        """
        self._cache.clear()

    # --- masks ---------------------------------------------------------------------------------
    def _left(self) -> Any:
        """(B,) budget left after each member's set (``"plan"``: its steps not yet played)."""
        left = self._cache.get("left")
        if left is None:
            left = self._cache["left"] = self._compute_left()
        return left

    def _compute_left(self) -> Any:
        xp = self.xp
        pending = self._chosen
        if self.plan_first:  # the pairs of the steps not yet played
            pending = pending & (self._slot_steps[None, :] >= self.inner.sim.k[:, None])
        return self.attack.b_remaining - xp.sum(xp.astype(pending, xp.int64), 1)

    def action_masks(self) -> Any:
        """(B, A) bool: legal actions now (stop always; a new sensor or pair within the budget)."""
        mask = self._cache.get("mask")
        if mask is None:
            mask = self._cache["mask"] = self._compute_masks()
        return self.xp.copy(mask)  # the caller's own array

    def _compute_masks(self) -> Any:
        xp = self.xp
        S = self._slots
        mask = xp.empty((self.num_envs, S + 1 + self._n_groups), dtype=xp.bool)
        mask[:, STOP] = True
        open_ = (self._left() > 0) & ~self._playing
        mask[:, 1 : S + 1] = ~self._chosen & open_[:, None]
        if self.increasing:  # the pairs at or below each member's last pick are closed
            mask[:, 1 : S + 1] = mask[:, 1 : S + 1] & (self._arange[None, :] > self._last[:, None])
        if self._n_groups:
            mask[:, S + 1 :] = self._group_masks(open_)
        return mask

    def _group_masks(self, open_: Any) -> Any:
        """(B, G) groups legal now: above the member's last group, adding 1..left new pairs."""
        xp = self.xp
        new = self._group_sizes[None, :] - xp.astype(self._chosen, xp.float64) @ self._groups_f
        left = xp.astype(self._left(), xp.float64)[:, None]
        fits = (new > 0) & (new <= left)
        above = self._group_ids[None, :] > self._last_group[:, None]
        return fits & above & open_[:, None]

    def _forced(self) -> Any:
        """(B,) members whose only legal action is stop."""
        forced = self._cache.get("forced")
        if forced is None:
            if self._n_groups:  # every action but stop is closed
                forced = self._playing | ~_any1(self.xp, self.action_masks()[:, 1:])
            else:
                forced = self._playing | (self._left() <= 0) | ~_any1(self.xp, ~self._chosen)
                if self.increasing:  # no pair above the last pick
                    forced = forced | (self._last >= self._slots)
            self._cache["forced"] = forced
        return forced

    def _current_sets(self) -> Any:
        """(B, M) bool: each member's set of its next window step."""
        if not self.plan_first:
            return self._chosen
        N, k = self.horizon, self.inner.sim.k
        plan = self._chosen.reshape(self.num_envs, N, self.M)
        rows = plan[self._rows, self.xp.minimum(k, N - 1)]  # (B, M): the step to play
        return rows & (k < N)[:, None]  # nothing once the window is over

    # --- step ----------------------------------------------------------------------------------
    def step(self, actions: Any):
        """One decision of every member (NEXT_STEP: members that ended last step restart).

        Raises:
            RuntimeError: Before :meth:`reset`.
            ValueError: For actions that are not one integer in [0, M] per member, or (with
                ``illegal_action="error"``) an action outside a member's mask.
        """
        actions, live = self._begin(actions, "attacker")
        xp = self.xp
        grouped = None
        if self._n_groups:  # the group actions, checked against the mask
            grouped = live & (actions > self._slots)
            if xp.any(grouped):
                legal = self.action_masks()[self._rows, actions] | ~grouped
                if not xp.all(legal):
                    if self.illegal_action == "error":
                        self._raise_illegal(actions, legal)
                    grouped = grouped & legal  # "trim" / "noop": an illegal group stops
                index = xp.where(grouped, actions - self._slots - 1, 0)
                added = self._groups[index] & grouped[:, None]
            else:
                grouped = None
        onehot = (actions[:, None] == self._arange) & live[:, None]  # (B, M): the picks
        closed = (self._left() <= 0) | self._playing
        taken = self._chosen | closed[:, None]
        if self.increasing:  # and the pairs at or below the last pick
            taken = taken | (self._arange[None, :] <= self._last[:, None])
        legal = ~_any1(xp, onehot & taken)
        if not xp.all(legal):
            if self.illegal_action == "error":
                self._raise_illegal(actions, legal)
            onehot = onehot & legal[:, None]  # "trim" / "noop": an illegal pick stops
        pick = _any1(xp, onehot)
        self._chosen = self._chosen | onehot
        if self.increasing:
            self._last = xp.where(pick, actions, self._last)
        if grouped is not None:
            self._chosen = self._chosen | added
            self._last_group = xp.where(grouped, actions, self._last_group)
            pick = pick | grouped
        self._changed()
        commit = live & ~pick
        if self.skip_forced:
            commit = commit | (pick & self._forced())
        if self.plan_first:
            self._playing = self._playing | commit
            self._changed()
        reward, done, truncated = self._play(commit)
        self._decisions = self._decisions + xp.astype(live, xp.int64)
        if self.parallel.max_cycles is not None:  # PettingZoo's limit, counted in decisions
            truncated = truncated | (live & ~done & (self._decisions >= self.parallel.max_cycles))
        if self.max_episode_steps is not None:  # Gymnasium's TimeLimit, counted in decisions
            truncated = truncated | (live & (self._decisions >= self.max_episode_steps))
        return self._finish(reward, done, truncated)

    def _raise_illegal(self, actions: Any, legal: Any) -> None:
        i = int(self.xp.to_numpy(self.xp.flatnonzero(~legal))[0])
        j = int(actions[i])
        allowed = np.flatnonzero(self.xp.to_numpy(self.action_masks()[i])).tolist()
        if j > self._slots:
            g = j - self._slots - 1
            new = int(self._group_sizes[g]) - int(self.xp.sum(self._groups[g] & self._chosen[i], 0))
            state = (bool(self._playing[i]), int(self._last_group[i]))
            n = self.parallel.system.n
            what, why = group_illegal(j, self._slots, n, *state, new, int(self._left()[i]))
        elif self.plan_first:
            k, s = divmod(j - 1, self.M)
            what = f"sensor {s + 1} at window step {k + 1}"
            if bool(self._playing[i]):
                why = "the plan is committed and plays out: stop (0) is the only legal action"
            elif bool(self._chosen[i, j - 1]):
                why = "this pair is already in the plan"
            elif self.increasing and j <= int(self._last[i]):
                why = (
                    "order='increasing' picks the pairs in increasing order and the last pick "
                    f"is action {int(self._last[i])}"
                )
            else:
                why = f"the plan already uses the budget ({self.budget})"
        else:
            what = f"add sensor {j}"
            why = (
                f"sensor {j} is already in this step's set"
                if bool(self._chosen[i, j - 1])
                else f"the step's set already uses the budget left ({int(self._left()[i])})"
            )
        raise ValueError(
            f"attacker action {j} ({what}) of member {i} is illegal: {why}; legal "
            f"actions are those with action_mask[a] = 1: {allowed}"
        )

    def _play(self, commit: Any) -> tuple[Any, Any, Any]:
        """The window steps of a decision: the committed sets, then the stops the env plays.

        The members not stepping are held (:meth:`PartialStep._save`,
        :meth:`PartialStep._restore`) around each run of window steps by the same members (a
        plan played out is one run), not around each window step: the engine steps the batch
        with the held members not active (its general update, n > 2, skips them; its other
        paths step them with an empty set: no bias, no change of the batch's flags), so the
        stepping members' values do not depend on them and their state is put back once, at
        the run's end.

        Returns:
            (B,) rewards, terminations and truncations summed over the window steps.
        """
        xp, B, sim = self.xp, self.num_envs, self.inner.sim
        reward = xp.zeros(B)
        done = xp.zeros(B, dtype=xp.bool)
        truncated = xp.zeros(B, dtype=xp.bool)
        stepping, group, saved = commit, None, None
        try:
            while xp.any(stepping):
                if group is None or not xp.all(stepping == group):  # a new run
                    if saved is not None:
                        self._restore(sim, saved, ~group)
                        self._changed()
                    group, saved = stepping, self._hold(stepping)
                r, d, t = self._window_step(stepping)
                reward = reward + r
                done = done | d
                truncated = truncated | t
                if not self.skip_forced:
                    break
                stepping = commit & ~(done | truncated)
                if not self.plan_first:  # "plan": commit is in _playing, so in _forced()
                    stepping = stepping & self._forced()
        finally:
            if saved is not None:
                self._restore(sim, saved, ~group)
            self._changed()
        return reward, done, truncated

    def _window_step(self, stepping: Any) -> tuple[Any, Any, Any]:
        """The window step of the members ``stepping`` with their sets (in a run of :meth:`_play`).

        The held members step as not active (the engine's general update skips them, its other
        paths step them with an empty set); their state is put back at the run's end.

        Returns:
            (B,) rewards, terminations and truncations (zero / False for the held members).
        """
        xp, sim = self.xp, self.inner.sim
        sets = xp.astype(self._current_sets() & stepping[:, None], xp.int8)
        attacked, sigma = self.attack.batch_apply(sets)
        used, leak, present, steady = self.defense.batch_apply(None, attacked, sigma)
        phi_prev = sim.phi
        sim.step(
            used,
            leak,
            present,
            steady,
            active=stepping,
            detection=self.defense.batch_detection(),
            probability=getattr(self.attack, "b_probability", None),
        )
        self._merge_detection(stepping)
        done = stepping & (sim.k >= self.spec_episode.horizon)
        truncated = xp.zeros(self.num_envs, dtype=xp.bool)
        reward = attacker_reward(self.spec_episode.reward_mode, sim.phi, phi_prev, done, xp)
        reward = xp.where(stepping, reward, 0.0)
        if not self.plan_first:  # "time": the next step's set starts empty
            self._chosen = self._chosen & ~stepping[:, None]
        self._changed()
        return reward, done, truncated

    # --- observations --------------------------------------------------------------------------
    def _observe(self) -> Any:
        """(B, d + S + 1) float32: the engine's features, the set (plan), the budget left."""
        xp = self.xp
        box = self.inner._observe("attacker")
        d = box.shape[1]
        out = xp.empty((self.num_envs, d + self._slots + 1), dtype=xp.float32)
        out[:, :d] = box
        out[:, d:-1] = xp.astype(self._chosen, xp.float32)
        out[:, -1] = xp.astype(xp.maximum(self._left(), 0), xp.float64) / self.budget
        return out


def _any1(xp: Any, x: Any) -> Any:
    """(B,) whether each row of the (B, M) boolean ``x`` has a True entry."""
    return xp.sum(xp.astype(x, xp.int64), 1) > 0


def _batched(value: Any, batch: int) -> bool:
    return hasattr(value, "shape") and len(value.shape) >= 1 and value.shape[0] == batch


def _expand(where: Any, ndim: int) -> Any:
    return where.reshape(-1, *[1] * (ndim - 1))


def make_vector(module: str, num_envs: int, **kwargs: Any) -> gym.vector.VectorEnv:
    """The native vector env of ``action="sequential"`` (what ``make_vec`` gives for it).

    :func:`fdia_env.vector.env.make_vector`, the table's ``vector_entry_point``, hands the
    sequential format of a module of :data:`SEQUENTIAL_MODULES` here (this module registers it
    in :data:`fdia_env.vector.env.FORMAT_VECTOR_ENVS`), with the same keywords: the vector
    env's options (those of :class:`SequentialVectorEnv`, plus ``agent`` and ``opponent``,
    which must be ``"attacker"`` and None) and the env's own.

    Raises:
        ValueError: For a module without the format's native vector env, a render mode, an
            agent other than the attacker, an opponent, or a bad option of the env.
    """
    if module not in SEQUENTIAL_MODULES:
        raise ValueError(
            f"action='sequential' has a native vector env for {list(SEQUENTIAL_MODULES)} only, "
            f"got module {module!r}; use gymnasium.make_vec(..., vectorization_mode='sync')"
        )
    from fdia_env.backend import get_backend

    options, env_kwargs = vector_env.split_vector_options(kwargs)
    agent, opponent = options.pop("agent"), options.pop("opponent")
    # an unknown backend or a missing GPU fails first
    get_backend(options["backend"], options["device"])
    if env_kwargs.pop("render_mode", None) is not None:
        raise ValueError("render_mode is not supported by the native vector env; use SyncVectorEnv")
    if not isinstance(agent, str) or agent != "attacker":
        raise ValueError(f"agent must be 'attacker' for {module}, got {agent!r}")
    if opponent is not None:
        raise ValueError(f"opponent must be None: {module} has a single player")
    import importlib

    parallel = importlib.import_module(module).parallel_env(**env_kwargs)
    if not isinstance(parallel, SequentialSetEnv):  # v1's "auto" up to 16 sensors: the bitmask
        fixed = {"scenario": parallel.scenario, "action": parallel.attack.format}
        return vector_env.make_vector(module, num_envs, **{**kwargs, **fixed})
    return SequentialVectorEnv(parallel, num_envs, **options)


for _module in SEQUENTIAL_MODULES:
    vector_env.FORMAT_VECTOR_ENVS[(_module, "sequential")] = make_vector
for _module in SEQUENTIAL_MODULES[1:]:  # v1's and v2's default: sequential above 16 sensors
    for _action in (None, "auto"):
        vector_env.FORMAT_VECTOR_ENVS[(_module, _action)] = make_vector
