"""Train one player with stable-baselines3: model, logging, checkpoints, resume, scoring.

:func:`train` runs one :class:`~agents.config.TrainConfig` end to end:

- every option is checked, and the model built, before the run folder is created: a launch
  with bad options leaves nothing behind;
- the env and its analytic reference come from :mod:`agents.registry`; envs are built by
  zero-argument thunks (:func:`env_thunk`);
- TensorBoard logs go to ``<run>/tb`` (SB3's own statistics plus ``eval/*``);
- :class:`ScoreCallback` evaluates the policy every ``eval_freq`` steps with
  :func:`agents.evaluate.evaluate` and logs its score against the reference;
- :class:`CheckpointCallback` saves ``checkpoints/model_<steps>.pt`` / ``.json`` (and the replay
  buffer of off-policy algorithms as ``replay_buffer_<steps>.npz``) every ``checkpoint_freq``
  steps in the format of :mod:`agents.checkpoint` (tensors and JSON, nothing unpickled; a kill
  at any moment of a write leaves a loadable pair), then points ``checkpoints/state.json`` at it;
- the best-scoring model of those evaluations is kept as ``best_model.pt`` / ``.json``
  (``best.json``) and gets its own row in the final table when it beats the final model;
- ``resume`` rebuilds the model from the run's config, loads the checkpoint ``state.json``
  names into it and continues the same run: same folder, ``num_timesteps``, update counters,
  optimizer state and replay buffer, ``reset_num_timesteps=False``. Its TensorBoard writer
  purges the previous sessions' events after the checkpoint, so the step ranges do not overlap;
- SIGINT/SIGTERM (:mod:`agents.interrupt`) end training at the next step; the final
  checkpoint, model and scores are written and :attr:`TrainResult.interrupted` names the signal.
"""

from __future__ import annotations

import importlib
import inspect
import json
import math
import numbers
import time
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv, VecEnvWrapper, VecMonitor

from agents.algos import build_model
from agents.checkpoint import (
    STAGED,
    UntrustedCheckpointError,
    check_count,
    check_seconds,
    hyperparameters_from,
    inside,
    load_model,
    load_replay_buffer,
    read_json,
    require_trusted,
    save_model,
    save_replay_buffer,
)
from agents.config import (
    DEFENDER_ENV,
    SPARSE_ENVS,
    TORCH_PPO,
    Hyperparameters,
    TrainConfig,
    algo_kwargs,
    check_device_available,
    flag,
    is_torch_ppo,
    parse_env_kwargs,
    resolved_hyperparameters,
    scenario_defaults,
    with_defaults,
)
from agents.evaluate import Evaluation, evaluate
from agents.interrupt import Diverged, StopTrainingCallback
from agents.lifecycle import EVALUATIONS, RunFolder, open_run, run_name, tensorboard
from agents.plots import learning_curve
from agents.registry import Reference, Trainable, get
from agents.runs import run_prefix, write_json, write_jsonl
from agents.seeding import derived_seed, seed_everything

__all__ = [
    "CheckpointState",
    "TrainResult",
    "UntrustedCheckpointError",
    "load_checkpoint",
    "save_checkpoint",
    "train",
]

KEEP_CHECKPOINTS = 2
CHECKPOINT_STATE = "checkpoints/state.json"  # a run folder that --resume can continue has it
CHECKPOINT_FILES = (  # pruned to the last KEEP_CHECKPOINTS of each
    "model_*.json",
    "model_*.pt",
    "model_*.zip",
    "replay_buffer_*.npz",
    "replay_buffer_*.pkl",
)


def env_thunk(
    gym_id: str,
    env_kwargs: dict[str, Any],
    opponent: Callable[[], Any] | None = None,
    monitor: bool = False,
    reward: tuple[float, float] | None = None,
    make: Callable[[dict[str, Any]], gym.Env] | None = None,
) -> Callable[[], gym.Env]:
    """A zero-argument factory of the env (a fresh ``opponent()`` each call, if given).

    ``reward``: ``(shift, scale)`` of :class:`NormalizedReward` for training (the monitor,
    outside it, logs the raw returns). ``make``: builds the env from its options (a task's
    :meth:`~agents.task_runs.TaskEntry.make_env`; None: ``gymnasium.make(gym_id, ...)``).
    """

    def thunk() -> gym.Env:
        kwargs = dict(env_kwargs)
        if opponent is not None:
            kwargs["opponent"] = opponent()
        env = gym.make(gym_id, **kwargs) if make is None else make(kwargs)
        if monitor:
            env = Monitor(env)
        return env if reward is None else NormalizedReward(env, *reward)

    return thunk


def opponent_factory(entry: Trainable, kind: str, env_kwargs: dict[str, Any]) -> Callable | None:
    """Factory of the fixed other player of a game view (None: the env's uniform mix).

    ``kind="equilibrium"`` plays the other side's LP equilibrium mix.
    """
    if not entry.game or kind == "uniform":
        return None
    if kind != "equilibrium":
        raise ValueError(f"opponent must be 'uniform' or 'equilibrium', got {kind!r}")
    other = get(entry.env, "defender" if entry.agent == "attacker" else "attacker")
    with other.make_resolved(env_kwargs) as env:
        probs = other.reference_of(env).policy.probs

    def make() -> Any:
        from fdia_env.envs.opponents import FixedMix

        return FixedMix(probs)

    return make


def env_option_names(gym_id: str) -> tuple[str, ...]:
    """The options (``--env-kwargs`` names) the env behind ``gym_id`` accepts."""
    from fdia_env.registration import GYM_IDS

    module, _ = GYM_IDS[gym_id]
    params = inspect.signature(importlib.import_module(module).parallel_env).parameters
    return tuple(n for n in params if n != "render_mode")


