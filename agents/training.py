"""Train one player with stable-baselines3: model, logging, checkpoints, resume, scoring.

:func:`train` runs one :class:`~agents.config.TrainConfig` end to end:

- the env and its analytic reference come from :mod:`agents.registry`; envs are built by
  zero-argument thunks (:func:`env_thunk`);
- TensorBoard logs go to ``<run>/tb`` (SB3's own statistics plus ``eval/*``);
- :class:`ScoreCallback` evaluates the policy every ``eval_freq`` steps with
  :func:`agents.evaluate.evaluate` and logs its score against the reference;
- :class:`CheckpointCallback` saves ``checkpoints/model_<steps>.zip`` (and the replay buffer of
  off-policy algorithms) every ``checkpoint_freq`` steps through a temporary file and
  ``os.replace``, then points ``checkpoints/state.json`` at it;
- the best-scoring model of those evaluations is kept as ``best_model.zip`` (``best.json``) and
  gets its own row in the final table when it beats the final model;
- ``resume`` loads the checkpoint ``state.json`` names and continues the same run: same folder,
  ``num_timesteps``, optimizer state and replay buffer, ``reset_num_timesteps=False``.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
from sb3_contrib import MaskablePPO
from stable_baselines3 import A2C, DQN, PPO, SAC
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import configure
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
from stable_baselines3.common.vec_env import DummyVecEnv

from agents.config import TrainConfig, algo_kwargs, parse_env_kwargs, resolved_hyperparameters
from agents.evaluate import Evaluation, evaluate
from agents.plots import learning_curve
from agents.registry import Reference, Trainable, get
from agents.runs import (
    atomic_write,
    check_resumable,
    config_dict,
    prepare_run_dir,
    read_jsonl,
    run_prefix,
    write_json,
    write_jsonl,
)
from agents.seeding import seed_everything

ALGO_CLASSES: dict[str, type[BaseAlgorithm]] = {
    "PPO": PPO,
    "MaskablePPO": MaskablePPO,
    "A2C": A2C,
    "DQN": DQN,
    "SAC": SAC,
}
KEEP_CHECKPOINTS = 2


def env_thunk(
    gym_id: str,
    env_kwargs: dict[str, Any],
    opponent: Callable[[], Any] | None = None,
    monitor: bool = False,
) -> Callable[[], gym.Env]:
    """A zero-argument factory of the env (a fresh ``opponent()`` each call, if given)."""

    def thunk() -> gym.Env:
        kwargs = dict(env_kwargs)
        if opponent is not None:
            kwargs["opponent"] = opponent()
        env = gym.make(gym_id, **kwargs)
        return Monitor(env) if monitor else env

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
    with other.make(**env_kwargs) as env:
        probs = other.reference_of(env).policy.probs

    def make() -> Any:
        from fdia_env.envs.opponents import FixedMix

        return FixedMix(probs)

    return make


def build_model(
    algo: str, env: Any, kwargs: dict[str, Any], seed: int, device: str = "cpu", verbose: int = 0
) -> BaseAlgorithm:
    """A new SB3 ``algo`` model with an MLP policy on ``env``."""
    return ALGO_CLASSES[algo]("MlpPolicy", env, seed=seed, device=device, verbose=verbose, **kwargs)


# ---------------------------------------------------------------------------- checkpoints


def save_checkpoint(model: BaseAlgorithm, folder: Path, train_seconds: float) -> Path:
    """Save ``model`` (and its replay buffer) atomically; point ``state.json`` at it.

    The replay buffer is written first and ``state.json`` last, so the checkpoint it names is
    always complete. Older checkpoints beyond the last :data:`KEEP_CHECKPOINTS` are removed.
    """
    steps = model.num_timesteps
    buffer = None
    if isinstance(model, OffPolicyAlgorithm) and model.replay_buffer is not None:
        buffer = atomic_write(folder / f"replay_buffer_{steps}.pkl", model.save_replay_buffer)
    path = atomic_write(folder / f"model_{steps}.zip", model.save)
    write_json(
        folder / "state.json",
        {
            "timesteps": steps,
            "train_seconds": train_seconds,
            "model": path.name,
            "replay_buffer": None if buffer is None else buffer.name,
        },
    )
    for pattern in ("model_*.zip", "replay_buffer_*.pkl"):
        old = sorted(folder.glob(pattern), key=lambda p: int(p.stem.rsplit("_", 1)[1]))
        for p in old[:-KEEP_CHECKPOINTS]:
            p.unlink(missing_ok=True)
    return path


def load_checkpoint(
    algo: str, folder: Path, env: Any, device: str = "cpu"
) -> tuple[BaseAlgorithm, float] | None:
    """The checkpoint ``state.json`` points at, and its training seconds (None: none yet).

    Off-policy models get their replay buffer back too.
    """
    state_path = folder / "state.json"
    if not state_path.is_file():
        return None
    state = json.loads(state_path.read_text())
    model = ALGO_CLASSES[algo].load(folder / state["model"], env=env, device=device)
    if state.get("replay_buffer") and isinstance(model, OffPolicyAlgorithm):
        model.load_replay_buffer(folder / state["replay_buffer"])
    return model, float(state["train_seconds"])


class CheckpointCallback(BaseCallback):
    """Every ``every`` steps of ``num_timesteps``, :func:`save_checkpoint`."""

    def __init__(self, folder: Path, every: int, clock: Callable[[], float]) -> None:
        super().__init__()
        self.folder, self.every, self.clock = folder, every, clock
        self.next_at = 0

    def _on_training_start(self) -> None:
        self.next_at = (self.model.num_timesteps // self.every + 1) * self.every

    def _on_step(self) -> bool:
        if self.model.num_timesteps >= self.next_at:
            save_checkpoint(self.model, self.folder, self.clock())
            self.next_at = (self.model.num_timesteps // self.every + 1) * self.every
        return True


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

    The best-scoring model so far is kept as ``best_model.zip`` (described by ``best.json``):
    evaluations of a deterministic policy in expected dynamics are exact, so the best one is a
    genuine score, not a lucky draw.
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
    ) -> None:
        super().__init__()
        self.eval_env, self.reference, self.every = eval_env, reference, every
        self.n_episodes, self.seed = n_episodes, seed
        self.history, self.history_path, self.clock = history, history_path, clock
        self.next_at = 0
        best_path = history_path.parent / "best.json"
        self.best = json.loads(best_path.read_text()) if best_path.is_file() else None

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
                run_dir = self.history_path.parent
                atomic_write(run_dir / "best_model.zip", self.model.save)
                self.best = record
                write_json(run_dir / "best.json", record)
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
    """

    run_dir: Path
    model: BaseAlgorithm
    evaluations: dict[str, Evaluation]
    history: list[dict[str, Any]] = field(default_factory=list)
    train_seconds: float = 0.0
    resumed: bool = False


