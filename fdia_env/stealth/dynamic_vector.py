"""Native vector env of ``stealth_dynamic_v0``'s attacker view: B filters as one batch.

``gymnasium.make_vec("fdia_env/StealthDynamic-v0", num_envs=B,
vectorization_mode="vector_entry_point", **options)`` (the options of
:func:`fdia_env.stealth.stealth_dynamic_v0.parallel_env`). The members run the same batched
model as the single env (a batch of one there). Autoreset is Gymnasium's default
``NEXT_STEP``: the step after an episode's last one resets that member (its action is ignored,
reward 0); ``autoreset_mode=AutoresetMode.SAME_STEP`` resets it in the same step, with the last
observation and info in ``infos["final_obs"]`` / ``infos["final_info"]`` (what
:func:`agents.torch_ppo.make_torch_env` asks for; see :mod:`fdia_env.stealth.vector_base`).
``action="linear"`` computes each member's detection probability by a numerical
integral (:func:`fdia_env.detection.gchisq.gchisq_sf`), the dominant cost of a member-step
unless the window is strictly stealthy.

``backend="torch", device="cpu" | "cuda"`` runs either attack (``action="bias"``, the default,
or ``"linear"``) on float64 tensors of that device: actions are tensors of the device,
observations, rewards, flags and infos come back as tensors there; its expected dynamics equal
numpy's to 1e-10, and so do its sampled dynamics given the same draws (it draws them from a
``torch.Generator`` of the device, ``seed`` an int or None). The linear attack's detection
probability (that integral) is computed by scipy on the CPU for every backend.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fdia_env.actions import check_vector_actions
from fdia_env.stealth.dynamic import MAX_LOG_ERROR, MAX_RATIO, StealthDynamicEnv
from fdia_env.stealth.vector_base import StealthVectorBase, entry_point

MAX_NUM_ENVS = 1 << 16


class StealthDynamicVectorEnv(StealthVectorBase):
    """B copies of the attacker's view, stepped as one batch (see the module docstring).

    Args: as :class:`~fdia_env.stealth.vector_base.StealthVectorBase`, B up to 2**16 and
    ``**kwargs`` the options of ``stealth_dynamic_v0.parallel_env``.
    """

    env_cls = StealthDynamicEnv
    max_num_envs = MAX_NUM_ENVS

    def _init_state(self) -> None:
        xp = self.xp
        self.model = self.env.model
        self._alpha = xp.full(self.num_envs, float(self.env.alpha), dtype=np.float64)
        tau = np.repeat(self.env._tau[[self.env._default_rate()]], self.num_envs, axis=0)
        self._tau = xp.asarray(tau)
        self._state = self.model.new_state(self.num_envs, xp)

    def _restart(self, members: Any) -> tuple[Any, dict[str, Any]]:
        """Start ``members`` afresh; the reset observation and info (rows of ``members``)."""
        xp, B = self.xp, self.num_envs
        self.model.restart(self._state, members, self._rng, self.env.dynamics == "sampled", xp)
        obs = xp.zeros((B, 4), dtype=np.float32)
        obs[:, 0] = 1.0
        clean = xp.full(B, self.model.clean, dtype=np.float64)
        zero = xp.zeros(B)
        return obs, self._infos(clean, clean, zero > 0, zero, zero, self._tau[:, 0], zero)

    def step(self, actions: Any) -> tuple[Any, Any, Any, Any, dict]:
        """One filter step for every member (NEXT_STEP: those that ended last step reset)."""
        env, B, xp = self.env, self.num_envs, self.xp
        acts = check_vector_actions(self.single_action_space, actions, B, "attacker", xp)
        resetting = xp.copy(self._needs_reset)
        sampled = env.dynamics == "sampled"
        out = self.model.step(
            self._state, acts, self._alpha, self._tau, sampled, self._rng, None, xp
        )
        caught = env.detected_reward
        if sampled:
            reward = xp.where(out["detected"], caught, out["error"])
        else:
            reward = (1.0 - out["p"]) * out["phi"] + out["p"] * caught
        if xp.any(resetting):  # the reset step itself: a fresh member, nothing happened
            self.model.restart(self._state, resetting, self._rng, sampled, xp)
        k = self._state["k"]
        live = ~resetting
        detected = out["detected"] & live
        terminated, truncated = self._episode_ends(k, live, detected)
        reward = xp.where(live, reward, 0.0)
        phi = xp.where(live, out["phi"], self.model.clean)
        ratio = xp.where(live, out["statistic"] / out["threshold"], 0.0)
        obs = xp.empty((B, 4), dtype=np.float32)
        obs[:, 0] = (env.horizon - k) / env.horizon
        obs[:, 1] = xp.astype(detected, np.float32)
        obs[:, 2] = xp.minimum(ratio, MAX_RATIO)
        obs[:, 3] = xp.minimum(xp.log(xp.maximum(phi / self.model.clean, 1.0)), MAX_LOG_ERROR)
        infos = self._infos(
            phi,
            xp.where(live, out["error"], self.model.clean),
            detected,
            xp.where(live, out["p"], 0.0),
            xp.where(live, out["statistic"], 0.0),
            xp.where(live, out["threshold"], self._tau[:, 0]),
            xp.where(live, out["kl"], 0.0),
        )
        obs, infos = self._autoreset(obs, infos, terminated | truncated)
        return obs, reward, terminated, truncated, infos

    def _infos(self, phi, error, detected, p, statistic, threshold, kl) -> dict[str, Any]:
        xp = self.xp
        info = {
            "phi": xp.astype(phi, np.float64),
            "error": xp.astype(error, np.float64),
            "step": xp.copy(self._state["k"]),
            "alpha": xp.copy(self._alpha),
            "detected": xp.astype(detected, np.bool_),
            "detection_probability": xp.astype(p, np.float64),
            "statistic": xp.astype(statistic, np.float64),
            "threshold": xp.astype(threshold, np.float64),
            "kl": xp.astype(kl, np.float64),
        }
        return self._all_members(info)


make_vector = entry_point(StealthDynamicVectorEnv, "dynamic stealth env")