def check_env_kwargs(gym_id: str, env_kwargs: dict[str, Any]) -> None:
    """Raise unless every key of ``env_kwargs`` is an option of the env.

    Raises:
        ValueError: Naming the unknown options and listing the valid ones.
    """
    valid = env_option_names(gym_id)
    unknown = [k for k in env_kwargs if k not in valid]
    if unknown:
        raise ValueError(
            f"{flag('env_kwargs')}: unknown option(s) {', '.join(map(repr, unknown))} for "
            f"{gym_id}; valid options: {', '.join(valid)}"
        )


def make_env(thunk: Callable[[], gym.Env], gym_id: str) -> gym.Env:
    """``thunk()``, with an env's rejection of an option value reported as a ValueError.

    Raises:
        ValueError: Naming ``--env-kwargs`` and the env's own message.
    """
    try:
        return thunk()
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{flag('env_kwargs')}: {gym_id} rejected its options: {exc}") from None


# ---------------------------------------------------------------------------- checkpoints


@dataclass(frozen=True)
class CheckpointState:
    """What ``checkpoints/state.json`` names, resolved and checked.

    Attributes:
        model: The model file (``.json`` of :mod:`agents.checkpoint`, or a trusted ``.zip``).
        replay_buffer: The replay buffer file (``.npz``, a trusted ``.pkl``), or None.
        timesteps: The checkpoint's step.
        train_seconds: Training wall time up to it.
    """

    model: Path
    replay_buffer: Path | None
    timesteps: int
    train_seconds: float


def save_checkpoint(
    model: BaseAlgorithm,
    folder: Path,
    train_seconds: float,
    algo: str,
    hyperparameters: dict[str, Any],
) -> Path:
    """Save ``model`` (and its replay buffer) atomically; point ``state.json`` at it.

    The replay buffer and the model are written first and ``state.json`` last, so the
    checkpoint it names is always complete. Older checkpoints beyond the last
    :data:`KEEP_CHECKPOINTS` are removed. Returns the model's ``.json``.
    """
    steps = model.num_timesteps
    buffer = None
    if isinstance(model, OffPolicyAlgorithm) and model.replay_buffer is not None:
        buffer = save_replay_buffer(model.replay_buffer, folder / f"replay_buffer_{steps}.npz")
    path = save_model(model, folder / f"model_{steps}.json", algo, hyperparameters)
    write_json(
        folder / "state.json",
        {
            "timesteps": steps,
            "train_seconds": train_seconds,
            "model": path.name,
            "replay_buffer": None if buffer is None else buffer.name,
        },
    )
    for pattern in CHECKPOINT_FILES:
        old = sorted(folder.glob(pattern), key=lambda p: int(p.stem.rsplit("_", 1)[1]))
        for p in old[:-KEEP_CHECKPOINTS]:
            p.unlink(missing_ok=True)
    for p in folder.glob(f"model_*.pt{STAGED}"):  # staged tensors of a pruned checkpoint
        if not p.with_name(p.name.removesuffix(f".pt{STAGED}") + ".json").is_file():
            p.unlink(missing_ok=True)
    return path


def read_checkpoint_state(folder: Path, root: Path, trusted: bool = False) -> CheckpointState:
    """Read ``folder/state.json`` and check the files it names, loading none of them.

    Raises:
        ValueError: For a corrupt state.json (naming it), a named file outside ``root`` or
            missing.
        UntrustedCheckpointError: For an SB3 ``.zip`` / pickled buffer without ``trusted``.
    """
    state_path = Path(folder) / "state.json"
    state = read_json(state_path, "checkpoint state")
    steps = check_count(state.get("timesteps"), "timesteps", state_path)
    seconds = check_seconds(state.get("train_seconds"), "train_seconds", state_path)
    files = {}
    for key, unsafe in (("model", ".zip"), ("replay_buffer", ".pkl")):
        name = state.get(key)
        if name is None and key == "replay_buffer":
            files[key] = None
            continue
        path = inside(folder, name, root, f"{key.replace('_', ' ')} file in {state_path}")
        if not path.is_file():
            raise ValueError(f"{path}, named by {state_path}, does not exist")
        if path.suffix == unsafe and not trusted:
            raise UntrustedCheckpointError(
                f"{path} (named by {state_path}) is a pickle-based stable-baselines3 file, which "
                "can run any code when loaded; it was not loaded: pass --trust-checkpoint to load "
                "it only if you made it yourself or trust whoever did"
            )
        files[key] = path
    return CheckpointState(files["model"], files["replay_buffer"], steps, float(seconds))


def load_checkpoint(
    checkpoint: CheckpointState,
    algo: str,
    env: Any,
    kwargs: dict[str, Any],
    root: Path,
    device: str = "cpu",
    trusted: bool = False,
) -> BaseAlgorithm:
    """The model of ``checkpoint``, rebuilt from ``algo`` and ``kwargs`` on ``env``.

    Off-policy models get their replay buffer back too. Nothing is unpickled unless
    ``trusted`` (and the checkpoint is an SB3 ``.zip``).

    Raises:
        ValueError: As :func:`agents.checkpoint.load_model`, or when the model's step count
            differs from the checkpoint's.
    """
    model = load_model(checkpoint.model, env, root, device, kwargs, algo, trusted)
    if model.num_timesteps != checkpoint.timesteps:
        raise ValueError(
            f"{checkpoint.model} holds a model at {model.num_timesteps} steps, its state.json "
            f"says {checkpoint.timesteps}"
        )
    if checkpoint.replay_buffer is not None and isinstance(model, OffPolicyAlgorithm):
        load_replay_buffer(model, checkpoint.replay_buffer, root, trusted)
    return model


