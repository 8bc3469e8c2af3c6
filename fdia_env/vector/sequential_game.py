"""The sensor game's sequential, masked action format in the native vector env.

``gymnasium.make_vec("fdia_env/SensorGameAttacker-v0", num_envs=B,
vectorization_mode="vector_entry_point", action="sequential")`` (or ``...Defender-v0``) returns
:class:`SequentialGameVectorEnv`: B members of the single env's Gymnasium view of the sequential
sensor game (:class:`fdia_env.envs.sequential.SequentialGameView`: the learner builds its subset
one sensor per decision, the fixed opponent plays a subset-format policy asked once per round)
stepped as one array computation, on numpy or on torch (``backend="torch", device=...``).

Each member decides on its own: a round of the wrapped game is played at the decision where both
players of that member have stopped; the other members keep their filter and infos unchanged.
The opponent's subset of a round is drawn when the round starts (the default, the uniform mix
over its subsets, draws from one generator per member seeded ``seed + i + 1`` on numpy, as the
single view seeds its opponent); it then takes one decision per pick and a stop, as in the
single view.

Member ``i`` follows the single view seeded ``seed + i`` exactly on numpy (observations,
rewards, terminations, truncations, infos and masks); on torch, expected dynamics match to
rounding with a deterministic opponent (the mix draws from the device generator: equal in
distribution). The (B, M + 1) masks are in ``infos["action_mask"]`` and
:meth:`SequentialGameVectorEnv.action_masks`. Autoreset and ``max_episode_steps`` (counted in
decisions) follow :mod:`fdia_env.vector.env`.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode

from fdia_env._validation import check_agent
from fdia_env.envs.opponents import FixedMix
from fdia_env.envs.parallel import attacker_reward
from fdia_env.envs.sequential import STOP, SequentialSubsetEnv, subset_actions
from fdia_env.envs.single_agent import Policy
from fdia_env.vector import env as vector_env
from fdia_env.vector.sequential import PartialStep

MODULE = "fdia_env.sensor_game_v0"
MAX_SENSORS = 62
"""The most sensors a member's set can have (it is coded as one int64 bitmask)."""


