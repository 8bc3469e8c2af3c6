"""``train.py attacker|defender --task NAME``: train the scored player of a benchmark task.

The env is built exactly as the task builds it (:meth:`fdia_env.tasks.Task.make_env`: its
Gymnasium id, options and, for the system family, its entry point); the learners that fit the
task env's action space are those of :func:`algorithms_for` (``--algo``: stable-baselines3's
and torch-ppo, which trains on :func:`task_torch_env`) and :func:`rllib_fits`
(``--backend rllib``). A ``--resume`` of a task run keeps its task (:func:`check_resumed_task`)
and rebuilds the task's env, never the options config.json records as text. At the end the run
folder is scored on the task by :func:`agents.bench.score.score`, the code of ``python -m
agents.bench score``, with its default seeds and episodes, so that both give the same number on
the same folder.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from agents.config import TORCH_PPO, is_torch_ppo
from agents.registry import (
    ALGORITHMS,
    BOX_ALGORITHMS,
    DISCRETE_ALGORITHMS,
    MASKED_ALGORITHMS,
    Reference,
    Trainable,
)

# the options of the attacker/defender commands that would change the task's env, by the
# TrainConfig field, with their default (a value other than it is refused under --task; --env
# too, whose default is the command's)
TASK_FIXED = {"scenario": None, "env_kwargs": {}, "opponent": "uniform"}
SCORE_SEEDS = 3  # python -m agents.bench score's default --seeds
# torch-ppo's default --num-envs on a task without a native torch vector env: copies of the
# task's env stepped on the host (agents.torch_vector), not a batch on the device
TASK_COPIES = 16
BACKENDS = ("sb3", "rllib")  # the --backend values a task run takes


def option(name: str) -> str:
    """The command-line spelling of a TrainConfig field (``env_kwargs`` → ``--env-kwargs``)."""
    return "--" + name.replace("_", "-")


def resolve_task(name: str, command: str) -> Any:
    """The task ``name`` for the ``command`` (``attacker`` or ``defender``).

    Raises:
        ValueError: Naming ``--task``: an unknown name (with close names and how to list the
            tasks), a game task, or a task whose scored player is not ``command``.
    """
    from fdia_env import tasks

    try:
        task = tasks.get(name)
    except ValueError as exc:
        raise ValueError(
            f'--task: {exc}; list them with python -c "from fdia_env import tasks; '
            'print(*tasks.names(), sep=chr(10))"'
        ) from None
    if task.is_game:
        raise ValueError(
            f"--task {name} is a game task (scored by exploitability): train both players "
            f"with train.py game --task {name}"
        )
    if task.player != command:
        raise ValueError(
            f"--task {name} scores the {task.player}, not the {command}: use "
            f"train.py {task.player} --task {name}"
        )
    return task


def check_task_options(cfg: Any, default_envs: tuple[str, ...]) -> None:
    """Raise unless ``cfg`` leaves every option that would change the task's env unset.

    ``default_envs``: the values of ``--env`` that mean it was not given (the command's
    default). ``--resume`` and ``--backend rllib`` are accepted (the drivers check the rest).

    Raises:
        ValueError: Naming the option (``--env``, ``--scenario``, ``--env-kwargs``,
            ``--opponent``, ``--num-envs``, ``--backend``).
    """
    given = [name for name, default in TASK_FIXED.items() if getattr(cfg, name) != default]
    if cfg.env not in default_envs:
        given.insert(0, "env")
    if given:
        raise ValueError(
            f"{option(given[0])} cannot be combined with --task {cfg.task}: the task fixes its "
            "env and options (drop the option, or train without --task)"
        )
    if cfg.num_envs is not None and not is_torch_ppo(cfg.algo):
        raise ValueError(
            f"--num-envs applies to --algo torch-ppo only with --task {cfg.task} (the "
            "stable-baselines3 learners train on one env of the task, RLlib on its own)"
        )
    if cfg.run.backend not in BACKENDS:
        raise ValueError(
            f"--backend {cfg.run.backend} is not supported with --task; use one of "
            f"{', '.join(BACKENDS)}"
        )


def torch_ppo_fits(space: gym.Space) -> bool:
    """Whether torch-ppo's policy fits an action space: ``Discrete`` or a bounded 1-D ``Box``."""
    if isinstance(space, spaces.Discrete):
        return True
    return (
        isinstance(space, spaces.Box)
        and len(space.shape) == 1
        and bool(np.all(np.isfinite(space.low)) and np.all(np.isfinite(space.high)))
    )


