"""stable-baselines3 ``VecEnv`` adapter for the native vector envs.

>>> from fdia_env.vector.sb3 import make_sb3_vec_env
>>> venv = make_sb3_vec_env("fdia_env/SparseAttack-v0", num_envs=8)
>>> venv.reset().shape
(8, 5)

SB3 resets finished environments in the same step and keeps their last observation in
``infos[i]["terminal_observation"]``; the adapter runs :class:`FdiaVectorEnv` in
``AutoresetMode.SAME_STEP`` to provide exactly that. ``infos[i]`` holds member i's info of the
step, as a single env's ``step`` gives it (a finished member's from ``final_info``, not its
reset's), and ``reset_infos`` the reset's, as SB3's ``DummyVecEnv`` does.
``env_method("action_masks")`` returns the per-env masks, which is how sb3-contrib's
``MaskablePPO`` reads them.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices

from fdia_env.vector.env import FdiaVectorEnv


class SB3VecEnv(VecEnv):
    """Present a :class:`FdiaVectorEnv` (in SAME_STEP autoreset mode) as an SB3 ``VecEnv``."""

    def __init__(self, venv: FdiaVectorEnv) -> None:
        if venv.metadata["autoreset_mode"] != AutoresetMode.SAME_STEP:
            raise ValueError("venv must use autoreset_mode=AutoresetMode.SAME_STEP for SB3")
        self.venv = venv
        super().__init__(venv.num_envs, venv.single_observation_space, venv.single_action_space)
        self._actions: np.ndarray | None = None

    def reset(self) -> np.ndarray:
        """Reset all envs with the seeds given by :meth:`seed` (if any)."""
        seeds = None if all(s is None for s in self._seeds) else list(self._seeds)
        if seeds is not None and any(s is None for s in seeds):
            raise ValueError("seed every env or none: got a partial list of seeds")
        obs, infos = self.venv.reset(seed=seeds)
        self._reset_seeds()
        self._reset_options()
        self.reset_infos = split_infos(infos, self.num_envs)
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        """Store the actions."""
        self._actions = np.asarray(actions)

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict]]:
        """Step the batch: each env's info of the step (``terminal_observation`` at an end).

        A finished env's info is its last step's (``final_info``) and its reset's goes in
        ``reset_infos``, as in SB3's ``DummyVecEnv``.
        """
        obs, reward, terminated, truncated, infos = self.venv.step(self._actions)
        dones = terminated | truncated
        cut = {"TimeLimit.truncated": (truncated & ~terminated).tolist()}
        info_list = split_infos(infos, self.num_envs, cut)
        if "final_obs" in infos:
            final = split_infos(infos["final_info"], self.num_envs, cut)
            for i in np.flatnonzero(infos["_final_obs"]).tolist():
                del info_list[i]["TimeLimit.truncated"]
                self.reset_infos[i] = info_list[i]
                info_list[i] = final[i]
                final[i]["terminal_observation"] = infos["final_obs"][i]
        return obs, reward.astype(np.float32), dones, info_list

    def close(self) -> None:
        """Nothing to release."""

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """The attribute of the shared vector env, once per index."""
        return [getattr(self.venv, attr_name)] * len(self._get_indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set the attribute on the shared vector env."""
        setattr(self.venv, attr_name, value)

    def env_method(
        self, method_name: str, *args: Any, indices: VecEnvIndices = None, **kwargs: Any
    ) -> list[Any]:
        """``action_masks`` per env; other methods are called once on the vector env."""
        idx = list(self._get_indices(indices))
        if method_name == "action_masks":
            masks = self.venv.action_masks()
            return [masks[i] for i in idx]
        result = getattr(self.venv, method_name)(*args, **kwargs)
        return [result] * len(idx)

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        """No per-env Gymnasium wrappers exist."""
        return [False] * len(self._get_indices(indices))

    def _get_indices(self, indices: VecEnvIndices) -> Iterable[int]:
        if indices is None:
            return range(self.num_envs)
        if isinstance(indices, int):
            return [indices]
        return indices


def split_infos(
    infos: dict[str, Any], num_envs: int, extra: dict[str, list[Any]] | None = None
) -> list[dict[str, Any]]:
    """One info dict per member from a Gymnasium vector env's batched ``infos``.

    Member i gets ``key: infos[key][i]`` for every key whose mask ``infos["_" + key]`` is set at
    i, a Python scalar for a one-dimensional entry (as a single env gives it) and a row of the
    array otherwise; ``final_obs`` / ``final_info`` (and their masks) are left out.

    Args:
        infos: The batched infos (numpy arrays or dicts of them, each with its ``"_" + key``
            mask).
        num_envs: B.
        extra: More entries every member gets, ``key: (B,) values``.

    Returns:
        A list of B dicts.
    """
    full: dict[str, list[Any]] = {}  # the keys every member has
    partial: list[tuple[str, list[Any], np.ndarray]] = []
    for key, value in infos.items():
        if key.startswith("_") or key in ("final_obs", "final_info"):
            continue
        if isinstance(value, dict):
            column = split_infos(value, num_envs)
        elif isinstance(value, np.ndarray) and value.ndim == 1:
            column = value.tolist()
        else:
            column = list(value)
        mask = infos.get("_" + key)
        if mask is None or mask.all():
            full[key] = column
            continue
        partial.append((key, column, mask))
    full.update(extra or {})
    keys = tuple(full)
    out = [dict(zip(keys, row, strict=True)) for row in zip(*full.values(), strict=True)]
    if not keys:
        out = [{} for _ in range(num_envs)]
    for key, column, mask in partial:
        for i in np.flatnonzero(mask).tolist():
            out[i][key] = column[i]
    return out


def make_sb3_vec_env(env_id: str, num_envs: int, **kwargs: Sequence[Any] | Any) -> SB3VecEnv:
    """``gymnasium.make_vec(env_id, num_envs, vectorization_mode="vector_entry_point")`` for SB3."""
    venv = gym.make_vec(
        env_id,
        num_envs=num_envs,
        vectorization_mode="vector_entry_point",
        autoreset_mode=AutoresetMode.SAME_STEP,
        **kwargs,
    )
    return SB3VecEnv(venv)
