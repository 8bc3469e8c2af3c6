"""Train a learner on a benchmark task for one seed and score it: one leaderboard row.

A stable-baselines3 algorithm (``MaskablePPO``, ``PPO``, ``A2C``, ``DQN``, ``SAC``) trains with
``train.py``'s default hyperparameters, updated by the ``hp`` given, on the task's env
(``task.make_env()``) for ``timesteps`` steps; ``torch-ppo`` trains on the task's torch vector
env with ``train.py``'s torch-ppo defaults updated by ``hp``, where ``num_envs`` (the members)
defaults to :func:`torch_envs`, so that even a short budget makes at least
:data:`TORCH_MIN_ITERATIONS` updates (one rollout is ``num_envs × n_steps`` env steps).
:func:`hyperparameter_names` lists what ``hp`` may set for each learner and
:func:`check_hyperparameters` checks it before any training. The trained policy is scored with
:func:`agents.bench.score.score_policy` on evaluation seed ``seed`` (the training seed), so three
seeds give three independently trained agents. A run that raises becomes a
:func:`failed_row`.
"""

from __future__ import annotations

import time
from typing import Any

from agents.bench.score import score_policy
from agents.leaderboard.rows import FAILED, OK

SB3 = ("MaskablePPO", "PPO", "A2C", "DQN", "SAC")
TORCH_PPO = "torch-ppo"
LEARNERS = (*SB3, TORCH_PPO)
TORCH_MAX_ENVS = 256
TORCH_MIN_ITERATIONS = 8


def torch_envs(timesteps: int, num_steps: int | None = None) -> int:
    """Members of torch-ppo's vector env for a budget: at most 256, at least 8 updates.

    Args:
        timesteps: The training budget in env steps.
        num_steps: Steps of each member per rollout (default: torch-ppo's, 12).

    >>> torch_envs(2048), torch_envs(20_000), torch_envs(10), torch_envs(2048, num_steps=4)
    (21, 208, 1, 64)
    """
    from agents.config import ALGO_DEFAULTS

    steps = ALGO_DEFAULTS[TORCH_PPO]["n_steps"] if num_steps is None else num_steps
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


def hyperparameter_names(algo: str) -> tuple[str, ...]:
    """What ``hp`` may set for ``algo``: its ``train.py`` hyperparameters.

    torch-ppo also takes ``num_envs``, the members of its vector env.

    >>> hyperparameter_names("torch-ppo")[-1], "buffer_size" in hyperparameter_names("PPO")
    ('num_envs', False)

    Raises:
        ValueError: For an algorithm that is not one of :data:`LEARNERS` (naming ``algo``).
    """
    from agents.config import ALGO_DEFAULTS

    if algo not in LEARNERS:
        raise ValueError(f"algo must be one of {', '.join(LEARNERS)}, got {algo!r}")
    names = tuple(ALGO_DEFAULTS[algo])
    return (*names, "num_envs") if algo == TORCH_PPO else names


def _torch_config(hp: dict[str, Any], timesteps: int) -> Any:
    """torch-ppo's :class:`agents.torch_ppo.TorchPPOConfig` for ``hp`` and the budget."""
    from agents.config import Hyperparameters, resolved_hyperparameters
    from agents.torch_ppo import TorchPPOConfig

    rest = {k: v for k, v in hp.items() if k != "num_envs"}
    resolved = resolved_hyperparameters(TORCH_PPO, Hyperparameters(**rest))
    num_envs = hp.get("num_envs", torch_envs(timesteps, resolved["n_steps"]))
    return TorchPPOConfig.from_hyperparameters(resolved, timesteps, num_envs)


def check_hyperparameters(
    algo: str, hp: dict[str, Any], timesteps: int = 1, option: str = "hp"
) -> None:
    """Raise unless ``hp`` are hyperparameters of ``algo`` with values it accepts.

    Args:
        algo: One of :data:`LEARNERS`.
        hp: Names of :func:`hyperparameter_names` to values.
        timesteps: The training budget (torch-ppo's members default to :func:`torch_envs`).
        option: How messages name ``hp`` (the runner's ``--hp``).

    Raises:
        ValueError: Naming ``option``, ``algo`` and the names it accepts for an unknown name,
            or naming ``option``, ``algo`` and the value's own error for a bad value.
    """
    names = hyperparameter_names(algo)
    unknown = sorted(set(hp) - set(names))
    if unknown:
        raise ValueError(
            f"{option} {', '.join(unknown)}: not a hyperparameter of {algo}; "
            f"{algo} takes {', '.join(names)}"
        )
    try:
        if algo == TORCH_PPO:
            _torch_config(hp, timesteps)
        else:
            from agents.config import Hyperparameters, algo_kwargs

            algo_kwargs(algo, Hyperparameters(**hp))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{option} for {algo}: {exc}") from None


