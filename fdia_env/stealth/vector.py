"""Native vector env of ``stealth_attack_v0``'s Gymnasium view: B snapshots as one batch.

``gymnasium.make_vec("fdia_env/StealthAttack-v0", num_envs=B,
vectorization_mode="vector_entry_point", **options)`` (the options of
:func:`fdia_env.stealth.stealth_attack_v0.parallel_env`). Autoreset is Gymnasium's default
``NEXT_STEP``: the step after an episode's last one resets that member (its action is ignored,
reward 0); ``autoreset_mode=AutoresetMode.SAME_STEP`` resets it in the same step, with the last
observation and info in ``infos["final_obs"]`` / ``infos["final_info"]`` (what
:func:`agents.torch_ppo.make_torch_env` asks for; see :mod:`fdia_env.stealth.vector_base`).

``backend="torch", device="cpu" | "cuda"`` runs the same step on float64 tensors of that
device: actions are tensors of the device, observations, rewards, flags and infos come back as
tensors there. Expected dynamics equal the numpy backend to 1e-10 (the χ² detection
probability is :func:`fdia_env.stealth.torch_ops.ncx2_sf`); sampled dynamics draw the meter
noise from a ``torch.Generator`` of the device (``seed`` an int or None), so they equal numpy in
distribution, and exactly given the same noise.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fdia_env.actions import check_vector_actions
from fdia_env.backend import NUMPY
from fdia_env.stealth.env import MAX_RATIO, StealthAttackEnv
from fdia_env.stealth.static import rounding_residual
from fdia_env.stealth.vector_base import StealthVectorBase, entry_point

MAX_NUM_ENVS = 1 << 20


class StealthVectorEnv(StealthVectorBase):
    """B copies of the attacker's view, stepped as one batch (see the module docstring).

    Args: as :class:`~fdia_env.stealth.vector_base.StealthVectorBase`, B up to 2**20 and
    ``**kwargs`` the options of ``stealth_attack_v0.parallel_env``.
    """

    env_cls = StealthAttackEnv
    max_num_envs = MAX_NUM_ENVS

    def _init_state(self) -> None:
        xp = self.xp
        est = self.env.estimation
        L = np.linalg.cholesky(est.R)
        diag_L = np.diag(L).copy() if not np.any(L - np.diag(np.diag(L))) else None
        scale = self.env.magnitude if self.env.action_kind == "shift" else 1.0
        self._HT = xp.asarray(est.H.T * scale)  # (n, m): bits @ HT = H c (box_shift: H bits)
        self._KT = xp.asarray(est.K.T)
        self._diag_L = None if diag_L is None else xp.asarray(diag_L)
        self._LT = xp.asarray(L.T)
        self._protected = xp.asarray(self.env.protected)
        if xp is not NUMPY:  # what the torch step computes itself (numpy: est's methods)
            self._Q = xp.asarray(est._Q)
            self._Linv = xp.asarray(est._Linv)
            self._ST = xp.asarray(est.S.T)
            self._lnr_scale = xp.asarray(est._lnr_scale)
            self._critical = xp.asarray(est.critical)
        self._k = xp.zeros(self.num_envs, dtype=np.int64)

    def injections(self, actions: Any) -> Any:
        """(B, m) injections of (B, d) actions: as the single env's ``injection``, batched."""
        env, xp = self.env, self.xp
        acts = xp.asarray(actions, dtype=np.float64)
        if env.action_kind == "free":
            a = env.a_max * xp.clip(acts, -1.0, 1.0)
        else:
            a = acts @ self._HT
        if env.action_kind == "box_shift":  # as env.box_scale: largest |a_i| = a_max
            size = self._row_max(abs(a))
            a = a * (env.a_max / xp.where(size > 0.0, size, env.a_max))
        a[:, self._protected] = 0.0
        size = abs(a)
        scale = self._row_max(size)
        a[size <= 1e-12 * xp.maximum(scale, 1e-300)] = 0.0
        if env.budget < a.shape[1]:
            if xp is NUMPY:
                order = np.argsort(-np.abs(a), axis=1, kind="stable")
                np.put_along_axis(a, order[:, env.budget :], 0.0, axis=1)
            else:
                import torch

                order = torch.argsort(-abs(a), dim=1, stable=True)
                a.scatter_(1, order[:, env.budget :], 0.0)
        return a

    def _restart(self, members: Any) -> tuple[Any, dict[str, Any]]:
        """Start ``members`` afresh; the reset observation and info (rows of ``members``)."""
        xp = self.xp
        self._k = xp.where(members, 0, self._k)
        obs = xp.zeros((self.num_envs, 3), dtype=np.float32)
        obs[:, 0] = 1.0
        zero = xp.zeros(self.num_envs)
        return obs, self._infos(zero, zero > 0, zero, zero, zero)

    def noise(self) -> Any:
        """(B, m) standard normal draws of this step's meter noise (before R's factor)."""
        if self.xp is NUMPY:
            return self._rng.standard_normal((self.num_envs, self.env.estimation.m))
        return self.xp.normal(self._rng, (self.num_envs, self.env.estimation.m))

    def step(self, actions: Any) -> tuple[Any, Any, Any, Any, dict]:
        """One snapshot for every member (NEXT_STEP: members that ended last step reset instead)."""
        env, est, xp, B = self.env, self.env.estimation, self.xp, self.num_envs
        actions = check_vector_actions(self.single_action_space, actions, B, "attacker", xp)
        a = self.injections(actions)
        damage = self._max_abs(a @ self._KT)
        p = self._detection_probability(a) if env.test == "chi2" else xp.zeros(B)
        caught = env.detected_reward
        if env.dynamics == "sampled":
            e = self.noise()
            e = e * self._diag_L if self._diag_L is not None else e @ self._LT
            z = self._attacked_residual(e, a)
            statistic = self._statistic(z)
            detected = statistic > est.threshold if env.test == "chi2" else self._lnr_alarm(z)
            reward = xp.where(detected, caught, damage)
        else:
            detected = xp.zeros(B, dtype=np.bool_)
            statistic = self._noncentrality(a)[0] + est.dof
            reward = (1.0 - p) * damage + p * caught
        resetting = xp.copy(self._needs_reset)
        live = ~resetting
        self._k = xp.where(resetting, 0, self._k + 1)
        terminated, truncated = self._episode_ends(self._k, live, detected)
        reward = xp.where(resetting, 0.0, reward)
        detected = detected & live
        obs = xp.empty((B, 3), dtype=np.float32)
        obs[:, 0] = (env.horizon - self._k) / env.horizon
        obs[:, 1] = xp.astype(detected, np.float32)
        obs[:, 2] = xp.where(live, xp.minimum(statistic / est.threshold, MAX_RATIO), 0.0)
        used = (a != 0).sum(1)
        infos = self._infos(
            xp.where(live, damage, 0.0),
            detected,
            xp.where(live, p, 0.0),
            xp.where(live, statistic, 0.0),
            xp.where(live, used, 0),
        )
        obs, infos = self._autoreset(obs, infos, terminated | truncated)
        return obs, reward, terminated, truncated, infos

    # --- the estimator's functions on the batch (numpy: the model's own methods) ---------
    def _row_max(self, x: Any) -> Any:
        """(B, 1) each row's largest entry."""
        return x.max(1, keepdims=True) if self.xp is NUMPY else x.amax(1, keepdim=True)

    def _max_abs(self, x: Any) -> Any:
        return np.max(np.abs(x), axis=1) if self.xp is NUMPY else x.abs().amax(1)

    def _statistic(self, z: Any) -> Any:
        """(B,) the χ² statistic of (B, m) readings (the non-centrality of injections)."""
        if self.xp is NUMPY:
            return np.asarray(self.env.estimation.statistic(z))
        est = self.env.estimation
        w = z * self._Linv.diagonal() if est._diag_Linv is not None else z @ self._Linv.T
        r = w - (w @ self._Q) @ self._Q.T
        return (r * r).sum(1)

    def _noncentrality(self, a: Any) -> tuple[Any, Any]:
        """(B,) λ of (B, m) injections (0 where stealthy) and (B,) where they are stealthy."""
        est = self.env.estimation
        if self.xp is NUMPY:
            lam, size = est._parts(a)
        else:
            import torch

            w = a * self._Linv.diagonal() if est._diag_Linv is not None else a @ self._Linv.T
            r = w - (w @ self._Q) @ self._Q.T
            lam, size = (r * r).sum(1), torch.linalg.vector_norm(w, dim=1)
        stealthy = rounding_residual(lam, size)
        return self.xp.where(stealthy, 0.0, lam), stealthy

    def _attacked_residual(self, e: Any, a: Any) -> Any:
        """(B, m) residuals of readings ``e + a`` (``StaticEstimation.attacked_residual``)."""
        if self.xp is NUMPY:
            return self.env.estimation.attacked_residual(e, a)
        seen = ~self._noncentrality(a)[1]
        return e @ self._ST + (a @ self._ST) * seen[:, None]

    def _lnr_alarm(self, z: Any) -> Any:
        """(B,) bool: the largest-normalised-residual test alarms."""
        est = self.env.estimation
        if self.xp is NUMPY:
            return np.asarray(est.alarm(z, "lnr"))
        r = self.xp.where(self._critical, 0.0, (z @ self._ST) / self._lnr_scale)
        return r.abs().amax(1) > est.lnr_threshold

    def _detection_probability(self, a: Any) -> Any:
        """(B,) the exact χ² detection probability of (B, m) injections."""
        est = self.env.estimation
        if self.xp is NUMPY:
            return np.asarray(est.detection_probability(a), dtype=np.float64)
        import torch

        from fdia_env.stealth.torch_ops import ncx2_sf

        lam, stealthy = self._noncentrality(a)
        # as StaticEstimation.detection_probability: α where stealthy, else the tail
        out = torch.where(stealthy, torch.full_like(lam, est.alpha), torch.ones_like(lam))
        seen = torch.nonzero(~stealthy).flatten()
        if seen.numel():
            out[seen] = ncx2_sf(est.threshold, est.dof, lam[seen])
        return out

    def _infos(self, phi, detected, p, statistic, used) -> dict[str, Any]:
        xp = self.xp
        info = {
            "phi": xp.astype(phi, np.float64),
            "step": xp.copy(self._k),
            "detected": xp.astype(detected, np.bool_),
            "detection_probability": xp.astype(p, np.float64),
            "statistic": xp.astype(statistic, np.float64),
            "meters_used": xp.astype(used, np.int64),
        }
        return self._all_members(info)


make_vector = entry_point(StealthVectorEnv, "stealth env")