def _check_positive(**values: int) -> None:
    for name, v in values.items():
        if v < 0 or (v == 0 and name in ("total_timesteps", "final_eval_episodes")):
            raise ValueError(f"{name.replace('_', '-')} must be positive, got {v}")


def train_prefix(cfg: TrainConfig) -> str:
    """Run folder name without its time: ``<env>[-defender]-<algo>-s<seed>``."""
    entry = get(cfg.env, cfg.agent)
    name = entry.env if cfg.agent == "attacker" else f"{entry.env}-{cfg.agent}"
    return run_prefix(name, entry.algorithm(cfg.algo), cfg.run.seed)


def train(cfg: TrainConfig) -> TrainResult:
    """Train ``cfg.agent`` of ``cfg.env``, evaluate it and write the run folder.

    Raises:
        ValueError: For an unknown env, scenario or algorithm (listing the valid names), a
            hyperparameter that does not apply, or a resume whose options differ.
        FileExistsError: When a new run's folder exists.
    """
    _check_positive(
        total_timesteps=cfg.total_timesteps,
        eval_freq=cfg.eval_freq,
        eval_episodes=cfg.eval_episodes,
        final_eval_episodes=cfg.final_eval_episodes,
        checkpoint_freq=cfg.checkpoint_freq,
    )
    entry = get(cfg.env, cfg.agent)
    algo = entry.algorithm(cfg.algo)
    kwargs = algo_kwargs(algo, cfg.hp)
    env_kwargs = entry.env_kwargs(cfg.scenario, **parse_env_kwargs(cfg.env_kwargs))
    opponent = opponent_factory(entry, cfg.opponent, env_kwargs)
    make_eval_env = env_thunk(entry.gym_id, env_kwargs, opponent)
    eval_env = make_eval_env()  # bad env kwargs fail here, before a run folder exists
    reference = entry.reference_of(eval_env)

    try:
        run_dir, resumed = prepare_run_dir(
            cfg.run.runs_root, cfg.run.run_dir, train_prefix(cfg), cfg.run.resume
        )
    except (ValueError, FileExistsError):
        eval_env.close()
        raise
    given = config_dict(cfg)
    if resumed:
        saved = json.loads((run_dir / "config.json").read_text())
        check_resumable(saved["config"], given, run_dir)
    write_json(
        run_dir / "config.json",
        {
            "command": cfg.agent,
            "config": given,
            "resolved": {
                "gym_id": entry.gym_id,
                "algo": algo,
                "env_kwargs": env_kwargs,
                "hyperparameters": resolved_hyperparameters(algo, cfg.hp),
                "reference": None
                if reference is None
                else {"name": reference.name, "value": reference.value},
            },
        },
    )

    seed_everything(cfg.run.seed, cfg.run.torch_threads)
    vec_env = DummyVecEnv([env_thunk(entry.gym_id, env_kwargs, opponent, monitor=True)])
    ckpt_dir = run_dir / "checkpoints"
    loaded = load_checkpoint(algo, ckpt_dir, vec_env, cfg.run.device) if resumed else None
    if loaded is None:
        model = build_model(algo, vec_env, kwargs, cfg.run.seed, cfg.run.device, cfg.run.verbose)
        offset = 0.0
    else:
        model, offset = loaded
        model.verbose = cfg.run.verbose
        model.set_random_seed(cfg.run.seed + model.num_timesteps)  # fresh draws after resume
    formats = ["tensorboard"] + (["stdout"] if cfg.run.verbose else [])
    model.set_logger(configure(str(run_dir / "tb"), formats))

    history_path = run_dir / "evaluations.jsonl"
    history = [h for h in read_jsonl(history_path) if h["timesteps"] <= model.num_timesteps]
    write_jsonl(history_path, history)
    start = time.perf_counter()

    def clock() -> float:
        return offset + time.perf_counter() - start

    callbacks: list[BaseCallback] = []
    if cfg.checkpoint_freq:
        callbacks.append(CheckpointCallback(ckpt_dir, cfg.checkpoint_freq, clock))
    if cfg.eval_freq:
        callbacks.append(
            ScoreCallback(
                eval_env,
                reference,
                cfg.eval_freq,
                cfg.eval_episodes,
                cfg.run.seed + 10_000,
                history,
                history_path,
                clock,
            )
        )
    remaining = cfg.total_timesteps - model.num_timesteps
    if remaining > 0:
        model.learn(
            remaining,
            callback=callbacks,
            reset_num_timesteps=loaded is None,
            progress_bar=cfg.run.progress_bar,
        )
    train_seconds = clock()
    save_checkpoint(model, ckpt_dir, train_seconds)
    atomic_write(run_dir / "model.zip", model.save)

    evaluations = final_evaluations(
        model, algo, eval_env, reference, cfg.final_eval_episodes, cfg.run.seed + 20_000
    )
    learned = evaluations[f"learned ({algo})"]
    best_path = run_dir / "best.json"
    if best_path.is_file():
        best = json.loads(best_path.read_text())
        if best["timesteps"] != model.num_timesteps and improves(
            best["score"], best["score_name"], {"score": learned.score}
        ):
            best_model = ALGO_CLASSES[algo].load(run_dir / "best_model.zip", device=cfg.run.device)
            row = evaluate(
                best_model, eval_env, cfg.final_eval_episodes, cfg.run.seed + 20_000, reference
            )
            evaluations = {
                f"learned ({algo})": learned,
                f"best eval ({best['timesteps']} steps)": row,
                **{k: v for k, v in evaluations.items() if k != f"learned ({algo})"},
            }
    if not history or history[-1]["timesteps"] != model.num_timesteps:
        history.append(history_record(learned, model.num_timesteps, train_seconds))
        write_jsonl(history_path, history)
    write_json(
        run_dir / "scores.json",
        {
            "num_timesteps": model.num_timesteps,
            "train_seconds": train_seconds,
            "evaluations": {k: v.to_dict() for k, v in evaluations.items()},
        },
    )
    learning_curve(
        run_dir / "learning_curve.png",
        history,
        None if reference is None else reference.value,
        None if reference is None else reference.name,
        f"{algo} {cfg.agent} on {entry.gym_id} ({env_kwargs['scenario']}), seed {cfg.run.seed}",
    )
    eval_env.close()
    vec_env.close()
    return TrainResult(run_dir, model, evaluations, history, train_seconds, resumed)


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
