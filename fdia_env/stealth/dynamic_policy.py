"""Attacks on the Kalman filter as policies of ``stealth_dynamic_v0`` (SB3 ``predict``).

``baselines.stealth`` computes the attacks (Mo & Sinopoli's injections, Guo et al.'s T); these
helpers turn them into the env's actions and play them:

>>> import numpy as np
>>> from fdia_env.stealth import stealth_dynamic_v0
>>> env = stealth_dynamic_v0.parallel_env(action="linear", dynamics="expected")
>>> linear_action(env.model, -np.eye(3))[:, :3].diagonal().tolist()  # T = I + 4 · (−½) I
[-0.5, -0.5, -0.5]
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fdia_env.envs.policy import PolicyBase, observation_array
from fdia_env.stealth.dynamic_model import DynamicModel


def bias_actions(model: DynamicModel, injections: Any) -> np.ndarray:
    """(N, r) ``action="bias"`` actions that inject the (N, m) ``injections`` on the rows.

    Args:
        model: The env's :class:`~fdia_env.stealth.dynamic_model.DynamicModel` (``env.model``).
        injections: (N, m) injections per step, zero off the attacked rows (as
            ``StealthyKalmanAttack.attack`` returns them).

    Raises:
        ValueError: Naming ``injections`` for a bad shape, non-finite entries or entries off the
            attacked rows, and ``a_max`` when an injection needs more than ``a_max`` innovation
            standard deviations.
    """
    inj = np.asarray(injections, dtype=np.float64)
    if inj.ndim != 2 or inj.shape[1] != model.m or not np.all(np.isfinite(inj)):
        raise ValueError(
            f"injections must be a finite (steps, {model.m}) array, got shape {inj.shape}"
        )
    off = np.ones(model.m, dtype=bool)
    off[model.rows] = False
    if np.any(inj[:, off] != 0.0):
        raise ValueError(
            f"injections must be zero off the attacked rows {model.rows.tolist()}, got non-zero "
            f"entries on rows {np.flatnonzero(np.any(inj[:, off] != 0.0, axis=0)).tolist()}"
        )
    actions = inj[:, model.rows] / (model.a_max * model.sigma)
    peak = float(np.abs(actions).max()) if actions.size else 0.0
    if peak > 1.0:
        raise ValueError(
            f"a_max = {model.a_max:g} is too small for these injections: they need "
            f"{peak * model.a_max:.6g} innovation standard deviations (raise a_max)"
        )
    return actions


def linear_action(model: DynamicModel, T: Any, sigma_b: Any = None) -> np.ndarray:
    """The ``action="linear"`` action ``(r, r + 1)`` playing ``z̃_S = T z_S + b``.

    Args:
        model: The env's model (``env.model``).
        T: (r, r) the map on the attacked rows.
        sigma_b: (r,) standard deviations of b (default zero).

    Raises:
        ValueError: Naming ``T``/``sigma_b`` for a bad shape or non-finite entries, and
            ``t_max``/``b_max`` when the attack lies outside the action's range.
    """
    r = len(model.rows)
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (r, r) or not np.all(np.isfinite(T)):
        raise ValueError(f"T must be a finite ({r}, {r}) matrix, got shape {T.shape}")
    sb = np.zeros(r) if sigma_b is None else np.asarray(sigma_b, dtype=np.float64)
    if sb.shape != (r,) or not np.all(np.isfinite(sb)) or np.any(sb < 0):
        raise ValueError(f"sigma_b must be {r} finite standard deviations >= 0, got {sigma_b!r}")
    action = np.zeros((r, r + 1))
    action[:, :r] = (T - np.eye(r)) / model.t_max
    action[:, r] = sb / (model.b_max * model.sigma)
    if np.abs(action[:, :r]).max(initial=0.0) > 1.0:
        raise ValueError(f"t_max = {model.t_max:g} is too small for this T (raise t_max)")
    if action[:, r].max(initial=0.0) > 1.0:
        raise ValueError(f"b_max = {model.b_max:g} is too small for this sigma_b (raise b_max)")
    return action


class ScheduledPolicy(PolicyBase):
    """Plays ``actions[k]`` at step k of the episode (an open-loop attack; SB3 ``predict``).

    The step is read from the observation's first entry (steps left / horizon).

    Args:
        actions: (N, *action shape) one action per step; N is the env's horizon.

    Example:
        >>> policy = ScheduledPolicy([[0.1], [0.2], [0.3]])
        >>> print(policy.predict(np.array([2 / 3, 0, 0, 0], dtype=np.float32))[0])  # step 1
        [0.2]
    """

    def __init__(self, actions: Any) -> None:
        table = np.asarray(actions, dtype=np.float64)
        if table.ndim < 2 or table.shape[0] == 0 or not np.all(np.isfinite(table)):
            raise ValueError(
                f"actions must be a finite (steps, ...) array of actions, got shape {table.shape}"
            )
        if np.abs(table).max() > 1.0:
            raise ValueError("actions must lie in [-1, 1] (the env's action space)")
        self.actions = table.astype(np.float32)
        self.actions.setflags(write=False)

    def act(self, observation: Any, deterministic: bool = False) -> np.ndarray:
        """The step's action, (B, ...) for a (B, 4) batch."""
        obs = observation_array(observation)
        horizon = self.actions.shape[0]
        k = np.clip(np.rint((1.0 - obs[..., 0]) * horizon).astype(np.int64), 0, horizon - 1)
        return self.actions[k].copy()