def best_model_file(run_dir: Path, trusted: bool = False) -> Path | None:
    """The best model that ``best.json`` describes, checked but not loaded (None: none).

    Runs made before the safe format have ``best_model.zip``, which needs ``trusted``.

    Raises:
        ValueError: For a corrupt best.json, or a model file outside the run folder or missing.
        UntrustedCheckpointError: For an SB3 ``.zip`` without ``trusted``.
    """
    best_path = Path(run_dir) / "best.json"
    if not best_path.is_file():
        return None
    record = read_best(best_path)
    path = inside(run_dir, record.get("model", "best_model.zip"), run_dir, "best model file")
    if not path.is_file():
        raise ValueError(f"best model file {path}, named by {best_path}, does not exist")
    if path.suffix == ".zip":
        require_trusted(path, trusted)
    return path


def read_best(path: Path) -> dict[str, Any]:
    """The ``best.json`` record at ``path``: its step, score and the score's name, checked.

    Raises:
        ValueError: For a corrupt record (naming ``path`` and the key).
    """
    record = read_json(path, "best-model record")
    check_count(record.get("timesteps"), "timesteps", path)
    score, name = record.get("score"), record.get("score_name")
    if isinstance(score, bool) or not isinstance(score, int | float) or not math.isfinite(score):
        raise ValueError(f"{path} is corrupt: score must be a finite number, got {score!r:.80}")
    if not isinstance(name, str):
        raise ValueError(f"{path} is corrupt: score_name must be a string, got {name!r:.80}")
    return record