class SequentialGameVectorEnv(PartialStep, gym.vector.VectorEnv):
    """B members of the sensor game's sequential format for one player, the other fixed.

    Args:
        parallel: The sequential sensor game (``sensor_game_v0.parallel_env(
            action="sequential")``); its spaces, picks and ``illegal_action`` are used.
        num_envs: B.
        agent: The learning player, ``"attacker"`` (default) or ``"defender"``.
        opponent: The other player's subset-format policy (``Discrete`` subset index, e.g. a
            :class:`~fdia_env.envs.opponents.FixedMix`); None: the uniform mix.
        autoreset_mode: ``AutoresetMode.NEXT_STEP`` (default) or ``SAME_STEP``.
        max_episode_steps: Truncate each member's episode after this many decisions, or None.
        backend: ``"numpy"`` (default) or ``"torch"``.
        device: torch only: ``"cpu"`` (default) or ``"cuda"``.

    Raises:
        TypeError: If ``parallel`` is not a :class:`SequentialSubsetEnv`.
        ValueError: For a bad ``num_envs``, ``agent``, ``opponent``, ``autoreset_mode``,
            ``max_episode_steps``, ``backend`` or ``device``, or more than 62 sensors.
    """

    def __init__(
        self,
        parallel: SequentialSubsetEnv,
        num_envs: int,
        agent: str = "attacker",
        opponent: Policy | None = None,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        max_episode_steps: int | None = None,
        backend: str = "numpy",
        device: Any = None,
    ) -> None:
        if not isinstance(parallel, SequentialSubsetEnv):
            raise TypeError(
                "parallel must be a SequentialSubsetEnv (sensor_game_v0.parallel_env("
                f"action='sequential')), got {type(parallel).__name__}"
            )
        check_agent(agent, parallel.possible_agents)
        if parallel.M > MAX_SENSORS:
            raise ValueError(
                f"the sensor game's sequential format has a native vector env up to "
                f"{MAX_SENSORS} sensors, got M = {parallel.M}; use gymnasium.make_vec(..., "
                "vectorization_mode='sync')"
            )
        other = next(p for p in parallel.possible_agents if p != agent)
        if opponent is None:
            opponent = FixedMix.uniform(len(parallel.models[other].subsets))
        # the engine of the wrapped subset-format game (its opponent draws a subset per round);
        # its own autoreset is never used
        self.inner = vector_env.FdiaVectorEnv(
            parallel.inner, num_envs, agent=agent, opponent=opponent, backend=backend, device=device
        )
        self._adopt(parallel, agent, autoreset_mode, max_episode_steps, backend)
        xp, M = self.xp, self.M
        self.other = other
        self.opponent = self.inner.opponent
        self.max_picks = int(parallel.max_picks[agent])
        self.min_picks = int(parallel.min_picks[agent])
        self.drops = parallel.drops[agent]
        self._arange = xp.asarray(np.arange(1, M + 1, dtype=np.int64))
        self._bits = xp.asarray(np.left_shift(1, np.arange(M, dtype=np.int64)))
        # the learner's subsets by bitmask: sorted codes and their subset indices
        codes = np.array([sum(1 << s for s in sub) for sub in parallel.models[agent].subsets])
        order = np.argsort(codes, kind="stable")
        self._codes = xp.asarray(codes[order].astype(np.int64))
        self._code_index = xp.asarray(order.astype(np.int64))
        # the decision (0-based, in a round) after which the opponent has stopped, per subset:
        # one decision per pick, then stop (its last pick stops it when it uses its picks and
        # skip_forced is on; -1: stopped before the first decision)
        most = parallel.max_picks[other]
        last = []
        for sub in parallel.models[other].subsets:
            c = len(subset_actions(parallel, other, sub))
            if self.skip_forced and most == 0:
                last.append(-1)
            else:
                last.append(c - 1 if self.skip_forced and c >= most else c)
        self._opp_last = xp.asarray(np.array(last, dtype=np.int64))
        self._start_stopped = self.skip_forced and self.max_picks == 0
        self._reset_state()

    def _reset_state(self) -> None:
        xp, B = self.xp, self.num_envs
        self._chosen = xp.zeros((B, self.M), dtype=xp.bool)
        self._stopped = xp.full(B, self._start_stopped, dtype=xp.bool)
        self._opp = xp.zeros(B, dtype=xp.int64)  # the opponent's subset index of the round
        self._t = xp.zeros(B, dtype=xp.int64)  # decisions taken in the round
        self._decisions = xp.zeros(B, dtype=xp.int64)
        self._prev_done = xp.zeros(B, dtype=xp.bool)

    # --- reset ---------------------------------------------------------------------------------
    def _reset_decisions(self) -> None:
        """Every member's decision state at a reset and the opponent's subsets of its round."""
        self._reset_state()
        self._new_rounds(self.inner._all)

    def _reset_members(self, where: Any) -> None:
        self.inner._reset_members(where)
        self._chosen = self._chosen & ~where[:, None]
        self._stopped = self.xp.where(where, self._start_stopped, self._stopped)
        self._t = self.xp.where(where, 0, self._t)
        self._decisions = self.xp.where(where, 0, self._decisions)
        self._new_rounds(where)

    def _new_rounds(self, where: Any) -> None:
        """The opponent's subsets of the rounds the members ``where`` start."""
        drawn = self.inner._opponent_actions(where)
        self._opp = self.xp.where(where, self.xp.astype(drawn, self.xp.int64), self._opp)

    # --- masks ---------------------------------------------------------------------------------
    def action_masks(self) -> Any:
        """(B, M + 1) bool: legal actions now (see :class:`SequentialSubsetEnv`)."""
        xp = self.xp
        n = xp.sum(xp.astype(self._chosen, xp.int64), 1)
        mask = xp.empty((self.num_envs, self.M + 1), dtype=xp.bool)
        mask[:, STOP] = self._stopped | (n >= self.min_picks)
        mask[:, 1:] = ~self._chosen & ((n < self.max_picks) & ~self._stopped)[:, None]
        return mask

    # --- step ----------------------------------------------------------------------------------
    def step(self, actions: Any):
        """One decision of every member (NEXT_STEP: members that ended last step restart).

        Raises:
            RuntimeError: Before :meth:`reset`.
            ValueError: For actions that are not one integer in [0, M] per member, or (with
                ``illegal_action="error"``) an action outside a member's mask.
        """
        actions, live = self._begin(actions, self.agent)
        xp, B = self.xp, self.num_envs
        mask = self.action_masks()
        legal = xp.sum(xp.astype(mask & (self._arange_all() == actions[:, None]), xp.int64), 1)
        legal = (legal > 0) | ~live
        if not xp.all(legal):
            if self.illegal_action == "error":
                self._raise_illegal(actions, legal)
        pick = live & (actions > 0)
        # "trim" / "noop": an illegal pick of a player still picking stops it; an illegal stop
        # or a waiting player's pick is ignored
        stop = live & ((~pick & legal) | (pick & ~legal & ~self._stopped))
        pick = pick & legal
        onehot = (actions[:, None] == self._arange) & pick[:, None]
        self._chosen = self._chosen | onehot
        stopped = self._stopped | stop
        if self.skip_forced:
            n = xp.sum(xp.astype(self._chosen, xp.int64), 1)
            stopped = stopped | (pick & (n >= self.max_picks))
        self._stopped = stopped
        opp_stopped = self._t >= self._opp_last[self._opp]
        self._t = self._t + xp.astype(live, xp.int64)
        commit = live & stopped & opp_stopped
        reward = xp.zeros(B)
        done = xp.zeros(B, dtype=xp.bool)
        if xp.any(commit):
            reward, done = self._play_rounds(commit)
        self._decisions = self._decisions + xp.astype(live, xp.int64)
        truncated = xp.zeros(B, dtype=xp.bool)
        if self.parallel.max_cycles is not None:  # PettingZoo's limit, counted in decisions
            truncated = truncated | (live & ~done & (self._decisions >= self.parallel.max_cycles))
        if xp.any(commit):  # a new round starts; the opponent draws where the episode goes on
            self._chosen = self._chosen & ~commit[:, None]
            self._stopped = xp.where(commit, self._start_stopped, self._stopped)
            self._t = xp.where(commit, 0, self._t)
            going_on = commit & ~(done | truncated)
            if xp.any(going_on):
                self._new_rounds(going_on)
        if self.max_episode_steps is not None:  # Gymnasium's TimeLimit, counted in decisions
            truncated = truncated | (live & (self._decisions >= self.max_episode_steps))
        return self._finish(reward, done, truncated)

    def _arange_all(self) -> Any:
        """(1, M + 1): the actions 0..M."""
        xp = self.xp
        return xp.asarray(np.arange(self.M + 1, dtype=np.int64))[None, :]

    def _raise_illegal(self, actions: Any, legal: Any) -> None:
        i = int(self.xp.to_numpy(self.xp.flatnonzero(~legal))[0])
        j = int(actions[i])
        chosen = self.xp.to_numpy(self._chosen[i])
        if bool(self._stopped[i]):
            why = (
                f"{self.agent} has stopped this round and waits: its only legal action is stop (0)"
            )
        elif j == STOP:
            why = "the attacker's set is empty (it attacks at least one sensor)"
        elif chosen[j - 1]:
            why = f"sensor {j} is already picked this round"
        else:
            why = f"{self.agent} has used its {self.max_picks} picks of the round"
        allowed = np.flatnonzero(self.xp.to_numpy(self.action_masks()[i])).tolist()
        raise ValueError(
            f"{self.agent} action {j} of member {i} is illegal: {why}; legal actions "
            f"(action_mask = 1): {allowed}"
        )

    def _play_rounds(self, commit: Any) -> tuple[Any, Any]:
        """The round of the members ``commit`` with both players' subsets; the others hold.

        Returns:
            (B,) the learner's rewards and the terminations (zero / False for the held members).
        """
        xp = self.xp
        with self._holding(commit) as sim:
            played = self._chosen if not self.drops else ~self._chosen
            code = xp.sum(xp.astype(played, xp.int64) * self._bits[None, :], 1)
            own = self._code_index[xp.searchsorted(self._codes, code) - 1]
            own = xp.where(commit, own, 0)
            subsets = {self.agent: own, self.other: xp.where(commit, self._opp, 0)}
            attacked, sigma = self.attack.batch_apply(subsets["attacker"])
            used, leak, present, steady = self.defense.batch_apply(
                subsets["defender"], attacked, sigma
            )
            self.attack.batch_observe_opponent(self.defense)
            self.defense.batch_observe_opponent(self.attack)
            phi_prev = sim.phi
            phi = sim.step(
                used,
                leak,
                present,
                steady,
                active=commit,
                detection=self.defense.batch_detection(),
                probability=self.attack.batch_probability(),
            )
        done = commit & (sim.k >= self.spec_episode.horizon)
        reward = attacker_reward(self.spec_episode.reward_mode, phi, phi_prev, done, xp)
        if self.agent == "defender":
            reward = -reward
        return xp.where(commit, reward, 0.0), done

    # --- observations --------------------------------------------------------------------------
    def _observe(self) -> Any:
        """(B, d + M) float32: the learner's features in the wrapped game, its picks."""
        xp = self.xp
        box = self.inner._observe(self.agent)
        d = box.shape[1]
        out = xp.empty((self.num_envs, d + self.M), dtype=xp.float32)
        out[:, :d] = box
        out[:, d:] = xp.astype(self._chosen, xp.float32)
        return out


# fdia_env.vector.env.make_vector (make_vec's entry point) builds the class for the format
vector_env.FORMAT_VECTOR_ENVS[(MODULE, "sequential")] = SequentialGameVectorEnv
