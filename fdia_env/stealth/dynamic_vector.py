"""Native vector env of ``stealth_dynamic_v0``'s attacker view: B filters as one numpy batch.

``gymnasium.make_vec("fdia_env/StealthDynamic-v0", num_envs=B,
vectorization_mode="vector_entry_point", **options)`` (the options of
:func:`fdia_env.stealth.stealth_dynamic_v0.parallel_env`, numpy only). The members run the same
batched model as the single env (a batch of one there). Autoreset is Gymnasium's default
``NEXT_STEP``: the step after an episode's last one resets that member (its action is ignored,
reward 0). ``action="linear"`` computes each member's detection probability by a numerical
integral (Imhof's), about 10–40 ms a member-step unless the window is strictly stealthy.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fdia_env.envs.actions import check_batch_actions
from fdia_env.stealth.dynamic import MAX_LOG_ERROR, MAX_RATIO, StealthDynamicEnv
from fdia_env.stealth.vector_base import StealthVectorBase, vector_options

MAX_NUM_ENVS = 1 << 16


class StealthDynamicVectorEnv(StealthVectorBase):
    """B copies of the attacker's view, stepped as one batch (see the module docstring).

    Args:
        num_envs: B, 1..2**16.
        **kwargs: Options of ``stealth_dynamic_v0.parallel_env`` (no ``render_mode``).
    """

    def __init__(self, num_envs: int, **kwargs: Any) -> None:
        self._init_batch(num_envs, StealthDynamicEnv, MAX_NUM_ENVS, kwargs)
        self.model = self.env.model
        self._alpha = np.full(self.num_envs, self.env.alpha)
        self._tau = np.repeat(self.env._tau[[self.env._default_rate()]], self.num_envs, axis=0)
        self._state = self.model.new_state(self.num_envs)
        self._needs_reset = np.zeros(self.num_envs, dtype=bool)

    def reset(
        self, *, seed: int | None = None, options: dict | None = None
    ) -> tuple[np.ndarray, dict]:
        """Reset every member; ``seed`` seeds the noise of the whole batch."""
        self._seed(seed)
        self._state = self.model.new_state(self.num_envs)
        everyone = np.ones(self.num_envs, dtype=bool)
        self.model.restart(self._state, everyone, self._rng, self.env.dynamics == "sampled")
        self._needs_reset[:] = False
        B = self.num_envs
        obs = np.zeros((B, 4), dtype=np.float32)
        obs[:, 0] = 1.0
        clean = np.full(B, self.model.clean)
        zero = np.zeros(B)
        return obs, self._infos(clean, clean, zero.astype(bool), zero, zero, self._tau[:, 0], zero)

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict]:
        """One filter step for every member (members that ended last step are reset instead)."""
        acts = check_batch_actions(self.single_action_space, actions, self.num_envs, "attacker")
        env, B = self.env, self.num_envs
        resetting = self._needs_reset.copy()
        sampled = env.dynamics == "sampled"
        out = self.model.step(self._state, acts, self._alpha, self._tau, sampled, self._rng)
        caught = -env.penalty if env.on_detect == "penalty" else 0.0
        if sampled:
            reward = np.where(out["detected"], caught, out["error"])
        else:
            reward = (1.0 - out["p"]) * out["phi"] + out["p"] * caught
        k = self._state["k"]
        if resetting.any():  # the reset step itself: a fresh member, nothing happened
            self.model.restart(self._state, resetting, self._rng, sampled)
            k = self._state["k"]
        live = ~resetting
        detected = out["detected"] & live
        terminated = live & ((k >= env.horizon) | (detected & (env.on_detect == "end")))
        truncated = live & ~terminated
        truncated &= (env.max_cycles is not None) & (k >= (env.max_cycles or 0))
        reward = np.where(live, reward, 0.0)
        phi = np.where(live, out["phi"], self.model.clean)
        ratio = np.where(live, out["statistic"] / out["threshold"], 0.0)
        obs = np.empty((B, 4), dtype=np.float32)
        obs[:, 0] = (env.horizon - k) / env.horizon
        obs[:, 1] = detected
        obs[:, 2] = np.minimum(ratio, MAX_RATIO)
        obs[:, 3] = np.minimum(np.log(np.maximum(phi / self.model.clean, 1.0)), MAX_LOG_ERROR)
        self._needs_reset = terminated | truncated
        infos = self._infos(
            phi,
            np.where(live, out["error"], self.model.clean),
            detected,
            np.where(live, out["p"], 0.0),
            np.where(live, out["statistic"], 0.0),
            np.where(live, out["threshold"], self._tau[:, 0]),
            np.where(live, out["kl"], 0.0),
        )
        return obs, reward, terminated, truncated, infos

    def _infos(self, phi, error, detected, p, statistic, threshold, kl) -> dict[str, np.ndarray]:
        info = {
            "phi": np.asarray(phi, dtype=np.float64),
            "error": np.asarray(error, dtype=np.float64),
            "step": self._state["k"].copy(),
            "alpha": self._alpha.copy(),
            "detected": np.asarray(detected, dtype=bool),
            "detection_probability": np.asarray(p, dtype=np.float64),
            "statistic": np.asarray(statistic, dtype=np.float64),
            "threshold": np.asarray(threshold, dtype=np.float64),
            "kl": np.asarray(kl, dtype=np.float64),
        }
        mask = np.ones(self.num_envs, dtype=bool)
        info.update({f"_{k}": mask for k in list(info)})
        return info


def make_vector(num_envs: int, **kwargs: Any) -> StealthDynamicVectorEnv:
    """Gymnasium ``vector_entry_point`` of ``"fdia_env/StealthDynamic-v0"``.

    Raises:
        ValueError: For ``backend``/``device`` other than numpy on the CPU, the defender's
            view, or a bad option.
    """
    backend, device = vector_options(kwargs, "dynamic stealth env")
    if backend != "numpy" or device not in (None, "cpu"):
        raise ValueError(
            f"backend={backend!r}, device={device!r}: the dynamic stealth env's native vector "
            "env runs numpy on the CPU (backend='numpy')"
        )
    return StealthDynamicVectorEnv(num_envs, **kwargs)
