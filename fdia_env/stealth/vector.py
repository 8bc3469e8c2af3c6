"""Native vector env of ``stealth_attack_v0``'s Gymnasium view: B snapshots as one numpy batch.

``gymnasium.make_vec("fdia_env/StealthAttack-v0", num_envs=B,
vectorization_mode="vector_entry_point", **options)`` (the options of
:func:`fdia_env.stealth.stealth_attack_v0.parallel_env`, numpy only). Autoreset is Gymnasium's
default ``NEXT_STEP``: the step after an episode's last one resets that member (its action is
ignored, reward 0).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from fdia_env._validation import check_int
from fdia_env.envs.actions import check_batch_actions
from fdia_env.stealth.env import MAX_RATIO, StealthAttackEnv

MAX_NUM_ENVS = 1 << 20


class StealthVectorEnv(VectorEnv):
    """B copies of the attacker's view, stepped as one batch (see the module docstring).

    Args:
        num_envs: B, 1..2**20.
        **kwargs: Options of ``stealth_attack_v0.parallel_env`` (no ``render_mode``).
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP}  # noqa: RUF012

    def __init__(self, num_envs: int, **kwargs: Any) -> None:
        if kwargs.get("render_mode") is not None:
            raise ValueError("render_mode is not supported by the native vector env")
        kwargs.pop("render_mode", None)
        self.num_envs = check_int("num_envs", num_envs, minimum=1, maximum=MAX_NUM_ENVS)
        self.env = StealthAttackEnv(**kwargs)
        est = self.env.estimation
        self.single_action_space = self.env.action_space("attacker")
        self.single_observation_space = self.env.observation_space("attacker")
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self._HT = est.H.T * self.env.magnitude  # (n, m): bits @ HT = H c
        self._KT = est.K.T
        L = np.linalg.cholesky(est.R)
        self._diag_L = np.diag(L).copy() if not np.any(L - np.diag(np.diag(L))) else None
        self._LT = L.T
        self._rng = np.random.default_rng()
        self._k = np.zeros(self.num_envs, dtype=np.int64)
        self._needs_reset = np.zeros(self.num_envs, dtype=bool)
        self._obs = np.zeros((self.num_envs, 3), dtype=np.float32)

    def injections(self, actions: np.ndarray) -> np.ndarray:
        """(B, m) injections of (B, d) actions: as the single env's ``injection``, batched."""
        env = self.env
        acts = np.asarray(actions, dtype=np.float64)
        if env.action_kind == "shift":
            a = acts @ self._HT
        else:
            a = env.a_max * np.clip(acts, -1.0, 1.0)
        a[:, env.protected] = 0.0
        scale = np.max(np.abs(a), axis=1, keepdims=True)
        a[np.abs(a) <= 1e-12 * np.maximum(scale, 1e-300)] = 0.0
        if env.budget < a.shape[1]:
            order = np.argsort(-np.abs(a), axis=1, kind="stable")
            drop = order[:, env.budget :]
            np.put_along_axis(a, drop, 0.0, axis=1)
        return a

    def reset(
        self, *, seed: int | None = None, options: dict | None = None
    ) -> tuple[np.ndarray, dict]:
        """Reset every member; ``seed`` seeds the noise of the whole batch."""
        if seed is not None:
            self._rng = np.random.default_rng(int(seed))
        self._k[:] = 0
        self._needs_reset[:] = False
        self._obs = np.zeros((self.num_envs, 3), dtype=np.float32)
        self._obs[:, 0] = 1.0
        zero = np.zeros(self.num_envs)
        return self._obs.copy(), self._infos(zero, zero.astype(bool), zero, zero, zero)

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict]:
        """One snapshot for every member (members that ended last step are reset instead)."""
        check_batch_actions(self.single_action_space, actions, self.num_envs, "attacker")
        env, est = self.env, self.env.estimation
        a = self.injections(actions)
        damage = np.max(np.abs(a @ self._KT), axis=1)
        if env.test == "chi2":
            p = np.asarray(est.detection_probability(a), dtype=np.float64)
        else:
            p = np.zeros(self.num_envs)
        caught = -env.penalty if env.on_detect == "penalty" else 0.0
        if env.dynamics == "sampled":
            e = self._rng.standard_normal((self.num_envs, est.m))
            z = (e * self._diag_L if self._diag_L is not None else e @ self._LT) + a
            statistic = np.asarray(est.statistic(z))
            if env.test == "chi2":
                detected = statistic > est.threshold
            else:
                detected = np.asarray(est.alarm(z, "lnr"))
            reward = np.where(detected, caught, damage)
        else:
            detected = np.zeros(self.num_envs, dtype=bool)
            statistic = np.asarray(est.noncentrality(a)) + est.dof
            reward = (1.0 - p) * damage + p * caught
        resetting = self._needs_reset.copy()
        self._k = np.where(resetting, 0, self._k + 1)
        terminated = ~resetting & ((self._k >= env.horizon) | (detected & (env.on_detect == "end")))
        truncated = ~resetting & ~terminated
        truncated &= (env.max_cycles is not None) & (self._k >= (env.max_cycles or 0))
        reward = np.where(resetting, 0.0, reward)
        obs = np.empty((self.num_envs, 3), dtype=np.float32)
        obs[:, 0] = (env.horizon - self._k) / env.horizon
        obs[:, 1] = np.where(resetting, 0.0, detected)
        obs[:, 2] = np.where(resetting, 0.0, np.minimum(statistic / est.threshold, MAX_RATIO))
        self._needs_reset = terminated | truncated
        self._obs = obs
        live = ~resetting
        infos = self._infos(
            np.where(live, damage, 0.0),
            detected & live,
            np.where(live, p, 0.0),
            np.where(live, statistic, 0.0),
            np.where(live, np.count_nonzero(a, axis=1), 0),
        )
        return obs.copy(), reward, terminated, truncated, infos

    def _infos(self, phi, detected, p, statistic, used) -> dict[str, np.ndarray]:
        info = {
            "phi": np.asarray(phi, dtype=np.float64),
            "step": self._k.copy(),
            "detected": np.asarray(detected, dtype=bool),
            "detection_probability": np.asarray(p, dtype=np.float64),
            "statistic": np.asarray(statistic, dtype=np.float64),
            "meters_used": np.asarray(used, dtype=np.int64),
        }
        mask = np.ones(self.num_envs, dtype=bool)
        info.update({f"_{k}": mask for k in list(info)})
        return info


def make_vector(num_envs: int, **kwargs: Any) -> StealthVectorEnv:
    """Gymnasium ``vector_entry_point`` of ``"fdia_env/StealthAttack-v0"``.

    Raises:
        ValueError: For ``backend``/``device`` other than numpy on the CPU, or a bad option.
    """
    backend, device = kwargs.pop("backend", "numpy"), kwargs.pop("device", None)
    agent = kwargs.pop("agent", "attacker")
    kwargs.pop("module", None)
    if agent != "attacker" or kwargs.get("defender") is not None:
        raise ValueError(
            "the native vector env plays the attacker alone (defender=None); use "
            "vectorization_mode='sync' for the defender's view"
        )
    if backend != "numpy" or device not in (None, "cpu"):
        raise ValueError(
            f"backend={backend!r}, device={device!r}: the stealth env's native vector env runs "
            "numpy on the CPU (backend='numpy')"
        )
    autoreset = kwargs.pop("autoreset_mode", AutoresetMode.NEXT_STEP)
    if autoreset not in (AutoresetMode.NEXT_STEP, "next_step", "NextStep"):
        raise ValueError(f"autoreset_mode must be NEXT_STEP here, got {autoreset!r}")
    return StealthVectorEnv(num_envs, **kwargs)
