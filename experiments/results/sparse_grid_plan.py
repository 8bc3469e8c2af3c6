"""The sparse attack as a plan of sensor-time pairs: the same instance, a learnable action space.

The results table (:mod:`experiments.results.sparse_grid`) now trains in the env's own
sequential format, plan-first order (``action="sequential", order="plan"``). This module is
the format of the published full table (2026-11-23) and stays for comparison: in the quick run
its torch PPO reached 76.5 % of the optimum against 74.1 % in the env's format (MaskablePPO
0.4 % against 15.6 %), and on ieee14-rtu c = 6, N = 6 (seed 0) torch PPO 100 % against 46.4 %,
so the env's format does not yet do at least as well for every learner.

``sparse_attack_v0`` acts once per window step with a subset of sensors: ``Discrete(2**M)``
(16,384 masked actions on a 14-bus RTU grid, where sb3-contrib's MaskablePPO runs at about
50 steps/s here) or, above 16 sensors, ``MultiBinary(M)`` (no mask: neither MaskablePPO nor the
torch PPO takes it). Its ``"single"`` format (``Discrete(M + 1)``) attacks at most one sensor
per step, a different problem: the grids' optima blank several meters at the last step.

Here the attacker writes its plan first: ``c`` (the budget) decisions, each picking one
sensor-time pair (action ``1 + k·M + i`` = sensor ``i`` at window step ``k``, 0-based) or none
(action 0); after the ``c``-th decision the plan is played in the wrapped ``sparse_attack_v0``
(``action="multibinary"``, one row of the plan per step) and the decision's reward is that
episode's return. Every attack set of at most ``c`` pairs is a plan and no plan spends more than
``c``, so the episode return is the wrapped env's for the same attack set: the identical
instance (system, c, N, objective, expected dynamics, steady start, terminal reward). In
expected dynamics the env is deterministic, so an open-loop plan loses nothing. (A
time-ordered variant, one sensor per decision within each step, was tried first: there uniform
exploration spends the budget at the first step and neither learner left that policy.)

Action mask: 0 always; a pair while it is not yet in the plan. Observation: the plan so far
((N·M,) zeros/ones, step-major) and the decisions left / c. Every episode takes exactly ``c``
decisions, so a batch of members stays in step (what :class:`PlanVectorEnv` relies on).

:class:`PlanSparseEnv` is the Gymnasium env (MaskablePPO, :func:`agents.evaluate.evaluate`);
:class:`PlanVectorEnv` the same MDP over the torch vector env for
:func:`agents.torch_ppo.train_torch_ppo`; :class:`PlanPolicy` plays a solver's attack set.
"""

from __future__ import annotations

from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

import fdia_env  # noqa: F401 - registers the Gymnasium ids
from agents.registry import parallel_of
from baselines.sparse.result import SparseResult
from fdia_env.scenarios import Scenario
from fdia_env.systems import LinearSystem

GYM_ID = "fdia_env/SparseAttack-v0"


def _check_budget(budget: Any) -> int:
    if isinstance(budget, bool) or not isinstance(budget, int | np.integer) or budget < 1:
        raise ValueError(f"budget must be an integer >= 1, got {budget!r}")
    return int(budget)


def _plan_spaces(pairs: int) -> tuple[spaces.Box, spaces.Discrete]:
    """Observation (plan so far, decisions left) and action spaces of the plan MDP."""
    obs = spaces.Box(0.0, 1.0, (pairs + 1,), dtype=np.float32)
    return obs, spaces.Discrete(pairs + 1)


class PlanSparseEnv(gym.Env):
    """``sparse_attack_v0`` on one instance, the attack set picked pair by pair (module doc).

    Args:
        scenario: Preset name, :class:`~fdia_env.scenarios.Scenario` or ``LinearSystem``.
        budget: c, sensor-time pairs over the window (>= 1).
        horizon: N, window steps.
        objective: ``"trace"`` or ``"logdet"``.

    Raises:
        ValueError: For a budget below 1 (naming it), or anything the wrapped env rejects (a
            budget above M·N, an unknown objective, ...), with its message.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": []}

    def __init__(
        self,
        scenario: str | Scenario | LinearSystem,
        budget: int,
        horizon: int,
        objective: str = "trace",
    ) -> None:
        self.budget = _check_budget(budget)
        self.inner = gym.make(
            GYM_ID,
            scenario=scenario,
            budget=self.budget,
            horizon=horizon,
            objective=objective,
            action="multibinary",
        )
        parallel = parallel_of(self.inner)
        self.M = parallel.system.M
        self.horizon = parallel.spec.horizon
        self.pairs = self.M * self.horizon
        self.observation_space, self.action_space = _plan_spaces(self.pairs)
        self._plan = np.zeros(self.pairs, bool)
        self._made = 0
        self._seed: int | None = None

    def _obs(self) -> np.ndarray:
        left = (self.budget - self._made) / self.budget
        return np.concatenate([self._plan, [left]]).astype(np.float32)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Start an empty plan (the wrapped env is reset, with ``seed``, when it is played)."""
        super().reset(seed=seed)
        self._seed = seed
        self._plan[:] = False
        self._made = 0
        return self._obs(), {}

    def action_masks(self) -> np.ndarray:
        """(N·M + 1,) legal actions: 0 always, a pair while it is not in the plan."""
        return np.concatenate([[True], ~self._plan])

    def play(self, plan: np.ndarray) -> float:
        """The wrapped env's return of the (N, M) 0/1 ``plan``, played step by step."""
        self.inner.reset(seed=self._seed)
        total, done, k = 0.0, False, 0
        while not done:
            _, reward, term, trunc, _ = self.inner.step(plan[k].astype(np.int8))
            total += float(reward)
            done, k = term or trunc, k + 1
        return total

    def step(self, action: Any):
        """Add pair ``action`` to the plan (0: none); the ``c``-th decision plays the plan.

        Raises:
            ValueError: For an action outside ``[0, N·M]`` or a pair already in the plan.
        """
        a = int(action)
        if not 0 <= a <= self.pairs or not self.action_masks()[a]:
            raise ValueError(
                f"action must be 0 (no pair) or a pair 1 + k·M + i not yet in the plan, in "
                f"[0, {self.pairs}], got {action!r}"
            )
        if a:
            self._plan[a - 1] = True
        self._made += 1
        if self._made < self.budget:
            return self._obs(), 0.0, False, False, {}
        total = self.play(self._plan.reshape(self.horizon, self.M))
        return self._obs(), total, True, False, {}

    def close(self) -> None:
        """Close the wrapped env."""
        self.inner.close()


