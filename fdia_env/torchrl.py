"""TorchRL's native face of the native vector env: an ``EnvBase`` batch-locked at B.

``FdiaTorchRLEnv("fdia_env/SparseAttack-v0", num_envs=B, backend="torch", device="cuda")``
builds the native vector env (:class:`~fdia_env.vector.env.FdiaVectorEnv`) with Gymnasium's
``SAME_STEP`` autoreset and serves it to TorchRL without a host round trip on the torch backend:
actions come in as tensors on the env's device and every output is a tensor there. On the numpy
backend (``backend="numpy"``, CPU) the same specs hold; the arrays are converted on the way in and
out.

Specs come from the env's Gymnasium spaces, with the batch (B,) in front:

- ``"observation"``: ``Bounded`` float32 (B, d), the single env's features;
- ``"action_mask"`` (masked players only: the sparse attack, also in its sequential format
  ``action="sequential"``, whose native vector env
  :class:`~fdia_env.vector.sequential.SequentialVectorEnv` this serves the same way, and the
  sensor game's sequential format,
  :class:`~fdia_env.vector.sequential_game.SequentialGameVectorEnv`): bool
  (B, A), True where legal, the key TorchRL's ``ActionMask`` transform and
  ``MaskedCategorical`` read;
- ``"phi"``: float64 (B,), the estimation-error measure Φ after the step;
- ``"action"``: ``Categorical`` int64 (B,) for a ``Discrete`` space (index encoding),
  ``Bounded`` (B, k) for a ``Box``, ``Binary`` / ``MultiCategorical`` for ``MultiBinary`` /
  ``MultiDiscrete``;
- ``"reward"``: float32 (B, 1); ``"done"``, ``"terminated"``, ``"truncated"``: bool (B, 1).

Autoreset: the vector env restarts a member in the step that ends its episode; the step returns
the member's last observation under ``"next"`` and the restarted one is what the following
partial reset (``"_reset"`` True for the members that finished, what collectors send) returns.
A reset of members whose episode is still running is refused (a full ``reset()`` restarts all);
truncate episodes with ``max_episode_steps=``. ``set_seed(s)`` seeds the next full reset
(member i of the numpy backend gets ``s + i``; the torch backend seeds its device generator).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode

try:
    import torch
    from tensordict import TensorDict, TensorDictBase
    from torchrl.data import Binary, Bounded, Categorical, Composite, MultiCategorical, Unbounded
    from torchrl.envs import EnvBase
except ImportError as exc:  # pragma: no cover - the [clients] extra is installed in CI
    raise ImportError(
        "fdia_env.torchrl needs TorchRL: pip install 'fdia-env[clients]' (torchrl>=0.14)"
    ) from exc

from fdia_env.vector.env import FdiaVectorEnv
from fdia_env.vector.sequential import SequentialVectorEnv
from fdia_env.vector.sequential_game import SequentialGameVectorEnv

__all__ = ["FdiaTorchRLEnv", "action_spec_of"]


def action_spec_of(space: spaces.Space, batch: int, device: torch.device) -> Any:
    """The TorchRL spec of a Gymnasium action ``space`` with the batch (``batch``,) in front.

    Raises:
        TypeError: For a space other than Discrete, Box, MultiBinary or MultiDiscrete.
    """
    if isinstance(space, spaces.Discrete):
        if int(space.start) != 0:
            raise TypeError(f"a Discrete action space must start at 0 for TorchRL, got {space}")
        return Categorical(int(space.n), shape=(batch,), dtype=torch.int64, device=device)
    if isinstance(space, spaces.Box):
        low = torch.as_tensor(np.broadcast_to(space.low, space.shape).copy(), device=device)
        high = torch.as_tensor(np.broadcast_to(space.high, space.shape).copy(), device=device)
        dtype = torch.float32 if space.dtype == np.float32 else torch.float64
        return Bounded(
            low.expand(batch, *space.shape).to(dtype),
            high.expand(batch, *space.shape).to(dtype),
            shape=(batch, *space.shape),
            dtype=dtype,
            device=device,
        )
    if isinstance(space, spaces.MultiBinary):
        n = int(np.prod(space.shape))
        return Binary(n, shape=(batch, *space.shape), dtype=torch.int64, device=device)
    if isinstance(space, spaces.MultiDiscrete):
        return MultiCategorical(
            torch.as_tensor(space.nvec, dtype=torch.int64),
            shape=(batch, *space.shape),
            dtype=torch.int64,
            device=device,
        )
    raise TypeError(
        f"no TorchRL spec for the action space {space}: Discrete, Box, MultiBinary or "
        "MultiDiscrete are supported"
    )


class FdiaTorchRLEnv(EnvBase):
    """A registered fdia_env id as a TorchRL env of batch size (B,), numpy or torch backend.

    Args:
        env: A Gymnasium id of fdia_env (``"fdia_env/SparseAttack-v0"``; the spawn form
            ``"fdia_env:fdia_env/SparseAttack-v0"`` is accepted) or a
            :class:`~fdia_env.vector.env.FdiaVectorEnv` built with
            ``autoreset_mode=AutoresetMode.SAME_STEP``.
        num_envs: B (with an id only).
        backend: ``"torch"`` (default) or ``"numpy"`` (with an id only).
        device: torch only: ``"cpu"`` (default) or ``"cuda"`` / ``"cuda:<i>"``.
        **kwargs: The env's options (``scenario``, ``max_episode_steps``, ``opponent``, ...),
            as for ``gymnasium.make_vec``.

    Raises:
        ValueError: For an id fdia_env does not register, options given with an env instance,
            or an env instance that does not use SAME_STEP autoreset (and every error of
            ``gymnasium.make_vec`` for the id's options).
        TypeError: For ``env`` that is neither an id nor a native vector env.
    """

    def __init__(
        self,
        env: str | FdiaVectorEnv,
        num_envs: int = 1,
        *,
        backend: str = "torch",
        device: Any = None,
        **kwargs: Any,
    ) -> None:
        venv = _vector_env(env, num_envs, backend, device, kwargs)
        self.venv = venv
        self._torch = venv.backend == "torch"
        dev = torch.device(venv.device) if self._torch else torch.device("cpu")
        B = venv.num_envs
        super().__init__(device=dev, batch_size=torch.Size([B]))
        box = venv.single_observation_space
        self._masked = isinstance(venv.parallel.observation_space(venv.agent), spaces.Dict)
        observation = {
            "observation": Bounded(
                torch.as_tensor(np.broadcast_to(box.low, (B, *box.shape)).copy()),
                torch.as_tensor(np.broadcast_to(box.high, (B, *box.shape)).copy()),
                shape=(B, *box.shape),
                dtype=torch.float32,
                device=dev,
            ),
            "phi": Unbounded(shape=(B,), dtype=torch.float64, device=dev),
        }
        if self._masked:
            n = int(venv.single_action_space.n)
            observation["action_mask"] = Binary(n, shape=(B, n), dtype=torch.bool, device=dev)
        self.observation_spec = Composite(observation, shape=(B,), device=dev)
        self.action_spec = action_spec_of(venv.single_action_space, B, dev)
        self.reward_spec = Unbounded(shape=(B, 1), dtype=torch.float32, device=dev)
        self.done_spec = Composite(
            {
                key: Categorical(2, shape=(B, 1), dtype=torch.bool, device=dev)
                for key in ("done", "terminated", "truncated")
            },
            shape=(B,),
            device=dev,
        )
        self._seed: int | None = None
        self._current: TensorDictBase | None = None  # every member's observation now
        self._restarted: torch.Tensor | None = None  # members restarted at the last step

    # --- TorchRL's EnvBase --------------------------------------------------------------------
    def _set_seed(self, seed: int | None) -> None:
        """Seed the next full reset."""
        self._seed = None if seed is None else int(seed)

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs: Any) -> TensorDictBase:
        reset = None if tensordict is None else tensordict.get("_reset", None)
        if reset is not None and self._current is not None and not bool(reset.all()):
            wanted = reset.reshape(self.batch_size).to(self.device)
            running = wanted & ~self._restarted
            if bool(running.any()):
                members = torch.nonzero(running).flatten().tolist()
                raise ValueError(
                    f"_reset asks to restart members {members[:8]} whose episode is still "
                    "running; fdia_env's TorchRL env restarts a member when its episode ends "
                    "(call reset() without '_reset' to restart every member, and truncate "
                    "episodes with max_episode_steps=)"
                )
            return self._current.clone()
        obs, info = self.venv.reset(seed=self._seed)
        self._seed = None
        self._restarted = torch.zeros(self.batch_size, dtype=torch.bool, device=self.device)
        self._current = self._observation(obs, info)
        return self._current.clone()

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        action = tensordict.get("action")
        if not self._torch:
            action = action.detach().cpu().numpy()
        obs, reward, terminated, truncated, info = self.venv.step(action)
        current = self._observation(obs, info)
        term = self._tensor(terminated, torch.bool)
        trunc = self._tensor(truncated, torch.bool)
        ended = term | trunc
        out = current.clone()
        if bool(ended.any()):  # the members' last observation, before SAME_STEP restarted them
            final = self._observation(_final_obs(info, self.venv), info["final_info"])
            out = _where(ended, final, current)
        self._current, self._restarted = current, ended
        out.set("reward", self._tensor(reward, torch.float32).reshape(*self.batch_size, 1))
        out.set("terminated", term.reshape(*self.batch_size, 1))
        out.set("truncated", trunc.reshape(*self.batch_size, 1))
        out.set("done", ended.reshape(*self.batch_size, 1))
        return out

    # --- conversions ----------------------------------------------------------------------------
    def _tensor(self, value: Any, dtype: torch.dtype) -> torch.Tensor:
        if isinstance(value, torch.Tensor):
            return value.to(device=self.device, dtype=dtype)
        return torch.as_tensor(np.asarray(value), device=self.device).to(dtype)

    def _observation(self, obs: Any, info: dict[str, Any]) -> TensorDictBase:
        values = {
            "observation": self._tensor(obs, torch.float32),
            "phi": self._tensor(info["phi"], torch.float64),
        }
        if self._masked:
            values["action_mask"] = self._tensor(info["action_mask"], torch.bool)
        return TensorDict(values, batch_size=self.batch_size, device=self.device)

    def close(self, *, raise_if_closed: bool = True) -> None:
        """Close the vector env."""
        self.venv.close()
        super().close(raise_if_closed=raise_if_closed)


def _vector_env(
    env: Any, num_envs: int, backend: str, device: Any, kwargs: dict[str, Any]
) -> FdiaVectorEnv | SequentialVectorEnv | SequentialGameVectorEnv:
    """The SAME_STEP native vector env of an id, or the given one after its checks."""
    if isinstance(env, FdiaVectorEnv | SequentialVectorEnv | SequentialGameVectorEnv):
        if kwargs or num_envs != 1 or backend != "torch" or device is not None:
            raise ValueError(
                "num_envs, backend, device and env options apply to an id only; got them with "
                "an FdiaVectorEnv (build it with those options instead)"
            )
        if env.autoreset_mode != AutoresetMode.SAME_STEP:
            raise ValueError(
                "env must use autoreset_mode=AutoresetMode.SAME_STEP for TorchRL, got "
                f"{env.autoreset_mode} (or pass the id and let FdiaTorchRLEnv build it)"
            )
        return env
    if not isinstance(env, str):
        raise TypeError(
            f"env must be an fdia_env Gymnasium id or an FdiaVectorEnv, got {type(env).__name__}"
        )
    import fdia_env.registration as registration

    registration.register_envs()
    env_id = env.removeprefix("fdia_env:")
    ids = sorted(registration.GYM_IDS)
    if env_id not in ids:
        raise ValueError(f"env must be one of {', '.join(ids)}, got {env!r}")
    module, agent = registration.GYM_IDS[env_id]
    entry = next(e for e in registration.ENVS.values() if e.module == module)
    if entry.vector != registration.VECTOR_ENTRY_POINT or not entry.has_vector(agent):
        raise ValueError(
            f"env {env_id!r} has no native vector env of the Kalman-filter engine, which "
            "FdiaTorchRLEnv wraps; use TorchRL's GymEnv (or GymWrapper on gymnasium.make_vec) "
            f"for it. FdiaTorchRLEnv serves {', '.join(_engine_ids(registration))}"
        )
    if "autoreset_mode" in kwargs or "vectorization_mode" in kwargs:
        raise ValueError(
            "autoreset_mode and vectorization_mode are set by FdiaTorchRLEnv (SAME_STEP, the "
            "native vector env); remove them"
        )
    venv = gym.make_vec(
        env_id,
        num_envs=num_envs,
        vectorization_mode="vector_entry_point",
        autoreset_mode=AutoresetMode.SAME_STEP,
        backend=backend,
        device=device,
        **kwargs,
    )
    if not isinstance(
        venv, FdiaVectorEnv | SequentialVectorEnv | SequentialGameVectorEnv
    ):  # no batched implementation
        raise ValueError(f"{env_id} has no native vector env; TorchRL's GymEnv serves it")
    return venv


def _engine_ids(registration: Any) -> list[str]:
    """The Gymnasium ids whose view has the engine's native vector env (what this wraps)."""
    return [
        env_id
        for e in registration.ENVS.values()
        if e.vector == registration.VECTOR_ENTRY_POINT
        for agent, env_id in e.views.items()
        if e.has_vector(agent)
    ]


def _final_obs(info: dict[str, Any], venv: FdiaVectorEnv) -> Any:
    """The (B, d) last observations of the members that ended (zeros elsewhere)."""
    final = info["final_obs"]
    if venv.backend == "torch":
        return final
    rows = np.zeros((venv.num_envs, *venv.single_observation_space.shape), dtype=np.float32)
    for i in np.flatnonzero(info["_final_obs"]):
        rows[i] = final[i]
    return rows


def _where(mask: torch.Tensor, a: TensorDictBase, b: TensorDictBase) -> TensorDictBase:
    """Entry by entry: ``a`` for the members of the (B,) ``mask``, ``b`` elsewhere."""
    out = b.clone()
    for key in b.keys():
        value = b.get(key)
        m = mask.reshape(-1, *[1] * (value.dim() - 1))
        out.set(key, torch.where(m, a.get(key), value))
    return out