def recorded_hyperparameters(algo: str, hp: dict[str, Any], timesteps: int) -> dict[str, Any]:
    """The row's ``hyperparameters``: ``hp`` as given (torch-ppo: with the ``num_envs`` used).

    >>> recorded_hyperparameters("torch-ppo", {}, 2048), recorded_hyperparameters("PPO", {}, 64)
    ({'num_envs': 21}, {})
    """
    if algo != TORCH_PPO:
        return dict(hp)
    return {**hp, "num_envs": _torch_config(hp, timesteps).num_envs}


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


def train_torch(
    task: Any, timesteps: int, seed: int, hp: dict[str, Any] | None = None
) -> tuple[Any, dict[str, int]]:
    """A torch-ppo policy trained on ``task``'s torch vector env (CPU), and what the run made.

    Args:
        task: The benchmark task.
        timesteps: The training budget in env steps.
        seed: The training seed.
        hp: ``train.py``'s torch-ppo hyperparameters over its defaults, and ``num_envs`` (the
            members; default :func:`torch_envs` of the budget and ``n_steps``).

    Returns:
        ``(policy, training)``: ``training`` gives the run's ``num_envs`` (members of the
        vector env), ``num_steps`` (steps of each per rollout), ``iterations`` (updates) and
        ``timesteps`` (env steps taken).
    """
    from agents.seeding import seed_everything
    from agents.torch_ppo import make_torch_env, train_torch_ppo

    config = _torch_config(dict(hp or {}), timesteps)
    seed_everything(seed, torch_threads=1)
    env = make_torch_env(task.env_id, config.num_envs, "cpu", **dict(task.env_kwargs))
    try:
        result = train_torch_ppo(env, config, seed=seed)
    finally:
        env.close()
    training = {
        "num_envs": int(env.num_envs),
        "num_steps": int(config.num_steps),
        "iterations": len(result.history),
        "timesteps": int(result.timesteps),
    }
    return result.policy, training


def learner_row(
    task: Any,
    algo: str,
    seed: int,
    timesteps: int,
    episodes: int | None = None,
    hp: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Train ``algo`` on ``task`` with ``seed`` and score it: a JSON row.

    ``hp`` updates ``train.py``'s default hyperparameters of ``algo``
    (:func:`hyperparameter_names`). The row holds the score
    (:meth:`agents.bench.score.Score.to_dict`), ``status`` ``"ok"``, the ``hyperparameters``
    (:func:`recorded_hyperparameters`), ``train_seconds`` and, for torch-ppo, ``training``
    (what :func:`train_torch` made).

    Raises:
        ValueError: For an algorithm that is not one of :data:`LEARNERS` (naming ``algo``),
            or bad ``hp`` (:func:`check_hyperparameters`).
    """
    hp = dict(hp or {})
    check_hyperparameters(algo, hp, timesteps)
    start = time.perf_counter()
    training: dict[str, int] | None = None
    if algo == TORCH_PPO:
        policy, training = train_torch(task, timesteps, seed, hp)
    else:
        policy = train_sb3(task, algo, timesteps, seed, hp)
    seconds = time.perf_counter() - start
    result = score_policy(
        task, policy, seeds=(seed,), episodes=episodes, agent=algo, description=algo
    )
    row = {
        **result.to_dict(),
        "method": algo,
        "kind": "learner",
        "status": OK,
        "seed": seed,
        "timesteps": timesteps,
        "hyperparameters": recorded_hyperparameters(algo, hp, timesteps),
        "train_seconds": round(seconds, 1),
    }
    if training is not None:
        row["training"] = training
    return row


def failed_row(
    task: Any,
    algo: str,
    seed: int,
    timesteps: int,
    hp: dict[str, Any],
    error: BaseException,
    seconds: float,
) -> dict[str, Any]:
    """The row of a run that raised ``error`` after ``seconds``: ``status`` ``"failed"``."""
    try:
        recorded = recorded_hyperparameters(algo, hp, timesteps)
    except (TypeError, ValueError):
        recorded = dict(hp)
    return {
        "task": task.name,
        "method": algo,
        "kind": "learner",
        "status": FAILED,
        "error": f"{type(error).__name__}: {error}",
        "seed": seed,
        "timesteps": timesteps,
        "hyperparameters": recorded,
        "train_seconds": round(seconds, 1),
    }
