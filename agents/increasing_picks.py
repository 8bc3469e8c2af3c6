"""The sparse attack's plan-first picks in increasing order: one sequence of picks per plan.

In the sequential format's plan-first order (``action="sequential"``, ``order="plan"``) a plan
of c pairs can be picked in any of its c! orders. An entropy bonus then finds its entropy in
shuffling the order of one plan's picks and stops exploring other plans: measured on
grid-ieee14 (c = 5, N = 9, log det, MaskablePPO, seed 2), the policy put all its probability on
the five pairs of SFS's plan, at every decision, and stopped at 96.81 % of the optimum.
:class:`IncreasingPicks` also forbids every pair below the last one picked (pairs numbered as
the actions: step-major), so each plan has exactly one sequence of picks and spreading
probability means trying other plans. The env's dynamics, rewards and reachable plans are
unchanged: its mask only loses the pairs below the last pick, and any plan can be picked in
increasing order. ``train.py`` uses it on the grid presets' sparse attack
(``--increasing-picks``; docs/guide/training.md), in the training env and in the env that
scores the learned policy, so the policy is played as it was trained.

>>> import gymnasium as gym
>>> import fdia_env  # registers the envs
>>> env = IncreasingPicks(gym.make("fdia_env/SparseAttack-v2", action="sequential", order="plan"))
>>> _ = env.reset(seed=0)
>>> int(env.action_masks().sum()), int(env.action_space.n)
(19, 19)
>>> _ = env.step(5)
>>> env.action_masks().nonzero()[0].tolist()  # stop and the pairs above pair 5
[0, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18]
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

STOP = 0


class IncreasingPicks(gym.Wrapper):
    """The plan-first sequential format with the picks in increasing order (module docstring).

    Args:
        env: A Gymnasium view of the sparse attack in the sequential format's plan-first order.

    Raises:
        ValueError: For an env not in that format and order.
    """

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        parallel = getattr(env.unwrapped, "parallel", None)
        if not getattr(parallel, "plan_first", False):
            raise ValueError(
                "increasing_picks applies to the sparse attack's sequential format in its "
                "plan-first order (env options action='sequential', order='plan'), "
                f"got {env.unwrapped!r}"
            )
        self._last = STOP

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        """Reset the env and the last pick."""
        self._last = STOP
        return self.env.reset(**kwargs)

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        """One decision of the env; a pick becomes the last pick."""
        self._last = max(self._last, int(action))
        return self.env.step(action)

    def action_masks(self) -> np.ndarray:
        """The env's mask without the pairs at or below the last pick (stop stays as it is)."""
        mask = np.array(self.env.unwrapped.action_masks(), copy=True)
        mask[STOP + 1 : self._last + 1] = 0
        return mask