class CheckpointCallback(BaseCallback):
    """Every ``every`` steps of ``num_timesteps``, ``save(model, seconds)``."""

    def __init__(
        self,
        every: int,
        clock: Callable[[], float],
        save: Callable[[BaseAlgorithm, float], Path],
    ) -> None:
        super().__init__()
        self.every, self.clock, self.save = every, clock, save
        self.next_at = 0

    def _on_training_start(self) -> None:
        self.next_at = (self.model.num_timesteps // self.every + 1) * self.every

    def _on_step(self) -> bool:
        if self.model.num_timesteps >= self.next_at:
            self.save(self.model, self.clock())
            self.next_at = (self.model.num_timesteps // self.every + 1) * self.every
        return True


class DivergenceCallback(BaseCallback):
    """Raises :class:`~agents.interrupt.Diverged` once training goes non-finite.

    After every update (at the start of the next rollout, and when training ends) the losses
    SB3 logged (``train/*loss``), the gradients and the parameters of the policy are checked,
    before any later callback evaluates or checkpoints the weights.
    """

    def _on_rollout_start(self) -> None:
        self.check()

    def _on_training_end(self) -> None:
        self.check()

    def _on_step(self) -> bool:
        return True

    def check(self) -> None:
        """Raise :class:`~agents.interrupt.Diverged` naming the first non-finite value.

        Raises:
            Diverged: With the step (``num_timesteps``).
        """
        for key, value in self.logger.name_to_value.items():
            if (
                key.startswith("train/")
                and key.endswith("loss")
                and isinstance(value, numbers.Real)
                and not math.isfinite(value)
            ):
                raise Diverged(f"the loss ({key})", self.model.num_timesteps)
        named = list(self.model.policy.named_parameters())
        grads = [(k, p.grad) for k, p in named if p.grad is not None]
        for kind, tensors in (("the gradient of", grads), ("the parameter", named)):
            flags = [bool(torch.isfinite(t).all()) for _, t in tensors]
            if not all(flags):
                name = tensors[flags.index(False)][0]
                raise Diverged(f"{kind} {name}", self.model.num_timesteps)


def improves(score: float | None, score_name: str, best: dict[str, Any] | None) -> bool:
    """Whether ``score`` beats ``best`` (higher ratio, or lower exploitability)."""
    if score is None:
        return False
    if best is None:
        return True
    if score_name == "exploitability":
        return score < best["score"]
    return score > best["score"]


class ScoreCallback(BaseCallback):
    """Every ``every`` steps: evaluate, log ``eval/*`` to TensorBoard, append to the history.

    The best-scoring model so far is kept by ``save_best`` (``best_model.json`` / ``.pt``,
    described by ``best.json``): evaluations of a deterministic policy in expected dynamics are
    exact, so the best one is a genuine score, not a lucky draw.
    """

    def __init__(
        self,
        eval_env: gym.Env,
        reference: Reference | None,
        every: int,
        n_episodes: int,
        seed: int,
        history: list[dict[str, Any]],
        history_path: Path,
        clock: Callable[[], float],
        save_best: Callable[[BaseAlgorithm], Path],
    ) -> None:
        super().__init__()
        self.eval_env, self.reference, self.every = eval_env, reference, every
        self.n_episodes, self.seed = n_episodes, seed
        self.history, self.history_path, self.clock = history, history_path, clock
        self.save_best = save_best
        self.next_at = 0
        best_path = history_path.parent / "best.json"
        self.best = read_best(best_path) if best_path.is_file() else None

    def _on_training_start(self) -> None:
        self.next_at = (self.model.num_timesteps // self.every + 1) * self.every

    def _on_step(self) -> bool:
        if self.model.num_timesteps >= self.next_at:
            self.next_at = (self.model.num_timesteps // self.every + 1) * self.every
            result = evaluate(self.model, self.eval_env, self.n_episodes, self.seed, self.reference)
            record = history_record(result, self.model.num_timesteps, self.clock())
            self.history.append(record)
            write_jsonl(self.history_path, self.history)
            if improves(result.score, result.score_name, self.best):
                saved = self.save_best(self.model)
                self.best = {**record, "model": saved.name}
                write_json(saved.parent / "best.json", self.best)
            self.logger.record("eval/mean_return", result.mean)
            if result.reference is not None:
                self.logger.record("eval/reference", result.reference)
            if result.score is not None:
                self.logger.record(f"eval/{result.score_name.replace(' ', '_')}", result.score)
            for key, value in result.extras.items():
                self.logger.record(f"eval/{key}", value)
            self.logger.dump(self.model.num_timesteps)
        return True


def history_record(result: Evaluation, timesteps: int, seconds: float) -> dict[str, Any]:
    """One evaluations.jsonl line."""
    summary = result.to_dict()
    return {
        "timesteps": int(timesteps),
        "train_seconds": round(seconds, 3),
        **{k: summary[k] for k in ("mean", "ci95", "reference", "score", "score_name")},
    }


# ---------------------------------------------------------------------------- the run


@dataclass
class TrainResult:
    """What :func:`train` returns.

    Attributes:
        run_dir: The run folder.
        model: The trained model.
        evaluations: Final evaluations by row name (the learned policy, its best evaluation
            during training when that was better, the analytic answer, random play), as in the
            printed table and scores.json.
        history: Evaluations during training (evaluations.jsonl).
        train_seconds: Wall time spent in ``learn`` (across resumes).
        resumed: Whether the run continued an existing folder.
        interrupted: The signal (SIGINT 2, SIGTERM 15) that stopped training early, or None.
        task_score: The run's :class:`agents.bench.score.Score` on its task (scores.json's
            ``task``): the ``--task`` run's, or the task whose env and options the run trained
            on (:func:`agents.task_runs.matching_task`); else None.
        task_given: Whether the run was on ``--task``.
    """

    run_dir: Path
    model: BaseAlgorithm
    evaluations: dict[str, Evaluation]
    history: list[dict[str, Any]] = field(default_factory=list)
    train_seconds: float = 0.0
    resumed: bool = False
    interrupted: int | None = None
    task_score: Any = None
    task_given: bool = False


@dataclass(frozen=True)
class RunSetup:
    """A run's env, algorithm and options, with its scenario's defaults applied.

    Attributes:
        entry: The registry entry of the learning player.
        algo: The algorithm (``--algo``, else the scenario's default, else the env's first).
        env_kwargs: The env options (the preset's, the scenario table's, ``--env-kwargs``).
        hp: ``--`` hyperparameters with the scenario table's filled in where unset.
        normalize_reward: Whether the training env's rewards are rescaled
            (:func:`reward_normalization`).
        num_envs: MaskablePPO's members of the native vector env (``--num-envs``, else the
            scenario table's ``num_envs``); None: one env.
    """

    entry: Trainable
    algo: str
    env_kwargs: dict[str, Any]
    hp: Hyperparameters
    normalize_reward: bool
    num_envs: int | None = None


def run_setup(
    env: str,
    agent: str,
    scenario: str | None,
    raw_env_kwargs: dict[str, str],
    algo: str | None,
    hp: Hyperparameters,
    normalize_reward: bool | None = None,
    num_envs: int | None = None,
) -> RunSetup:
    """Resolve a command's options against the registry and :data:`SCENARIO_DEFAULTS`.

    ``num_envs`` is ``--num-envs``; where it and ``--n-steps`` are both unset, MaskablePPO takes
    the scenario's ``num_envs`` and ``vector_hyperparameters``.

    Raises:
        ValueError: For an unknown env, scenario or algorithm (listing the valid names).
    """
    entry = get(env, agent)
    env_kwargs = entry.env_kwargs(scenario, **parse_env_kwargs(raw_env_kwargs))
    defaults = scenario_defaults(entry.env, env_kwargs["scenario"], env_kwargs)
    if is_torch_ppo(algo):
        name = TORCH_PPO
    else:
        name = entry.algorithm(algo if algo is not None else defaults.algo)
    normalize = defaults.normalize_reward if normalize_reward is None else normalize_reward
    if name == "MaskablePPO" and num_envs is None and hp.n_steps is None and defaults.num_envs:
        num_envs = defaults.num_envs
        vector = {**defaults.hyperparameters, **defaults.vector_hyperparameters}
        defaults = replace(defaults, hyperparameters=vector)
    return RunSetup(entry, name, env_kwargs, with_defaults(name, hp, defaults), normalize, num_envs)


def setup_of(cfg: TrainConfig) -> RunSetup:
    """:func:`run_setup` of the attacker or defender command (:func:`task_setup` with --task)."""
    if cfg.task is not None:
        return task_setup(cfg)
    return run_setup(
        cfg.env, cfg.agent, cfg.scenario, cfg.env_kwargs, cfg.algo, cfg.hp, cfg.normalize_reward,
        cfg.num_envs,
    )  # fmt: skip


def task_setup(cfg: TrainConfig) -> RunSetup:
    """The run's setup on ``cfg.task``: its env and options, a learner that fits its actions.

    torch-ppo's members are ``--num-envs``, by default :data:`agents.config.TORCH_PPO_NUM_ENVS`
    on a native torch vector env and :data:`agents.task_runs.TASK_COPIES` copies of the task's
    env on the others.

    Raises:
        ValueError: Naming the option: ``--task`` (unknown, a game, another player's),
            ``--env``/``--scenario``/``--env-kwargs``/``--opponent`` given with it, or an
            ``--algo`` that does not fit the task's action space.
    """
    from agents.task_runs import (
        TASK_COPIES,
        check_task_options,
        has_native_torch_env,
        task_algorithm,
        task_entry,
    )

    defaults = (SPARSE_ENVS[0],) if cfg.agent == "attacker" else (SPARSE_ENVS[0], DEFENDER_ENV)
    check_task_options(cfg, defaults)  # the defender command's default or TrainConfig's
    entry = task_entry(cfg)
    algo = task_algorithm(entry, cfg.algo)
    normalize = bool(cfg.normalize_reward)
    num_envs = None
    if algo == TORCH_PPO:
        copies = None if has_native_torch_env(entry.task) else TASK_COPIES
        num_envs = cfg.num_envs if cfg.num_envs is not None else copies
    return RunSetup(entry, algo, dict(entry.task.env_kwargs), cfg.hp, normalize, num_envs)


def say_kept(say: Callable[[str], None], what: str, saved: Any, today: Any) -> None:
    """The one line a resume prints for an option it keeps from its run, not today's default."""
    say(f"resuming with the run's own {what} {saved} (train.py's defaults are now {today})")


def saved_env_kwargs(
    env_kwargs: dict[str, Any], resolved: dict[str, Any], say: Callable[[str], None]
) -> dict[str, Any]:
    """A resumed run's env options (its ``resolved`` entry's), reported where they differ."""
    saved = resolved.get("env_kwargs", env_kwargs)
    if saved != env_kwargs:
        say_kept(say, "env options", saved, env_kwargs)
    return saved


def as_saved(
    setup: RunSetup,
    resolved: dict[str, Any],
    num_envs: int | None,
    say: Callable[[str], None],
    config_path: Path = Path("config.json"),
) -> RunSetup:
    """``setup`` with the env options, members and hyperparameters a resumed run was saved with.

    ``train.py``'s per-scenario defaults change between versions (dc-ieee14-50 gained the
    state groups, the grid presets 8 members of the native vector env), while the options given
    on the command line must be the run's own (:func:`agents.runs.check_resumable`): a resume
    continues the run with what its config.json's ``resolved`` entry says it was trained with,
    and ``say`` gets one line per option where that differs from today's defaults.

    Args:
        setup: Today's resolution of the command (:func:`setup_of`).
        resolved: The run's saved ``resolved`` entry ({}: a new run, ``setup`` unchanged).
        num_envs: ``--num-envs`` (the members of a run saved before ``resolved`` named them).
        say: Reports the options kept.
        config_path: The run's config.json (named in errors).

    Raises:
        ValueError: For a ``resolved`` entry that is corrupt (naming ``config_path``).
    """
    if not resolved:
        return setup
    if getattr(setup.entry, "task", None) is not None:
        env_kwargs = task_env_kwargs(setup.entry.task, setup.env_kwargs, resolved, config_path)
    else:
        env_kwargs = saved_env_kwargs(setup.env_kwargs, resolved, say)
    if not isinstance(env_kwargs, dict) or not isinstance(env_kwargs.get("scenario"), str):
        if getattr(setup.entry, "task", None) is None:  # a task's (the family's: no scenario)
            raise ValueError(
                f"run config {config_path} is corrupt: resolved.env_kwargs must be a JSON "
                f"object naming the scenario, got {env_kwargs!r:.80}"
            )
    members = setup.num_envs
    if setup.algo != TORCH_PPO:  # torch-ppo's members are its own (--num-envs, checked)
        members = resolved.get("num_envs", num_envs)
        if members is not None and (
            isinstance(members, bool) or not isinstance(members, int) or members < 1
        ):
            raise ValueError(
                f"run config {config_path} is corrupt: resolved.num_envs must be an integer "
                f">= 1 or null, got {members!r:.80}"
            )
        if members != setup.num_envs:
            say_kept(say, "native vector env members", members, setup.num_envs)
    hp = saved_hyperparameters(setup.algo, setup.hp, resolved, say, config_path)
    return replace(setup, env_kwargs=env_kwargs, num_envs=members, hp=hp)


def task_env_kwargs(
    task: Any,
    env_kwargs: dict[str, Any],
    resolved: dict[str, Any],
    config_path: Path = Path("config.json"),
) -> dict[str, Any]:
    """A resumed ``--task`` run's env options: ``env_kwargs``, the task's own.

    config.json records them as text where they are objects (a scenario, a system family, an
    opponent policy: :func:`agents.task_runs.plain_kwargs`), which could not rebuild the env;
    the record must be the task's, and the task's objects are used.

    Args:
        task: The run's :class:`fdia_env.tasks.Task`.
        env_kwargs: Its env options (``task.env_kwargs``).
        resolved: The run's saved ``resolved`` entry.
        config_path: The run's config.json (named in errors).

    Raises:
        ValueError: For a ``resolved`` entry of another task or other options (naming
            ``config_path``).
    """
    from agents.task_runs import plain_kwargs

    recorded = resolved.get("env_kwargs")
    if resolved.get("task") != task.name or recorded != plain_kwargs(env_kwargs):
        raise ValueError(
            f"run config {config_path} records another env than task {task.name} builds "
            f"(resolved.task {resolved.get('task')!r}, resolved.env_kwargs {recorded!r:.120}): "
            "it cannot be resumed on the task; start a new run"
        )
    return env_kwargs


def saved_hyperparameters(
    algo: str,
    hp: Hyperparameters,
    resolved: dict[str, Any],
    say: Callable[[str], None],
    config_path: Path = Path("config.json"),
) -> Hyperparameters:
    """The hyperparameters a resumed run was saved with, where they differ from ``hp``'s.

    ``resolved`` is the run's saved ``resolved`` entry ({} for a new run: ``hp`` unchanged);
    ``say`` gets one line naming the hyperparameters kept and today's defaults. Every driver
    that resumes from ``train.py``'s scenario table (attacker, defender, game) keeps them so.

    Raises:
        ValueError: For saved hyperparameters that are not valid (naming ``config_path``, the
            run's config.json, and the key).
    """
    saved = resolved.get("hyperparameters")
    today = json.loads(json.dumps(resolved_hyperparameters(algo, hp)))
    if saved is None or saved == today:
        return hp
    kept = hyperparameters_from(saved, config_path, "resolved.hyperparameters")
    changed = sorted(k for k in saved.keys() | today.keys() if saved.get(k) != today.get(k))
    old, new = ({k: values.get(k) for k in changed} for values in (saved, today))
    say_kept(say, "hyperparameters", old, new)
    return kept


def train_prefix(cfg: TrainConfig) -> str:
    """Run folder name without its time: ``<env>[-defender]-<algo>-s<seed>`` (also torch-ppo's)."""
    setup = setup_of(cfg)
    return run_prefix(run_name(setup.entry.env, cfg.agent), setup.algo, cfg.run.seed)


class NormalizedReward(gym.Wrapper):
    """Training rewards ``(r − shift) / scale``, the shift paid once, at the episode's end.

    So an episode's return ``G`` becomes ``(G − shift) / scale``: with ``shift`` the return of
    doing nothing and ``scale`` the reference's distance from it, 0 is doing nothing and 1 the
    reference. A fixed affine map (nothing to save in a checkpoint, the same after a resume);
    the ranking of policies, and so the optimum, is unchanged.
    """

    def __init__(self, env: gym.Env, shift: float, scale: float) -> None:
        super().__init__(env)
        if not (math.isfinite(shift) and math.isfinite(scale) and scale > 0):
            raise ValueError(
                f"reward normalisation needs a finite shift and a scale > 0, got {shift}, {scale}"
            )
        self.shift, self.scale = float(shift), float(scale)

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict]:
        """One step with the rescaled reward (raw in ``info["raw_reward"]``)."""
        obs, reward, terminated, truncated, info = self.env.step(action)
        scaled = float(reward) - (self.shift if terminated or truncated else 0.0)
        return obs, scaled / self.scale, terminated, truncated, {**info, "raw_reward": reward}


class NormalizedVecReward(VecEnvWrapper):
    """:class:`NormalizedReward` for a stable-baselines3 ``VecEnv``.

    Each member's rewards become ``(r − shift) / scale``, the shift paid once, at the step
    that ends the member's episode.
    """

    def __init__(self, venv: VecEnv, shift: float, scale: float) -> None:
        super().__init__(venv)
        if not (math.isfinite(shift) and math.isfinite(scale) and scale > 0):
            raise ValueError(
                f"reward normalisation needs a finite shift and a scale > 0, got {shift}, {scale}"
            )
        self.shift, self.scale = float(shift), float(scale)

    def reset(self) -> Any:
        """Reset every member."""
        return self.venv.reset()

    def step_wait(self) -> Any:
        """The members' step with the rescaled rewards."""
        obs, reward, dones, infos = self.venv.step_wait()
        scaled = (reward - self.shift * dones) / self.scale
        return obs, scaled.astype(np.float32), dones, infos


def native_vec_env(
    gym_id: str,
    env_kwargs: dict[str, Any],
    num_envs: int,
    reward: tuple[float, float] | None = None,
    opponent: Callable[[], Any] | None = None,
) -> VecEnv:
    """The env's native vector env of ``num_envs`` members as a stable-baselines3 ``VecEnv``.

    Monitored (the raw episode returns, as :func:`env_thunk`'s ``Monitor``), its rewards
    rescaled by ``reward`` (``(shift, scale)``, as :class:`NormalizedReward`); a game view's
    fixed other player is ``opponent()`` (None: the env's uniform mix).

    Raises:
        ValueError: Naming ``--num-envs`` where the env has no native vector env.
    """
    from fdia_env.vector.sb3 import make_sb3_vec_env

    kwargs = dict(env_kwargs) if opponent is None else {**env_kwargs, "opponent": opponent()}
    try:
        venv: VecEnv = VecMonitor(make_sb3_vec_env(gym_id, num_envs, **kwargs))
    except (TypeError, ValueError, gym.error.Error) as exc:
        raise ValueError(
            f"{flag('num_envs')} trains on the env's native vector env, which {gym_id} with "
            f"these options does not have: {exc}"
        ) from None
    return venv if reward is None else NormalizedVecReward(venv, *reward)


def null_return(entry: Trainable, env: gym.Env) -> float:
    """The return of doing nothing: the sparse attacker (any version) attacking no sensor (else 0).

    Played in ``env`` (its own format: the stop action, the empty bitmask or zeros).
    """
    if entry.env not in SPARSE_ENVS:
        return 0.0
    space = env.action_space
    nothing = np.zeros(space.shape, space.dtype) if space.shape else 0
    env.reset(seed=0)
    total, done = 0.0, False
    while not done:
        _, reward, terminated, truncated, _ = env.step(nothing)
        total += float(reward)
        done = terminated or truncated
    return total


def reward_normalization(
    entry: Trainable, env: gym.Env, reference: Reference | None
) -> tuple[float, float] | None:
    """``(shift, scale)`` of :class:`NormalizedReward` for ``env``, or None where none applies.

    The shift is :func:`null_return`; the scale is the reference's distance from it (for a
    game: the size of the game value). None without a reference, or when the reference is no
    better than doing nothing.
    """
    if reference is None:
        return None
    shift = null_return(entry, env)
    scale = abs(reference.value - shift)
    if not math.isfinite(scale) or scale <= 1e-12 * max(1.0, abs(reference.value)):
        return None
    return shift, scale


def train(cfg: TrainConfig, report: Callable[[str], None] | None = print) -> TrainResult:
    """Train ``cfg.agent`` of ``cfg.env``, evaluate it and write the run folder.

    Every option is checked and the model built before a new run's folder is created; if the
    run then fails before its first checkpoint, the folder is removed. SIGINT/SIGTERM stop
    training at the next step (the final checkpoint, model and scores are still written;
    :attr:`TrainResult.interrupted` names the signal); a second one raises
    :class:`agents.interrupt.Aborted` at once. The previous signal handlers are restored.

    Args:
        cfg: The attacker or defender command's settings.
        report: Called with a line on resuming and on removing stale temporary files (None:
            silent).

    Raises:
        ValueError: For an unknown env, scenario or algorithm (listing the valid names), a
            hyperparameter that does not apply or that SB3 rejects, an env option the env does
            not take, a device not present, nothing to resume, a corrupt checkpoint or one
            outside its run folder, or a resume whose options differ.
        UntrustedCheckpointError: For a pickle-based checkpoint without
            ``cfg.run.trust_checkpoint``.
        FileExistsError: When a new run's folder exists.
    """
    say = report or (lambda line: None)
    check_device_available(cfg.run.device)
    trusted = cfg.run.trust_checkpoint

    with ExitStack() as stack:
        run = open_run(cfg, stack, train_prefix(cfg), CHECKPOINT_STATE, say, fresh=True)
        # a resume continues with the options its run was resolved with ({} for a new run)
        setup = as_saved(
            setup_of(cfg), run.saved_resolved, cfg.num_envs, say, run.path / "config.json"
        )
        entry, algo, env_kwargs = setup.entry, setup.algo, setup.env_kwargs
        kwargs = algo_kwargs(algo, setup.hp)
        hyperparameters = resolved_hyperparameters(algo, setup.hp)
        from agents.task_runs import plain_kwargs

        task = getattr(entry, "task", None)
        maker = None if task is None else entry.make_env
        if task is None:
            check_env_kwargs(entry.gym_id, env_kwargs)
        opponent = opponent_factory(entry, cfg.opponent, env_kwargs)
        eval_env = make_env(env_thunk(entry.gym_id, env_kwargs, opponent, make=maker), entry.gym_id)
        stack.callback(eval_env.close)
        reference = entry.reference_of(eval_env)
        checkpoint: CheckpointState | None = None
        if run.resumed and not run.checkpointed:
            say(run.restart_note())
            for name in ("best.json", "best_model.json", "best_model.pt"):  # of the lost part
                (run.path / name).unlink(missing_ok=True)
        if run.checkpointed:
            checkpoint = read_checkpoint_state(run.path / "checkpoints", run.path, trusted)
            run.check_not_shorter("total_timesteps", cfg.total_timesteps, checkpoint.timesteps)
            best_model_file(run.path, trusted)  # refuse an unsafe one now, not after training

        normalization = (
            reward_normalization(entry, eval_env, reference) if setup.normalize_reward else None
        )
        seed_everything(cfg.run.seed, cfg.run.torch_threads)
        if setup.num_envs is None:
            vec_env: VecEnv = DummyVecEnv(
                [env_thunk(entry.gym_id, env_kwargs, opponent, True, normalization, maker)]
            )
        else:
            vec_env = native_vec_env(
                entry.gym_id, env_kwargs, setup.num_envs, normalization, opponent
            )
        stack.callback(vec_env.close)
        if checkpoint is not None:
            model = load_checkpoint(
                checkpoint, algo, vec_env, kwargs, run.path, cfg.run.device, trusted
            )
            model.verbose = cfg.run.verbose
            model.set_random_seed(run.resume_seed(cfg.run.seed, model.num_timesteps))
            offset = checkpoint.train_seconds
            say(f"resuming {run.path} from its checkpoint at {model.num_timesteps} steps")
        else:
            model = build_model(
                algo, vec_env, kwargs, cfg.run.seed, cfg.run.device, cfg.run.verbose
            )
            offset = 0.0
            run.begin()  # only now: every option has been checked
        run.write_config(
            cfg.agent,
            cfg,
            {
                "gym_id": entry.gym_id,
                **({} if task is None else {"task": task.name}),
                "algo": algo,
                "env_kwargs": env_kwargs if task is None else plain_kwargs(env_kwargs),
                "hyperparameters": hyperparameters,
                "num_envs": setup.num_envs,
                "reward_normalization": None
                if normalization is None
                else {"shift": normalization[0], "scale": normalization[1]},
                "reference": reference_record(reference),
            },
        )
        model.set_logger(
            tensorboard(
                run.path / "tb",
                model.num_timesteps + 1 if checkpoint else 0 if run.resumed else None,
                cfg.run.verbose > 0,
            )
        )
        run.watch_signals()
        return _train_and_score(
            cfg, model, algo, kwargs, hyperparameters, run, eval_env, reference, offset,
            env_kwargs, entry,
        )  # fmt: skip


def _train_and_score(
    cfg: TrainConfig,
    model: BaseAlgorithm,
    algo: str,
    kwargs: dict[str, Any],
    hyperparameters: dict[str, Any],
    run: RunFolder,
    eval_env: gym.Env,
    reference: Reference | None,
    offset: float,
    env_kwargs: dict[str, Any],
    entry: Trainable,
) -> TrainResult:
    """Learn (until done or stopped), write the final checkpoint, model and scores."""
    run_dir, resumed, stop = run.path, run.resumed, run.stop
    ckpt_dir = run_dir / "checkpoints"
    history_path = run_dir / EVALUATIONS
    history = run.evaluations(model.num_timesteps)
    start = time.perf_counter()

    def clock() -> float:
        return offset + time.perf_counter() - start

    def checkpoint(m: BaseAlgorithm, seconds: float) -> Path:
        return save_checkpoint(m, ckpt_dir, seconds, algo, hyperparameters)

    def save_best(m: BaseAlgorithm) -> Path:
        return save_model(m, run_dir / "best_model.json", algo, hyperparameters)

    # an evaluation is written before the checkpoint of its step: a kill between the two
    # leaves the earlier checkpoint, from which the resumed run evaluates that step again
    callbacks: list[BaseCallback] = [StopTrainingCallback(stop), DivergenceCallback()]
    if cfg.eval_freq:
        callbacks.append(
            ScoreCallback(
                eval_env,
                reference,
                cfg.eval_freq,
                cfg.eval_episodes,
                derived_seed(cfg.run.seed, 10_000),
                history,
                history_path,
                clock,
                save_best,
            )
        )
    if cfg.checkpoint_freq:
        callbacks.append(CheckpointCallback(cfg.checkpoint_freq, clock, checkpoint))
    remaining = cfg.total_timesteps - model.num_timesteps
    if remaining > 0 and not stop.requested:
        try:
            model.learn(
                remaining,
                callback=callbacks,
                reset_num_timesteps=not run.checkpointed,
                progress_bar=cfg.run.progress_bar,
            )
        except Diverged as exc:
            raise run.diverged(exc) from None
    train_seconds = clock()
    checkpoint(model, train_seconds)
    save_model(model, run_dir / "model.json", algo, hyperparameters)

    final_seed = derived_seed(cfg.run.seed, 20_000)
    evaluations = final_evaluations(
        model, algo, eval_env, reference, cfg.final_eval_episodes, final_seed
    )
    learned = evaluations[f"learned ({algo})"]
    best_file = best_model_file(run_dir, cfg.run.trust_checkpoint)
    if best_file is not None:
        best = read_best(run_dir / "best.json")
        if best["timesteps"] != model.num_timesteps and improves(
            best["score"], best["score_name"], {"score": learned.score}
        ):
            best_model = load_model(
                best_file,
                model.get_env(),
                run_dir,
                cfg.run.device,
                kwargs,
                algo,
                cfg.run.trust_checkpoint,
            )
            row = evaluate(best_model, eval_env, cfg.final_eval_episodes, final_seed, reference)
            evaluations = {
                f"learned ({algo})": learned,
                f"best eval ({best['timesteps']} steps)": row,
                **{k: v for k, v in evaluations.items() if k != f"learned ({algo})"},
            }
    if not history or history[-1]["timesteps"] != model.num_timesteps:
        history.append(history_record(learned, model.num_timesteps, train_seconds))
        write_jsonl(history_path, history)
    task = getattr(entry, "task", None)
    what = f"task {task.name}" if task is not None else env_kwargs["scenario"]
    fields: dict[str, Any] = {}
    task_score = None
    if task is None and stop.signum is None:  # a scenario that is a task's: its scale too
        from agents.task_runs import matching_task

        scored = matching_task(entry.gym_id, env_kwargs, cfg.agent)
    else:
        scored = task
    if scored is not None:  # scored as python -m agents.bench score scores the folder
        from agents.task_runs import score_run

        task_score = score_run(scored, run_dir)
        fields["task"] = task_score.to_dict()
    write_scores(
        run,
        history,
        reference,
        f"{algo} {cfg.agent} on {entry.gym_id} ({what}), seed {cfg.run.seed}",
        evaluations,
        num_timesteps=model.num_timesteps,
        train_seconds=train_seconds,
        **fields,
    )
    model.logger.close()
    return TrainResult(
        run_dir, model, evaluations, history, train_seconds, resumed, stop.signum, task_score,
        task is not None,
    )  # fmt: skip


def reference_record(reference: Reference | None) -> dict[str, Any] | None:
    """The analytic reference as config.json records it (its name and value)."""
    return None if reference is None else {"name": reference.name, "value": reference.value}


def write_scores(
    run: RunFolder,
    history: list[dict[str, Any]],
    reference: Reference | None,
    title: str,
    evaluations: dict[str, Evaluation],
    **fields: Any,
) -> None:
    """A finished run's ``scores.json`` (:meth:`RunFolder.write_scores`) and learning curve."""
    run.write_scores(fields, evaluations)
    learning_curve(
        run.path / "learning_curve.png",
        history,
        None if reference is None else reference.value,
        None if reference is None else reference.name,
        title,
    )


def final_evaluations(
    model: BaseAlgorithm,
    algo: str,
    env: gym.Env,
    reference: Reference | None,
    n_episodes: int,
    seed: int,
) -> dict[str, Evaluation]:
    """The learned policy, the analytic answer (if a policy) and random play, in one loop."""
    rows = {f"learned ({algo})": evaluate(model, env, n_episodes, seed, reference)}
    if reference is not None and reference.policy is not None:
        rows[reference.name] = evaluate(reference.policy, env, n_episodes, seed, reference)
    rows["random"] = evaluate("random", env, n_episodes, seed, reference)
    return rows