def rllib_fits(space: gym.Space) -> bool:
    """Whether RLlib PPO (``--backend rllib``) fits an action space: ``Discrete``, float ``Box``.

    RLlib's catalog has no distribution for ``MultiBinary`` actions nor for an integer ``Box``.
    """
    if isinstance(space, spaces.Discrete):
        return True
    return isinstance(space, spaces.Box) and np.issubdtype(space.dtype, np.floating)


def algorithms_for(space: gym.Space) -> tuple[str, ...]:
    """The ``--algo`` learners that fit an action space (the default first).

    stable-baselines3's (MaskablePPO first on ``Discrete`` actions, SAC on ``Box``, PPO on
    ``MultiBinary``), then torch-ppo where :func:`torch_ppo_fits`.
    """
    if isinstance(space, spaces.Discrete):
        sb3: tuple[str, ...] = MASKED_ALGORITHMS
    elif isinstance(space, spaces.Box):
        sb3 = BOX_ALGORITHMS
    elif isinstance(space, spaces.MultiBinary | spaces.MultiDiscrete):
        sb3 = tuple(a for a in DISCRETE_ALGORITHMS if a != "DQN")
    else:
        return ()
    return (*sb3, TORCH_PPO) if torch_ppo_fits(space) else sb3


def learners_for(space: gym.Space) -> str:
    """The learners that fit an action space as one phrase, for the errors that list them."""
    rllib = ", and --backend rllib (PPO)" if rllib_fits(space) else ""
    return f"--algo {', '.join(algorithms_for(space))}{rllib}"


def has_native_torch_env(task: Any) -> bool:
    """Whether the task's env has a native torch vector env (else torch-ppo steps copies)."""
    from fdia_env.registration import torch_ids

    return task.entry_point is None and task.env_id in torch_ids()


def task_torch_env(
    task: Any, env_kwargs: dict[str, Any], num_envs: int, device: str
) -> gym.vector.VectorEnv:
    """The torch vector env torch-ppo trains on for ``task`` (``env_kwargs``: the task's).

    The env's native torch vector env (``backend="torch"``, the task's options) where it has
    one (:func:`has_native_torch_env`), else ``num_envs`` copies of the task's env
    (:class:`agents.torch_vector.TorchVectorOf`): the system family, whose env is an entry
    point of its own, and the views without a native vector env.
    """
    if has_native_torch_env(task):
        from agents.torch_ppo import make_torch_env

        return make_torch_env(task.env_id, num_envs, device, **env_kwargs)
    from agents.torch_vector import TorchVectorOf
    from fdia_env.tasks.task import make_pinned

    return TorchVectorOf(
        lambda: make_pinned(task.env_id, task.entry_point, env_kwargs), num_envs, device
    )


def run_env_name(task_name: str) -> str:
    """The run folder's env part of a task run: ``task-sparse-ch4-position-v0``."""
    return "task-" + task_name.replace("/", "-")


def plain_kwargs(env_kwargs: Any) -> dict[str, Any]:
    """The task's env options as config.json records them (objects as their text)."""
    return json.loads(json.dumps(dict(env_kwargs), default=str))


@dataclass(frozen=True)
class TaskEntry(Trainable):
    """The learning player of a task, as the drivers use a registry entry.

    Attributes:
        task: The :class:`fdia_env.tasks.Task`.
        action_space: The task env's action space (what the learners must fit).
    """

    task: Any = None
    action_space: Any = None

    @property
    def gym_id(self) -> str:
        """The task's Gymnasium id."""
        return self.task.env_id

    def make_env(self, env_kwargs: dict[str, Any]) -> gym.Env:
        """The task's env with ``env_kwargs`` (the task's own)."""
        from fdia_env.tasks.task import make_pinned

        return make_pinned(self.task.env_id, self.task.entry_point, env_kwargs)

    def reference_of(self, env: gym.Env) -> Reference | None:
        """The task's stored optimum (or best known value) as the run's reference."""
        best = self.task.references.optimum
        objective = self.task.references.objective
        return Reference(
            value=float(best.value),
            name=f"{best.name} (task)",
            objective="logdet" if objective == "logdet" else "trace",
            exact=bool(best.certified),
            cost=float(best.value) < 0,
            bound=None if best.certified else best.bound,
        )


