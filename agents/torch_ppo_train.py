"""``train.py attacker|defender --algo torch-ppo``: a run of :mod:`agents.torch_ppo`.

The same run folder and scoring as the stable-baselines3 runs (:mod:`agents.training`):
``config.json``, ``evaluations.jsonl`` (an :func:`agents.evaluate.evaluate` of the policy every
``eval_freq`` steps, at iteration boundaries: of a snapshot of the weights, run by a background
thread while training goes on, :mod:`agents.background`), ``model.json`` / ``model.pt`` (the final
policy in the tensor-only format of :func:`agents.torch_ppo.save_policy`), ``scores.json`` and
``learning_curve.png``; the final table scores the learned policy, the analytic answer and random
play against the registry's reference. Training runs on ``--device`` with ``--num-envs`` members of
the torch vector env. ``checkpoints/state.json`` + ``state.pt`` hold the training state (weights,
Adam's moments, the device generator, the return statistics, the counters; tensors only, SHA-256
checked) every ``--checkpoint-freq`` steps and when training ends or is stopped (SIGINT/SIGTERM end
it after the current iteration), so ``--resume`` continues a stopped run; the env members start
fresh episodes there. The checkpoints are written by the same background thread, after the
evaluations queued before them: a run killed at any moment resumes from a checkpoint whose
evaluations are on disk. Not supported here: ``--opponent equilibrium`` (a fixed mix is drawn on
the device: the uniform one).
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym

from agents.background import Background
from agents.config import (
    TORCH_PPO,
    TORCH_PPO_NUM_ENVS,
    Hyperparameters,
    TrainConfig,
    check_device_available,
    flag,
    resolve_device,
    resolved_hyperparameters,
)
from agents.evaluate import evaluate
from agents.interrupt import Diverged
from agents.lifecycle import EVALUATIONS, RunResult, open_run
from agents.runs import write_jsonl
from agents.seeding import derived_seed, seed_everything
from agents.torch_ppo import (
    TorchPolicy,
    TorchPPOConfig,
    TrainingState,
    load_training_state,
    make_torch_env,
    save_policy,
    save_training_state,
    train_torch_ppo,
)

MODEL = "model.json"  # a run folder of this algo holds it once training has finished
# a run folder that --resume can continue holds it (the SB3 runs' marker name, another format)
CHECKPOINT = "checkpoints/state.json"


@dataclass
class TorchPPORun(RunResult):
    """What :func:`train_torch_ppo_run` returns, with :class:`~agents.lifecycle.RunResult`'s fields.

    ``history`` holds the evaluations during training (evaluations.jsonl).

    Attributes:
        policy: The trained policy (SB3-style ``predict``).
        device: The torch device it ran on.
        num_envs: Members of the vector env.
        task_score: With ``--task``: the run's :class:`agents.bench.score.Score` on the task
            (scores.json's ``task``), else None.
        task_given: Whether the run was on ``--task``.
    """

    policy: TorchPolicy = field(kw_only=True)
    device: str = field(default="cpu", kw_only=True)
    num_envs: int = field(default=TORCH_PPO_NUM_ENVS, kw_only=True)
    task_score: Any = field(default=None, kw_only=True)
    task_given: bool = field(default=True, kw_only=True)


def torch_ppo_config(
    cfg: TrainConfig, hp: Hyperparameters | None = None, num_envs: int | None = None
) -> tuple[TorchPPOConfig, dict[str, Any]]:
    """The :class:`TorchPPOConfig` of a train command, and its resolved hyperparameters.

    Args:
        cfg: The command.
        hp: Its hyperparameters with the scenario's defaults (:func:`agents.training.setup_of`,
            e.g. no observation normalisation on the grid presets); None: ``cfg.hp`` alone.
        num_envs: The members (the run's setup's: ``--num-envs``, or a task's default); None:
            ``cfg.num_envs``, or :data:`~agents.config.TORCH_PPO_NUM_ENVS` without it.

    Raises:
        ValueError: For a hyperparameter that does not apply to torch-ppo (naming where it
            does), or ``--n-epochs``/``--n-steps`` values torch-ppo rejects.
    """
    hp = resolved_hyperparameters(TORCH_PPO, cfg.hp if hp is None else hp)
    if num_envs is None:
        num_envs = TORCH_PPO_NUM_ENVS if cfg.num_envs is None else cfg.num_envs
    try:
        config = TorchPPOConfig.from_hyperparameters(hp, cfg.total_timesteps, num_envs)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"--algo torch-ppo: {exc}") from None
    return config, hp


def train_torch_ppo_run(
    cfg: TrainConfig, report: Callable[[str], None] | None = print
) -> TorchPPORun:
    """Train ``cfg.agent`` of ``cfg.env`` with torch-ppo, score it and write the run folder.

    Every option is checked and the env built before the run folder is created; a run that
    fails before its model is saved leaves no folder. SIGINT/SIGTERM end training after the
    current iteration; the model and scores are still written. The run folder's lifecycle is
    :mod:`agents.lifecycle`'s (``report`` gets its lines; None: silent).

    Raises:
        ValueError: For an unknown env or scenario, ``--resume``, ``--opponent equilibrium``, a
            hyperparameter that does not apply, a device that is not there, or env options
            the env rejects.
        FileExistsError: When the run folder exists.
        ValueError: With ``--resume``: nothing to resume, options that differ from the run's,
            or a training state that is corrupt, outside the run folder or does not fit.
    """
    if cfg.opponent != "uniform":
        raise ValueError(
            f"{flag('opponent')} {cfg.opponent!r} is not supported with --algo torch-ppo (the "
            "fixed opponent is the uniform mix, drawn on the device)"
        )
    check_device_available(cfg.run.device)
    device = resolve_device(cfg.run.device)
    from agents.task_runs import plain_kwargs, score_run, task_torch_env
    from agents.training import (
        as_saved,
        check_env_kwargs,
        final_evaluations,
        history_record,
        reference_record,
        setup_of,
        train_prefix,
        write_scores,
    )

    # the scenario's env options and hyperparameters (train.py's table), as the SB3 learners'
    setup = setup_of(cfg)
    entry = setup.entry
    torch_ppo_config(cfg, setup.hp, setup.num_envs)  # checked before the run folder exists

    with ExitStack() as stack:
        run = open_run(cfg, stack, train_prefix(cfg), CHECKPOINT, report, fresh=True)
        # a resume continues with the env options and hyperparameters its run was resolved with
        say = report or (lambda _: None)
        setup = as_saved(setup, run.saved_resolved, cfg.num_envs, say, run.path / "config.json")
        env_kwargs = setup.env_kwargs
        config, hyperparameters = torch_ppo_config(cfg, setup.hp, setup.num_envs)
        task = getattr(entry, "task", None)
        if task is None:
            check_env_kwargs(entry.gym_id, env_kwargs)
        resume: TrainingState | None = None
        if run.resumed and not run.checkpointed:
            say(run.restart_note())
        if run.checkpointed:  # checked before any env is built
            resume = load_training_state(run.path / CHECKPOINT, run.path)
            run.check_not_shorter("total_timesteps", cfg.total_timesteps, resume.timesteps)
            if resume.timesteps != resume.iteration * config.batch_size:
                raise ValueError(
                    f"training state {run.path / CHECKPOINT}: {resume.timesteps} env steps after "
                    f"{resume.iteration} iterations of {config.num_envs} x {config.num_steps}: "
                    "it is not a state of this run's config"
                )
            say(f"resuming {run.path} from its training state at {resume.timesteps} steps")
        try:
            if task is None:
                eval_env = gym.make(entry.gym_id, **env_kwargs)
                venv = make_torch_env(entry.gym_id, config.num_envs, device, **env_kwargs)
            else:  # the native torch vector env, or copies of the task's env
                eval_env = entry.make_env(env_kwargs)
                venv = task_torch_env(task, env_kwargs, config.num_envs, device)
        except (TypeError, ValueError, gym.error.Error) as exc:
            if task is not None:
                raise ValueError(
                    f"--algo torch-ppo on --task {task.name}: its torch vector env: {exc}"
                ) from None
            raise ValueError(
                f"{flag('env_kwargs')}: {entry.gym_id} rejected its options: {exc}"
            ) from None
        stack.callback(eval_env.close)
        stack.callback(venv.close)
        reference = entry.reference_of(eval_env)
        seed_everything(cfg.run.seed, cfg.run.torch_threads)
        run_dir = run.begin()
        run.write_config(
            cfg.agent,
            cfg,
            {
                "gym_id": entry.gym_id,
                **({} if task is None else {"task": task.name}),
                "algo": TORCH_PPO,
                "backend": "torch",
                "device": device,
                "num_envs": config.num_envs,
                "env_kwargs": env_kwargs if task is None else plain_kwargs(env_kwargs),
                "hyperparameters": hyperparameters,
                "reference": reference_record(reference),
            },
        )
        stop = run.watch_signals()
        history_path = run_dir / EVALUATIONS
        done = 0 if resume is None else resume.timesteps
        history: list[dict[str, Any]] = run.evaluations(done) if run.resumed else []
        eval_seed = derived_seed(cfg.run.seed, 10_000)
        state = {"next": (done // cfg.eval_freq + 1) * cfg.eval_freq if cfg.eval_freq else 0}

        # evaluations and checkpoint writes run in order on one worker while training goes on
        jobs = stack.enter_context(Background("torch-ppo-evaluations"))

        def evaluation(policy: TorchPolicy, timesteps: int, seconds: float) -> None:
            ev = evaluate(policy, eval_env, cfg.eval_episodes, eval_seed, reference)
            history.append(history_record(ev, timesteps, seconds))
            write_jsonl(history_path, history)

        def on_iteration(record: dict[str, float], policy: TorchPolicy) -> None:
            if not cfg.eval_freq or record["timesteps"] < state["next"]:
                return
            state["next"] = (record["timesteps"] // cfg.eval_freq + 1) * cfg.eval_freq
            jobs.submit(evaluation, policy.snapshot(), record["timesteps"], record["seconds"])

        try:
            result = train_torch_ppo(
                venv,
                config,
                seed=cfg.run.seed,
                stop=lambda: stop.requested,
                log=on_iteration,
                resume=resume,
                checkpoint=lambda st: jobs.submit(save_training_state, st, run_dir / CHECKPOINT),
                checkpoint_freq=cfg.checkpoint_freq,
            )
        except Diverged as exc:
            jobs.drain()  # the last good checkpoint and its evaluations are written
            raise run.diverged(exc) from None
        jobs.drain()
        save_policy(result.policy, run_dir / "model.json", config, result.timesteps)

        final_seed = derived_seed(cfg.run.seed, 20_000)
        rows = final_evaluations(
            result.policy, TORCH_PPO, eval_env, reference, cfg.final_eval_episodes, final_seed
        )
        learned = rows[f"learned ({TORCH_PPO})"]
        if not history or history[-1]["timesteps"] != result.timesteps:
            history.append(history_record(learned, result.timesteps, result.train_seconds))
            write_jsonl(history_path, history)
        task_score = None
        if task is not None:  # scored as python -m agents.bench score scores the folder
            task_score = score_run(task, run_dir)
        what = f"task {task.name}" if task is not None else env_kwargs["scenario"]
        write_scores(
            run,
            history,
            reference,
            f"torch-ppo {cfg.agent} on {entry.gym_id} ({what}), "
            f"seed {cfg.run.seed}, B={config.num_envs} on {device}",
            rows,
            num_timesteps=result.timesteps,
            train_seconds=result.train_seconds,
            steps_per_second=result.steps_per_second,
            device=device,
            num_envs=config.num_envs,
            **({} if task_score is None else {"task": task_score.to_dict()}),
        )
        return TorchPPORun(
            run_dir,
            rows,
            history,
            result.timesteps,
            result.train_seconds,
            resume is not None,
            stop.signum,
            policy=result.policy,
            device=device,
            num_envs=config.num_envs,
            task_score=task_score,
        )