class PlanVectorEnv:
    """:class:`PlanSparseEnv` for ``num_envs`` members on the torch vector env.

    What :func:`agents.torch_ppo.train_torch_ppo` needs: ``backend == "torch"``,
    ``SAME_STEP`` autoreset, tensors on ``device``, ``action_masks()``. Every episode takes
    ``c`` decisions, so the members end together; the last one plays the N steps of every
    member's plan in the wrapped torch vector env (which then autoresets itself).

    Args:
        scenario: As :class:`PlanSparseEnv`.
        budget: c (>= 1).
        horizon: N.
        objective: ``"trace"`` or ``"logdet"``.
        num_envs: Members B.
        device: Torch device.
    """

    backend = "torch"

    def __init__(
        self,
        scenario: str | Scenario | LinearSystem,
        budget: int,
        horizon: int,
        objective: str,
        num_envs: int,
        device: str = "cpu",
    ) -> None:
        import torch

        from agents.torch_ppo import make_torch_env

        self.budget = _check_budget(budget)
        self.inner = make_torch_env(
            GYM_ID,
            num_envs,
            device,
            scenario=scenario,
            budget=self.budget,
            horizon=horizon,
            objective=objective,
            action="multibinary",
        )
        self.num_envs = self.inner.num_envs
        self.device = self.inner.device
        self.metadata = {"autoreset_mode": gym.vector.AutoresetMode.SAME_STEP}
        self.M = int(self.inner.single_action_space.shape[0])
        self.horizon = int(self.inner.spec_episode.horizon)
        self.pairs = self.M * self.horizon
        self.single_observation_space, self.single_action_space = _plan_spaces(self.pairs)
        self._plan = torch.zeros((self.num_envs, self.pairs), dtype=torch.bool, device=self.device)
        self._made = 0
        self._torch = torch

    def _obs(self):
        torch = self._torch
        left = torch.full(
            (self.num_envs, 1), (self.budget - self._made) / self.budget, device=self.device
        )
        return torch.cat([self._plan.float(), left], dim=1)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Reset every member (and the wrapped env, seeded)."""
        self.inner.reset(seed=seed, options=options)
        self._plan.zero_()
        self._made = 0
        return self._obs(), {}

    def action_masks(self):
        """(B, N·M + 1) bool legal actions (as :meth:`PlanSparseEnv.action_masks`)."""
        torch = self._torch
        first = torch.ones((self.num_envs, 1), dtype=torch.bool, device=self.device)
        return torch.cat([first, ~self._plan], dim=1)

    def step(self, actions):
        """One decision of every member ((B,) int64 tensor)."""
        torch = self._torch
        B = self.num_envs
        rows = torch.arange(B, device=self.device)
        picked = actions > 0
        self._plan[rows[picked], actions[picked] - 1] = True
        self._made += 1
        no = torch.zeros(B, dtype=torch.bool, device=self.device)
        if self._made < self.budget:
            zeros = torch.zeros(B, dtype=torch.float64, device=self.device)
            return self._obs(), zeros, no, no.clone(), {}
        plan = self._plan.reshape(B, self.horizon, self.M).to(torch.int8)
        total = torch.zeros(B, dtype=torch.float64, device=self.device)
        for k in range(self.horizon):
            reward = self.inner.step(plan[:, k].contiguous())[1]
            total += reward
        final = self._obs()
        self._plan.zero_()
        self._made = 0
        done = torch.ones(B, dtype=torch.bool, device=self.device)
        return self._obs(), total, done, no, {"final_obs": final}

    def close(self) -> None:
        """Close the wrapped vector env."""
        self.inner.close()


class PlanPolicy:
    """Plays a solver's attack set in :class:`PlanSparseEnv` (SB3 ``predict`` signature).

    Picks the lowest-numbered pair of the set not yet in the plan, else 0.

    Args:
        result: A :class:`~baselines.sparse.result.SparseResult` (``attacks`` as 0-based
            (step, sensor) pairs).
    """

    def __init__(self, result: SparseResult) -> None:
        self.pairs = np.array(
            sorted(1 + k * result.num_sensors + i for k, i in result.attacks), dtype=np.int64
        )
        self.size = int(result.horizon) * int(result.num_sensors)

    def predict(
        self, observation: Any, state: Any = None, episode_start: Any = None, **_: Any
    ) -> tuple[Any, Any]:
        """The next pick for one (N·M + 1,) observation."""
        plan = np.asarray(observation)[: self.size] > 0.5
        todo = [a for a in self.pairs if not plan[a - 1]]
        return np.int64(todo[0] if todo else 0), state