def task_entry(cfg: Any) -> TaskEntry:
    """The :class:`TaskEntry` of ``cfg.task`` for ``cfg.agent``, its learners fitted.

    Raises:
        ValueError: As :func:`resolve_task`; for a task env whose actions no learner fits.
    """
    task = resolve_task(cfg.task, cfg.agent)
    env = task.make_env()
    try:
        space = env.action_space
    finally:
        env.close()
    algorithms = algorithms_for(space)
    if not algorithms:
        raise ValueError(f"--task {task.name}: no learner fits its action space {space}")
    return TaskEntry(
        env=run_env_name(task.name),
        agent=cfg.agent,
        scenarios={"task": {}},
        algorithms=algorithms,
        reference=None,
        masked="MaskablePPO" in algorithms,
        task=task,
        action_space=space,
    )


def _key(algo: str) -> str:
    return algo.replace("_", "").replace("-", "").lower()


def task_algorithm(entry: TaskEntry, algo: str | None) -> str:
    """``--algo`` checked against the task's action space (None: the first that fits).

    Raises:
        ValueError: Naming ``--algo``, the task, its action space and the learners that fit
            it (:func:`learners_for`).
    """
    if algo is None:
        return entry.algorithms[0]
    for name in entry.algorithms:
        if _key(name) == _key(algo):
            return name
    known = _key(algo) in {_key(a) for a in (*ALGORITHMS, TORCH_PPO)}
    what = "does not fit the action space of" if known else "is no learner for"
    raise ValueError(
        f"--algo {algo!r} {what} task {entry.task.name} ({entry.action_space}); learners that "
        f"fit: {learners_for(entry.action_space)}"
    )


def check_rllib_fits(entry: TaskEntry) -> None:
    """Raise unless RLlib PPO (``--backend rllib``) fits the task's action space.

    Raises:
        ValueError: Naming ``--backend rllib``, the task, its action space and the learners
            that fit it.
    """
    if not rllib_fits(entry.action_space):
        raise ValueError(
            f"--backend rllib (PPO) does not fit the action space of task {entry.task.name} "
            f"({entry.action_space}); learners that fit: {learners_for(entry.action_space)} "
            "(--backend sb3)"
        )


def matching_task(gym_id: str, env_kwargs: dict[str, Any], agent: str) -> Any:
    """The single-player task whose env a run without ``--task`` trained on, or None.

    A task matches when it scores ``agent``, names the run's scenario and
    :func:`agents.bench.agents.check_trained_on` accepts the run's env id and options (another
    version of the sparse attack that builds the same env included).
    """
    from agents.bench.agents import check_trained_on
    from fdia_env import tasks

    for name in tasks.names():
        task = tasks.get(name)
        if task.is_game or task.player != agent:
            continue
        if task.env_kwargs.get("scenario") != env_kwargs.get("scenario"):
            continue
        try:
            check_trained_on("run", gym_id, env_kwargs, task)
        except (ValueError, TypeError, KeyError):
            continue
        return task
    return None


def score_run(task: Any, run_dir: Path) -> Any:
    """``python -m agents.bench score --task NAME --agent RUN_DIR`` as a :class:`Score`."""
    from agents.bench.score import score

    return score(task, str(run_dir), seeds=range(SCORE_SEEDS))


def score_lines(result: Any, task: Any, given: bool = True) -> list[str]:
    """The task score's lines above the final table: normalised first, then raw and % of optimum.

    ``given``: the run was on ``--task``; else it was on the task's env and options.
    """
    from agents.bench.score import scale_legend

    lo, hi = result.normalised_ci
    best = task.references.optimum
    percent = task.references.ratio(result.mean)
    what = "optimum" if best.certified else "best known"
    pct = f", {percent:.2%} of the {what}" if math.isfinite(percent) else ""
    n_seeds, n_eps = result.returns.shape
    on = "task" if given else "the run's env is task"
    return [
        f"{on} {task.name}: normalised {result.normalised:.4f} [{lo:.4f}, {hi:.4f}]",
        f"  ({scale_legend(task)}); raw return {result.mean:.6g} ± {result.ci95:.3g}{pct}",
        f"  (python -m agents.bench score: {n_seeds} seeds x {n_eps} episodes)",
    ]
