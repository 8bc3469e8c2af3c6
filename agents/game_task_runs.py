"""``train.py game --task NAME``: both players of a benchmark game task, its player scored.

The game is played exactly as the task builds it: each side's Gymnasium view (the task's own
id for its player, the same env's other view for the opponent) with the task's options and no
scenario preset of ``train.py`` (:class:`GameTaskEntry`). Best responses default to exact
(``--algo exact``), so PSRO is double oracle and runs until its fixed point, an equilibrium of
the full game (:attr:`agents.config.GameConfig.converges`); learned best responses (PPO, A2C,
DQN, torch-ppo) are selectable where the game is a matrix game. The informed-attacker Bayesian
games, whose attacker plays one strategy per type it observes, train with exact best responses
(:mod:`agents.informed_game`).

At the end the run folder is scored on the task by :func:`agents.task_runs.score_run`, the code
of ``python -m agents.bench score``, which reads the scored player's final mix from the folder's
``scores.json`` (:func:`agents.bench.agents.load_agent`): both give the same number.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import gymnasium as gym

from agents.registry import Trainable

# the game command's options that would change the task's game, with their defaults
GAME_FIXED = {"env": "sensor_game_v0", "scenario": None, "env_kwargs": {}}
EXACT = "exact"
LIST_TASKS = (
    'list them with python -c "from fdia_env import tasks; print(*tasks.names(), sep=chr(10))"'
)


def option(name: str) -> str:
    """The command-line spelling of a GameConfig field (``env_kwargs`` → ``--env-kwargs``)."""
    return "--" + name.replace("_", "-")


def resolve_game_task(name: str) -> Any:
    """The game task ``name``.

    Raises:
        ValueError: Naming ``--task``: an unknown name (with close names and how to list the
            tasks), or a task that is not a game (pointing to its player's command).
    """
    from fdia_env import tasks

    try:
        task = tasks.get(name)
    except ValueError as exc:
        raise ValueError(f"--task: {exc}; {LIST_TASKS}") from None
    if not task.is_game:
        raise ValueError(
            f"--task {name} is not a game task (it scores the {task.player}'s return against "
            f"a fixed env): train it with train.py {task.player} --task {name}"
        )
    return task


def check_game_task_options(cfg: Any) -> None:
    """Raise unless ``cfg`` leaves every option that would change the task's game unset.

    Raises:
        ValueError: Naming the option (``--env``, ``--scenario``, ``--env-kwargs``,
            ``--backend``, ``--resume``).
    """
    given = [name for name, default in GAME_FIXED.items() if getattr(cfg, name) != default]
    if given:
        raise ValueError(
            f"{option(given[0])} cannot be combined with --task {cfg.task}: the task fixes its "
            "game (its env and options; drop the option, or train without --task)"
        )
    if cfg.run.backend != "sb3":
        raise ValueError(f"--backend {cfg.run.backend} is not supported with --task yet")
    if cfg.run.resume:
        raise ValueError(f"--resume is not supported with --task {cfg.task} yet")


def game_env_of(task: Any) -> str:
    """The registered two-player env whose view the task's player acts in."""
    from agents.registry import game_names
    from fdia_env.registration import get_env

    for env in game_names():
        if get_env(env).views.get(task.player) == task.env_id:
            return env
    raise ValueError(f"--task {task.name}: {task.env_id} is no view of a registered game")


def is_informed(task: Any) -> bool:
    """Whether the task's game is the informed-attacker Bayesian game (no matrix game)."""
    return task.env_kwargs.get("types") is not None and (
        task.env_kwargs.get("attacker_model") == "informed"
    )


@dataclass(frozen=True)
class GameTaskEntry(Trainable):
    """One side of a game task, as the self-play drivers use a registry entry.

    Its views are built with exactly the options given (the task's): ``train.py``'s scenario
    presets are never applied.

    Attributes:
        task: The :class:`fdia_env.tasks.Task`.
    """

    task: Any = None

    def make(self, scenario: str | None = None, **overrides: Any) -> gym.Env:
        """The side's view with the task's options updated by ``overrides`` (an opponent)."""
        kwargs = {**self.task.env_kwargs, **overrides}
        if scenario is not None:
            kwargs["scenario"] = scenario
        return self.make_resolved(kwargs)

    def make_resolved(self, env_kwargs: dict[str, Any], **extra: Any) -> gym.Env:
        """The side's view with exactly ``env_kwargs`` (and ``extra``), as the task builds it."""
        from fdia_env.tasks.task import make_pinned

        return make_pinned(self.gym_id, None, {**env_kwargs, **extra})


def task_entries(task: Any) -> dict[str, GameTaskEntry]:
    """Both sides of the task's game (:class:`GameTaskEntry`)."""
    from agents.registry import get

    env = game_env_of(task)
    out = {}
    for side in ("attacker", "defender"):
        entry = get(env, side)
        out[side] = GameTaskEntry(
            **{f.name: getattr(entry, f.name) for f in fields(Trainable)}, task=task
        )
    return out


def task_algo(cfg: Any, entries: dict[str, GameTaskEntry]) -> str:
    """``--algo`` under ``--task``: ``exact`` by default, else a learner of the game.

    Raises:
        ValueError: Naming ``--algo``: a learner unknown or that does not fit the game, or one
            given for the informed-attacker Bayesian game (exact best responses only).
    """
    from agents.config import TORCH_PPO, is_torch_ppo

    task = entries["attacker"].task
    if cfg.algo is None or str(cfg.algo).strip().lower() == EXACT:
        return EXACT
    if is_informed(task):
        raise ValueError(
            f"--algo {cfg.algo}: task {task.name} is the informed-attacker Bayesian game, whose "
            "attacker plays one strategy per type it observes (no matrix game over its "
            "actions); it trains with --algo exact (the default)"
        )
    if is_torch_ppo(cfg.algo):
        return TORCH_PPO
    try:
        return entries["attacker"].algorithm(cfg.algo)
    except ValueError:
        valid = ", ".join([EXACT, *entries["attacker"].algorithms, TORCH_PPO])
        raise ValueError(
            f"--algo {cfg.algo!r} does not fit task {task.name}; best responses that fit: {valid}"
        ) from None


@dataclass(frozen=True)
class GameTaskSetup:
    """A ``game --task`` run's resolved options.

    Attributes:
        task: The :class:`fdia_env.tasks.Task`.
        entries: Each side's :class:`GameTaskEntry`.
        algo: ``exact``, ``torch-ppo`` or an SB3 algorithm.
        env_kwargs: The task's env options.
    """

    task: Any
    entries: dict[str, GameTaskEntry]
    algo: str
    env_kwargs: dict[str, Any]

    @property
    def scenario(self) -> str:
        """The scenario preset the task's game is played on."""
        return str(self.env_kwargs["scenario"])


def game_task_setup(cfg: Any) -> GameTaskSetup:
    """The game task of ``cfg.task``, its options checked, both sides and the oracle resolved.

    Raises:
        ValueError: As :func:`resolve_game_task`, :func:`check_game_task_options` and
            :func:`task_algo`.
    """
    task = resolve_game_task(cfg.task)
    check_game_task_options(cfg)
    entries = task_entries(task)
    return GameTaskSetup(task, entries, task_algo(cfg, entries), dict(task.env_kwargs))


def task_resolved(task: Any) -> dict[str, Any]:
    """What config.json's ``resolved`` records of the task (the bench's loader checks it)."""
    from agents.task_runs import plain_kwargs

    return {"task": task.name, "gym_id": task.env_id, "env_kwargs": plain_kwargs(task.env_kwargs)}


def score_lines(result: Any, task: Any) -> list[str]:
    """The game task score's lines above the final table (normalised first)."""
    from agents.bench.score import scale_legend

    lo, hi = result.normalised_ci
    expl = result.extras.get("exploitability", float("nan"))
    rel = result.extras.get("relative_exploitability", float("nan"))
    n_seeds, n_eps = result.returns.shape
    return [
        f"task {task.name}: normalised {result.normalised:.4f} [{lo:.4f}, {hi:.4f}]",
        f"  ({scale_legend(task)}); the {task.player}'s final mix: exploitability {expl:.6g} "
        f"({rel:.2%} of the game value), worst-case return {result.raw:.6g} (game value "
        f"{task.references.optimum.value:.6g})",
        f"  (python -m agents.bench score: {n_seeds} seeds x {n_eps} episodes)",
    ]


def score_game_run(task: Any, result: Any) -> Any:
    """Score a finished ``game --task`` run's player on its task; ``scores.json`` gets ``task``.

    The score is :func:`agents.task_runs.score_run`'s (``python -m agents.bench score`` on the
    run folder: the player's final mix read back from ``scores.json``). ``result`` (a
    :class:`agents.selfplay.SelfPlayResult`) gets it as ``task_score``; a run stopped before its
    first iteration (no scores) is returned as it is.
    """
    if not result.history:
        return result
    from agents.checkpoint import read_json
    from agents.runs import write_json
    from agents.task_runs import score_run

    score = score_run(task, result.run_dir)
    path = result.run_dir / "scores.json"
    write_json(path, {"task": score.to_dict(), **read_json(path, "scores")})
    result.task_score = score
    return result
