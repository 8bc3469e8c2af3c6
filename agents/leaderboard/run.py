"""Train a learner on a benchmark task for one seed and score it: one leaderboard row.

A stable-baselines3 algorithm (``MaskablePPO``, ``PPO``, ``A2C``, ``DQN``, ``SAC``) trains with
``train.py``'s default hyperparameters on the task's env (``task.make_env()``) for
``timesteps`` steps; ``torch-ppo`` trains on the task's torch vector env with
:func:`torch_envs` members, so that even a short budget makes at least
:data:`TORCH_MIN_ITERATIONS` updates (one rollout is ``members × num_steps`` env steps). The
trained policy is
scored with :func:`agents.bench.score.score_policy` on evaluation seed ``seed`` (the training
seed), so three seeds give three independently trained agents.
"""

from __future__ import annotations

import time
from typing import Any

from agents.bench.score import score_policy

SB3 = ("MaskablePPO", "PPO", "A2C", "DQN", "SAC")
TORCH_PPO = "torch-ppo"
LEARNERS = (*SB3, TORCH_PPO)
TORCH_MAX_ENVS = 256
TORCH_MIN_ITERATIONS = 8


def torch_envs(timesteps: int) -> int:
    """Members of torch-ppo's vector env for a budget: at most 256, at least 8 updates.

    >>> torch_envs(2048), torch_envs(20_000), torch_envs(10)
    (21, 208, 1)
    """
    from agents.torch_ppo import TorchPPOConfig

    steps = TorchPPOConfig().num_steps
    return max(1, min(TORCH_MAX_ENVS, int(timesteps) // (steps * TORCH_MIN_ITERATIONS)))


def applicable(task: Any, algo: str) -> bool:
    """Whether ``algo`` fits ``task``'s action space (the algorithms ``train.py`` offers)."""
    from agents.registry import by_gym_id

    entry = by_gym_id(task.env_id)
    if algo == TORCH_PPO:  # a native vector env on torch, and actions its policy fits
        from gymnasium import spaces

        from fdia_env.registration import torch_ids

        if task.entry_point is not None or task.env_id not in torch_ids():
            return False
        from agents.torch_ppo import make_torch_env

        try:  # the task's options may need a model without a torch implementation
            env = make_torch_env(task.env_id, 1, "cpu", **dict(task.env_kwargs))
            try:
                env.reset(seed=0)  # (a sensor game over more than 62 sensors refuses here)
            finally:
                env.close()
        except (TypeError, ValueError):
            return False
        with task.make_env() as env:
            space = env.action_space
        return isinstance(space, spaces.Discrete) or (
            isinstance(space, spaces.Box) and len(space.shape) == 1
        )
    if entry is None:
        return algo in ("PPO", "A2C")
    if algo not in entry.algorithms:
        return False
    if algo in ("SAC", "DQN"):  # one kind of action space; the task's options may change it
        from gymnasium import spaces

        with task.make_env() as env:
            space = env.action_space
        return isinstance(space, spaces.Box if algo == "SAC" else spaces.Discrete)
    return True


def train_sb3(
    task: Any, algo: str, timesteps: int, seed: int, hp: dict[str, Any] | None = None
) -> Any:
    """An SB3 ``algo`` model trained on ``task`` (``train.py``'s defaults updated by ``hp``)."""
    from stable_baselines3.common.monitor import Monitor
    from stable_baselines3.common.vec_env import DummyVecEnv

    from agents.algos import build_model
    from agents.config import Hyperparameters, algo_kwargs
    from agents.seeding import seed_everything

    seed_everything(seed, torch_threads=1)
    vec = DummyVecEnv([lambda: Monitor(task.make_env())])
    try:
        model = build_model(algo, vec, algo_kwargs(algo, Hyperparameters(**(hp or {}))), seed)
        model.learn(timesteps)
    finally:
        vec.close()
    return model


def train_torch(task: Any, timesteps: int, seed: int, num_envs: int | None = None) -> Any:
    """A torch-ppo policy trained on ``task``'s torch vector env (CPU).

    ``num_envs`` defaults to :func:`torch_envs` of the budget.
    """
    from agents.seeding import seed_everything
    from agents.torch_ppo import TorchPPOConfig, make_torch_env, train_torch_ppo

    seed_everything(seed, torch_threads=1)
    num_envs = torch_envs(timesteps) if num_envs is None else num_envs
    env = make_torch_env(task.env_id, num_envs, "cpu", **dict(task.env_kwargs))
    try:
        config = TorchPPOConfig(total_timesteps=timesteps, num_envs=num_envs)
        return train_torch_ppo(env, config, seed=seed).policy
    finally:
        env.close()


def check_hyperparameters(hp: dict[str, Any]) -> None:
    """Raise unless ``hp`` are valid :class:`agents.config.Hyperparameters` fields.

    Raises:
        ValueError: Naming ``hp`` and the valid fields, or the field's own error.
    """
    from dataclasses import fields

    from agents.config import Hyperparameters

    valid = [f.name for f in fields(Hyperparameters)]
    unknown = sorted(set(hp) - set(valid))
    if unknown:
        raise ValueError(f"hp: unknown hyperparameters {unknown}; valid: {', '.join(valid)}")
    Hyperparameters(**hp)


def learner_row(
    task: Any,
    algo: str,
    seed: int,
    timesteps: int,
    episodes: int | None = None,
    hp: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Train ``algo`` on ``task`` with ``seed`` and score it: a JSON row.

    ``hp`` updates ``train.py``'s default hyperparameters of the stable-baselines3 learners.

    Raises:
        ValueError: For an algorithm that is not one of :data:`LEARNERS` (naming ``algo``),
            or bad ``hp``.
    """
    if algo not in LEARNERS:
        raise ValueError(f"algo must be one of {', '.join(LEARNERS)}, got {algo!r}")
    hp = dict(hp or {})
    check_hyperparameters(hp)
    start = time.perf_counter()
    if algo == TORCH_PPO:
        policy = train_torch(task, timesteps, seed)
    else:
        policy = train_sb3(task, algo, timesteps, seed, hp)
    seconds = time.perf_counter() - start
    result = score_policy(
        task, policy, seeds=(seed,), episodes=episodes, agent=algo, description=algo
    )
    return {
        **result.to_dict(),
        "method": algo,
        "kind": "learner",
        "seed": seed,
        "timesteps": timesteps,
        "hyperparameters": {"num_envs": torch_envs(timesteps)} if algo == TORCH_PPO else hp,
        "train_seconds": round(seconds, 1),
    }
