"""``train.py attacker|defender|game --backend rllib``: RLlib PPO runs scored like the SB3 runs.

- :func:`train_rllib`: one player of a Gymnasium view (the other fixed, as ``--opponent``);
- :func:`selfplay_rllib`: both players of a two-player game learning at once (multi-agent PPO,
  one RL module each), scored after every iteration by the exploitability of their mixes on the
  exact payoff matrix; the reported strategies are the average of the mixes over the second
  half of the run (simultaneous gradient play orbits the equilibrium; its average converges).

A run folder ``runs/<env>[-<agent>]-rllib-PPO-s<seed>-<time>/`` holds ``config.json``,
``progress.jsonl`` (one line per iteration: steps, per-agent returns, seconds), ``scores.json``,
``rllib_state.json``/``rllib_state.pt`` (what ``--resume`` reads: weights, optimizer state and
counters as tensors and JSON, :mod:`agents.rllib.state`) and ``checkpoint/`` (RLlib's own
``Algorithm.save_to_path``, for ``Algorithm.from_checkpoint``; it holds pickles and ``--resume``
never reads it). SIGINT/SIGTERM stop after the current iteration; the state and the scores are
still written, and ``--resume`` continues the run (PSRO with RLlib best responses cannot resume:
its policies live in memory only).
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from agents.config import GameConfig, RunSettings, TrainConfig, parse_env_kwargs
from agents.lifecycle import RunFolder, RunResult, game_scores, run_name
from agents.lifecycle import open_run as open_folder
from agents.population import LearnedOracle
from agents.registry import Trainable, game_names, get
from agents.rllib import require_ray
from agents.rllib.state import STATE, load_module, save_module
from agents.runs import read_jsonl, run_prefix, write_json
from agents.seeding import derived_seed, seed_everything

ALGO = "PPO"
# two-player zero-sum games with continuous actions: self-play without an exact matrix game; each
# side that has an analytic reference (agents.registry) is scored in its view at the end
CONTINUOUS_GAMES = ("detection_game_v0",)


def check_algo(algo: str | None) -> None:
    """Raise unless ``algo`` is None or PPO (the algorithm this backend trains).

    Raises:
        ValueError: Naming the option.
    """
    if algo is not None and algo.replace("-", "").replace("_", "").lower() != "ppo":
        raise ValueError(
            f"--algo {algo!r}: --backend rllib trains PPO (with RLlib's action-masking module "
            "for masked players); leave --algo out or use the sb3 backend"
        )


def init_ray(run: RunSettings) -> None:
    """Start a local Ray (``run.num_cpus``) or connect to ``run.ray_address``, once.

    Raises:
        ImportError: Without ray (naming the ``fdia-env[rllib]`` extra).
        ConnectionError: When the cluster cannot be reached (with the token-auth hint).
    """
    require_ray()
    import ray

    if ray.is_initialized():
        return
    if run.ray_address is not None:
        try:
            ray.init(address=run.ray_address, include_dashboard=False)
        except ConnectionError as exc:
            raise ConnectionError(
                f"{exc} (--ray-address {run.ray_address}): is `ray start --head` running there? "
                "A cluster with token authentication (Ray's default once ~/.ray/auth_token "
                "exists) needs RAY_AUTH_MODE=token here, and the head's token in "
                "~/.ray/auth_token, RAY_AUTH_TOKEN_PATH or RAY_AUTH_TOKEN"
            ) from exc
    else:
        ray.init(num_cpus=run.num_cpus, include_dashboard=False)


def env_config_of(
    entry: Trainable, env_kwargs: dict[str, Any], opponent: str = "uniform"
) -> tuple[dict[str, Any], Any]:
    """The view's RLlib ``env_config`` (with the fixed opponent's mix) and an eval env."""
    from agents.training import opponent_factory

    config = dict(env_kwargs)
    make = opponent_factory(entry, opponent, env_kwargs)
    if make is not None:
        mix = make()
        config["opponent"] = [float(p) for p in mix.probs]
        return config, entry.make_resolved(env_kwargs, opponent=mix)
    return config, entry.make_resolved(env_kwargs)


@dataclass
class RLlibTrainResult(RunResult):
    """What :func:`train_rllib` returns, with :class:`~agents.lifecycle.RunResult`'s fields.

    ``history`` holds one record per RLlib iteration (steps, per-agent returns, seconds).

    Attributes:
        policy: The learned policy (:class:`~agents.rllib.policy.RLlibPolicy`).
        task_score: With ``--task``: the run's :class:`agents.bench.score.Score` on the task
            (scores.json's ``task``), else None.
    """

    policy: Any = field(kw_only=True)
    task_score: Any = field(default=None, kw_only=True)


def _iterate(
    algo: Any,
    total_steps: int,
    run: Session,
    stop: Any,
    on_iteration: Callable[[dict[str, Any]], None] | None = None,
    progress: bool = False,
    desc: str = "",
    checkpoint_every: int = 0,
) -> tuple[list[dict[str, Any]], int, float]:
    """Train until ``total_steps`` env steps (or a stop request); write progress.jsonl.

    Continues ``run``'s history, steps and seconds (a resumed run's). The resumable state is
    saved every ``checkpoint_every`` env steps (0: never here) and, whatever the reason the loop
    ends (done, or a stop request), once at its end, before the caller's final evaluation.
    """
    from agents.rllib.config import agent_returns, steps_sampled
    from agents.runs import write_jsonl

    history = run.history
    steps, seconds = run.steps, run.seconds
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=total_steps, initial=min(steps, total_steps), desc=desc, unit="step")
    while steps < total_steps and not stop.requested:
        start = time.perf_counter()
        result = algo.train()
        seconds += time.perf_counter() - start
        n = steps_sampled(result)
        steps += n
        rec = {
            "iteration": int(result.get("training_iteration", len(history) + 1)),
            "timesteps": steps,
            "train_seconds": round(seconds, 3),
            "agent_returns": agent_returns(result),
        }
        if on_iteration is not None:
            on_iteration(rec)
        history.append(rec)
        write_jsonl(run.run_dir / "progress.jsonl", history)
        if checkpoint_every and steps // checkpoint_every > (steps - n) // checkpoint_every:
            run.save(algo, steps, seconds)
        if bar is not None:
            bar.update(n)
    if bar is not None:
        bar.close()
    run.save(algo, steps, seconds)
    return history, steps, seconds


@dataclass
class Session:
    """An RLlib run's folder (:class:`agents.lifecycle.RunFolder`) and its saved state.

    Attributes:
        folder: The run folder and its lifecycle.
        meta: The resumed state's description (``rllib_state.json``), or None for a new run.
        payload: The resumed state's tensors, or None.
        history: The progress records up to the saved state (``progress.jsonl``).
        steps: Env steps sampled so far.
        seconds: Training seconds so far.
        extra: Loop state to save with the next checkpoint (:meth:`save`).
    """

    folder: RunFolder
    meta: dict[str, Any] | None = None
    payload: dict[str, Any] | None = None
    history: list[dict[str, Any]] = field(default_factory=list)
    steps: int = 0
    seconds: float = 0.0
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def run_dir(self) -> Path:
        """The run folder."""
        return self.folder.path

    @property
    def resumed(self) -> bool:
        """Whether the run continues a saved state (False for a run started again from 0)."""
        return self.meta is not None

    def seed(self, seed: int) -> int:
        """RLlib's seed: the run's, or a fresh one derived from it after a resume."""
        return self.folder.resume_seed(seed, self.steps)

    def save(self, algo: Any, steps: int, seconds: float) -> None:
        """Write the resumable state (:func:`agents.rllib.state.save_state`)."""
        from agents.rllib.state import save_state

        extra = {
            "timesteps": steps,
            "train_seconds": seconds,
            "records": len(self.history),
            **self.extra,
        }
        if algo is None:
            from agents.rllib.state import FORMAT

            write_json(self.run_dir / STATE, {"format": FORMAT, "algorithm": None, **extra})
        else:
            save_state(algo, self.run_dir, extra)


def rllib_prefix(cfg: TrainConfig | GameConfig) -> str:
    """Run folder name without its time: ``<env>[-<agent>|-<method>]-rllib-PPO-s<seed>``.

    A ``--task`` run's env part is the task's (``task-sparse-ch4-position-v0``).
    """
    if isinstance(cfg, GameConfig):
        return run_prefix(f"{cfg.env}-{cfg.method}", f"rllib-{ALGO}", cfg.run.seed)
    if cfg.task is not None:
        from agents.task_runs import resolve_task, run_env_name

        env = run_env_name(resolve_task(cfg.task, cfg.agent).name)
    else:
        env = get(cfg.env, cfg.agent).env
    return run_prefix(run_name(env, cfg.agent), f"rllib-{ALGO}", cfg.run.seed)


def open_run(
    cfg: TrainConfig | GameConfig,
    stack: ExitStack,
    report: Callable[[str], None] | None = print,
    with_algorithm: bool = True,
) -> Session:
    """The run folder of ``cfg``: a new one's path (not created yet), or the one to resume.

    On ``--resume``: the folder (``--run-dir``, or the latest of this env, method or agent and
    seed that holds ``rllib_state.json``) is locked, its config.json must agree with ``cfg``
    (except the training length and how it runs), and its state is read and checked, never
    unpickled (:func:`agents.rllib.state.read_state`); the progress records after the state
    are dropped. A run stopped before its first state starts again from step 0 with its saved
    options (and says so).

    Raises:
        ValueError: Nothing to resume, a run of another backend, options that differ, or a
            corrupt, foreign or pickled state file.
        FileExistsError: When a new run's folder exists.
    """
    say = report or (lambda line: None)
    folder = open_folder(cfg, stack, rllib_prefix(cfg), STATE, report, backend="rllib", fresh=True)
    if not folder.checkpointed:  # a new run, or one stopped before its first state: from 0
        if folder.resumed:
            say(folder.restart_note())
        return Session(folder)
    run_dir = folder.path
    if with_algorithm:
        from agents.rllib.state import read_state

        meta, payload = read_state(run_dir)
    else:
        from agents.checkpoint import read_json as read_meta

        meta, payload = read_meta(run_dir / STATE, "RLlib state"), None
    for key, kind in (("timesteps", int), ("train_seconds", float), ("records", int)):
        value = meta.get(key)
        if isinstance(value, bool) or not isinstance(value, kind | int) or value < 0:
            raise ValueError(f"RLlib state {run_dir / STATE} is corrupt: {key!r} is {value!r}")
    history = read_jsonl(run_dir / "progress.jsonl")[: meta["records"]]
    if len(history) != meta["records"]:
        raise ValueError(
            f"cannot resume {run_dir}: progress.jsonl has {len(history)} records, its state "
            f"{meta['records']}"
        )
    done = len(history)
    say(
        f"resuming {run_dir} from its state after {done} iteration{'s' * (done != 1)}, "
        f"{meta['timesteps']} steps"
    )
    session = Session(
        folder, meta, payload, history, int(meta["timesteps"]), float(meta["train_seconds"])
    )
    if isinstance(cfg, TrainConfig):
        folder.check_not_shorter("total_timesteps", cfg.total_timesteps, session.steps)
    elif cfg.method != "selfplay" and cfg.env not in CONTINUOUS_GAMES:  # one record each
        folder.check_not_shorter("iterations", cfg.n_iterations, done, "iterations")
    return session


def begin(session: Session, algo: Any) -> None:
    """Start training in ``session``'s folder.

    A new run: create and lock its folder (removed if it fails before its first state); a
    resumed one: load its saved state into ``algo`` (None: a loop without an algorithm).
    """
    if session.resumed and algo is not None:
        from agents.rllib.state import restore_state

        restore_state(algo, session.meta, session.payload, session.run_dir / STATE)
    session.folder.begin()


def train_rllib(cfg: TrainConfig, report: Callable[[str], None] | None = print) -> Any:
    """Train ``cfg.agent`` of ``cfg.env`` with RLlib PPO, evaluate it, write the run folder.

    With ``cfg.run.resume`` the run continues (:func:`open_run`): the algorithm is rebuilt from
    its config, the saved weights, optimizer state and counters are loaded into it, and it
    trains up to ``cfg.total_timesteps`` in all. The state is saved every
    ``cfg.checkpoint_freq`` env steps and at the end (also when SIGINT/SIGTERM stop the run
    after the current iteration).

    Raises:
        ImportError: Without ray (naming the ``fdia-env[rllib]`` extra).
        ValueError: For an unknown env or scenario, an algorithm other than PPO, a
            hyperparameter that does not apply, an env option the env does not take, nothing
            to resume, a resume whose options differ, or a corrupt or pickled state file.
        FileExistsError: When a new run's folder exists.
        agents.rllib.ZeroStepsSampled: When an iteration sampled nothing.
    """
    from agents.rllib.config import rllib_hyperparameters
    from agents.rllib.envs import is_masked
    from agents.rllib.policy import policy_of
    from agents.training import check_env_kwargs, final_evaluations, saved_env_kwargs

    check_algo(cfg.algo)
    hyperparameters = rllib_hyperparameters(cfg.hp)
    if cfg.task is not None:
        return _train_rllib_task(cfg, hyperparameters, report)
    entry = get(cfg.env, cfg.agent)
    env_kwargs = entry.env_kwargs(cfg.scenario, **parse_env_kwargs(cfg.env_kwargs))
    check_env_kwargs(entry.gym_id, env_kwargs)
    env_config, eval_env = env_config_of(entry, env_kwargs, cfg.opponent)
    with ExitStack() as stack:
        stack.callback(eval_env.close)
        run = open_run(cfg, stack, report)
        # a resume continues with the env options its run was resolved with (train.py's
        # per-scenario defaults change between versions), as the SB3 and torch-ppo drivers do
        saved = saved_env_kwargs(env_kwargs, run.folder.saved_resolved, report or (lambda _: None))
        if saved != env_kwargs:
            env_kwargs = saved
            check_env_kwargs(entry.gym_id, env_kwargs)
            env_config, eval_env = env_config_of(entry, env_kwargs, cfg.opponent)
            stack.callback(eval_env.close)
        run_dir = run.run_dir
        reference = entry.reference_of(eval_env)
        algo, stop = _start(
            run, cfg, entry.gym_id, env_config, cfg.total_timesteps, cfg.agent, env_kwargs,
            hyperparameters, reference,
        )  # fmt: skip
        history, steps, seconds = _iterate(
            algo,
            cfg.total_timesteps,
            run,
            stop,
            progress=cfg.run.progress_bar,
            desc=f"RLlib PPO {cfg.agent} on {entry.env}",
            checkpoint_every=cfg.checkpoint_freq,
        )
        masked = is_masked(_view_space(entry.gym_id, env_config))
        policy = policy_of(algo, None, eval_env.action_space, masked)
        seed = derived_seed(cfg.run.seed, 10_000)
        rows = final_evaluations(policy, ALGO, eval_env, reference, cfg.final_eval_episodes, seed)
        evaluations = {f"learned (RLlib {ALGO})": rows.pop(f"learned ({ALGO})"), **rows}
        algo.save_to_path(str((run_dir / "checkpoint").resolve()))
        run.folder.write_scores(_run_scores(run, history, steps, seconds), evaluations)
        return RLlibTrainResult(
            run_dir, evaluations, history, steps, seconds, run.resumed, stop.signum, policy=policy
        )


def _train_rllib_task(
    cfg: TrainConfig, hyperparameters: dict[str, Any], report: Callable[[str], None] | None
) -> RLlibTrainResult:
    """:func:`train_rllib` on ``--task``: the task's env (:data:`~agents.rllib.envs.TASK_ENV`).

    config.json records the task, its Gymnasium id and its options (objects as text); at the
    end the run folder is scored on the task as ``python -m agents.bench score`` scores it
    (scores.json's ``task``).
    """
    from agents.rllib.envs import TASK_ENV, is_masked
    from agents.rllib.policy import policy_of
    from agents.task_runs import check_rllib_fits, plain_kwargs, score_run
    from agents.training import final_evaluations, task_env_kwargs, task_setup

    setup = task_setup(cfg)  # the options a task fixes, and the task's learners
    entry, task, env_kwargs = setup.entry, setup.entry.task, setup.env_kwargs
    check_rllib_fits(entry)
    env_config = {"task": task.name}
    with ExitStack() as stack:
        eval_env = entry.make_env(env_kwargs)
        stack.callback(eval_env.close)
        run = open_run(cfg, stack, report)
        if run.folder.resumed:  # the run's record must be the task's
            saved = run.folder.saved_resolved
            task_env_kwargs(task, env_kwargs, saved, run.run_dir / "config.json")
        reference = entry.reference_of(eval_env)
        recorded = {"env": task.env_id, "task": task.name, "env_kwargs": plain_kwargs(env_kwargs)}
        algo, stop = _start(
            run, cfg, TASK_ENV, env_config, cfg.total_timesteps, cfg.agent, env_kwargs,
            hyperparameters, reference, recorded,
        )  # fmt: skip
        history, steps, seconds = _iterate(
            algo,
            cfg.total_timesteps,
            run,
            stop,
            progress=cfg.run.progress_bar,
            desc=f"RLlib PPO {cfg.agent} on task {task.name}",
            checkpoint_every=cfg.checkpoint_freq,
        )
        masked = is_masked(_view_space(TASK_ENV, env_config))
        policy = policy_of(algo, None, eval_env.action_space, masked)
        seed = derived_seed(cfg.run.seed, 10_000)
        rows = final_evaluations(policy, ALGO, eval_env, reference, cfg.final_eval_episodes, seed)
        evaluations = {f"learned (RLlib {ALGO})": rows.pop(f"learned ({ALGO})"), **rows}
        algo.save_to_path(str((run.run_dir / "checkpoint").resolve()))
        task_score = score_run(task, run.run_dir)  # as python -m agents.bench score scores it
        fields = {"task": task_score.to_dict()}
        run.folder.write_scores(_run_scores(run, history, steps, seconds, **fields), evaluations)
        return RLlibTrainResult(
            run.run_dir, evaluations, history, steps, seconds, run.resumed, stop.signum,
            policy=policy, task_score=task_score,
        )  # fmt: skip


def _view_space(gym_id: str, env_config: dict[str, Any]) -> Any:
    from agents.rllib.envs import make_view

    with make_view(gym_id, env_config) as env:
        return env.observation_space


def _ppo(
    cfg: TrainConfig | GameConfig, env: str, env_config: dict[str, Any], seed: int, total: int
) -> Any:
    """RLlib PPO's config of ``env`` with the run's settings (env runners, timeout, device)."""
    from agents.rllib.config import ppo_config

    return _with_run(
        ppo_config(
            env,
            env_config,
            hp=cfg.hp,
            num_env_runners=cfg.run.num_env_runners,
            envs_per_env_runner=cfg.run.envs_per_env_runner,
            seed=seed,
            total_timesteps=total,
            sample_timeout_s=cfg.run.sample_timeout_s,
        ),
        cfg.run,
    )


def _start(
    run: Session,
    cfg: TrainConfig | GameConfig,
    env: str,
    env_config: dict[str, Any],
    total: int,
    command: str,
    env_kwargs: dict[str, Any],
    hyperparameters: dict[str, Any],
    reference: Any,
    recorded: dict[str, Any] | None = None,
) -> tuple[Any, Any]:
    """The lifecycle steps every RLlib driver shares, after :func:`open_run`.

    Seed, start Ray, build the algorithm (a resumed run's state loaded into it), write
    config.json (``recorded``: its ``resolved`` entries in place of ``env`` and ``env_kwargs``,
    a task run's) and watch SIGINT/SIGTERM.

    Returns:
        The algorithm (stopped when the run's exit stack closes) and the stop request.
    """
    seed = run.seed(cfg.run.seed)
    seed_everything(seed, cfg.run.torch_threads)
    init_ray(cfg.run)
    algo = _ppo(cfg, env, env_config, seed, total).build_algo()
    run.folder.stack.callback(algo.stop)
    begin(run, algo)
    _write_config(run, command, cfg, env, env_kwargs, hyperparameters, reference, recorded)
    return algo, run.folder.watch_signals()


def _start_selfplay(
    run: Session,
    cfg: GameConfig,
    env_kwargs: dict[str, Any],
    hyperparameters: dict[str, Any],
    reference: Any,
) -> tuple[int, Any, Any]:
    """The self-play drivers' start in ``run``: one iteration's length, then :func:`_start`.

    Returns:
        The env steps of one iteration, the algorithm and the stop request.
    """
    per_iteration = _per_iteration(cfg, run, hyperparameters)
    algo, stop = _start(
        run, cfg, cfg.env, env_kwargs, cfg.n_iterations * per_iteration, "game", env_kwargs,
        hyperparameters, reference,
    )  # fmt: skip
    return per_iteration, algo, stop


def _iterate_selfplay(
    cfg: GameConfig, algo: Any, run: Session, stop: Any, per_iteration: int, on_iteration: Any
) -> tuple[list[dict[str, Any]], int, float]:
    """:func:`_iterate` over the self-play drivers' ``cfg.n_iterations`` iterations."""
    return _iterate(
        algo, cfg.n_iterations * per_iteration, run, stop, on_iteration,
        progress=cfg.run.progress_bar, desc=f"RLlib self-play on {cfg.env}",
    )  # fmt: skip


def _run_scores(
    run: Session, history: list[dict[str, Any]], steps: int, seconds: float, **fields: Any
) -> dict[str, Any]:
    """``scores.json``'s fields of an RLlib run: ``fields``, then its length and returns."""
    return {
        **fields,
        "agent_returns": history[-1]["agent_returns"] if history else {},
        "iterations": len(history),
        "timesteps": steps,
        "train_seconds": seconds,
        "resumed": run.resumed,
    }


def _per_iteration(cfg: GameConfig, run: Session, hyperparameters: dict[str, Any]) -> int:
    """Env steps of one self-play iteration (whole rollouts), the resume's length checked.

    Raises:
        ValueError: For a resume whose ``--iterations`` is below the iterations done.
    """
    n_steps = hyperparameters["n_steps"]
    per_iteration = math.ceil(cfg.steps_per_iteration / n_steps) * n_steps
    run.folder.check_not_shorter(
        "iterations", cfg.n_iterations, run.steps // per_iteration, "iterations"
    )
    return per_iteration


def _with_run(config: Any, run: RunSettings) -> Any:
    """Apply the run's torch device to the learner (``cuda`` uses one GPU)."""
    if run.device.startswith("cuda"):
        config = config.learners(num_gpus_per_learner=1)
    return config


def _write_config(
    run: Session,
    command: str,
    cfg: TrainConfig | GameConfig,
    env: str,
    env_kwargs: dict[str, Any],
    hyperparameters: dict[str, Any],
    reference: Any,
    recorded: dict[str, Any] | None = None,
) -> None:
    from agents.training import reference_record

    run.folder.write_config(
        command,
        cfg,
        {
            "backend": "rllib",
            "env": env,
            "algo": ALGO,
            "env_kwargs": env_kwargs,
            **(recorded or {}),
            "hyperparameters": hyperparameters,
            "reference": reference_record(reference),
        },
    )


# ------------------------------------------------------------------------------------ self-play


def initial_mixes(policies: dict[str, Any], parallel: Any) -> dict[str, np.ndarray]:
    """Each player's mixed strategy: its action distribution at the (seeded) initial state."""
    obs, _ = parallel.reset(seed=0)
    out = {}
    for side, policy in policies.items():
        own = obs[side]
        if isinstance(own, dict):
            out[side] = policy.action_probs(own["observation"], own["action_mask"])
        else:
            out[side] = policy.action_probs(own)
    return out


def _matrix_game(
    cfg: GameConfig,
) -> tuple[dict[str, Any], dict[str, Any], Any, dict[str, int], dict[str, Any]]:
    """Check a matrix game's options; its entries, env kwargs, exact game, sizes, PPO settings.

    Raises:
        ValueError: For an unknown game, algorithm or env option, or an env that is not a
            one-shot matrix game.
    """
    from agents.population import SIDES
    from agents.rllib.config import rllib_hyperparameters

    if cfg.env not in game_names():
        valid = [*game_names(), *CONTINUOUS_GAMES]
        raise ValueError(f"unknown game {cfg.env!r}; valid games: {', '.join(valid)}")
    check_algo(cfg.algo)
    entries = {side: get(cfg.env, side) for side in SIDES}
    env_kwargs = entries["attacker"].env_kwargs(cfg.scenario, **parse_env_kwargs(cfg.env_kwargs))
    reference, n = _matrix_reference(cfg, entries, env_kwargs)
    return entries, env_kwargs, reference, n, rllib_hyperparameters(cfg.hp)


def _matrix_reference(
    cfg: GameConfig, entries: dict[str, Any], env_kwargs: dict[str, Any]
) -> tuple[Any, dict[str, int]]:
    """The exact game of ``env_kwargs`` (checked) and each side's number of actions."""
    from agents.population import SIDES
    from agents.training import check_env_kwargs

    check_env_kwargs(entries["attacker"].gym_id, env_kwargs)
    with entries["attacker"].make_resolved(env_kwargs) as env:
        reference = entries["attacker"].reference_of(env)
        n = {side: int(env.unwrapped.parallel.action_space(side).n) for side in SIDES}
    if reference is None or not reference.is_game:
        raise ValueError(f"{cfg.env} with {env_kwargs} is not a one-shot matrix game")
    reference.matrix_game()  # raises for the informed-attacker Bayesian game
    return reference, n


def _resumed_game(
    cfg: GameConfig,
    run: Session,
    entries: dict[str, Any],
    env_kwargs: dict[str, Any],
    reference: Any,
    n: dict[str, int],
    say: Callable[[str], None],
) -> tuple[dict[str, Any], Any, dict[str, int]]:
    """A resumed run's own game: its saved env options, exact game and sizes.

    Those given where they are the run's (a new run, or defaults unchanged since it was saved).
    """
    from agents.training import saved_env_kwargs

    saved = saved_env_kwargs(env_kwargs, run.folder.saved_resolved, say)
    if saved == env_kwargs:
        return env_kwargs, reference, n
    return saved, *_matrix_reference(cfg, entries, saved)


def selfplay_rllib(cfg: GameConfig, report: Callable[[str], None] | None = print) -> Any:
    """Both players of ``cfg.env`` learning at once (``--method selfplay``), scored exactly.

    Other methods (psro, fsp, ibr) run :func:`psro_rllib`.

    ``cfg.n_iterations`` iterations of ``cfg.steps_per_iteration`` env steps each; after each the
    exploitability of the players' current mixes and of their average over the second half of
    the iterations so far is computed on the exact payoff matrix. The result's ``x``/``y`` are
    the average mixes (the last-iterate figures are in the history). ``--resume`` continues
    to ``cfg.n_iterations`` in all (both modules' weights, optimizer states and counters, and the
    mixes averaged so far, restored).

    Raises:
        ImportError: Without ray.
        ValueError: For a method other than selfplay, an env that is not a one-shot matrix game,
            an unknown scenario, a hyperparameter that does not apply, nothing to resume, a
            resume whose options differ, or a corrupt or pickled state file.
        FileExistsError: When a new run's folder exists.
    """
    from agents.population import SIDES
    from agents.rllib.envs import make_multi_agent
    from agents.rllib.policy import policy_of
    from agents.selfplay import SelfPlayResult, _final_evaluations
    from baselines.game import exploitability

    if cfg.method != "selfplay":
        return psro_rllib(cfg, report)
    if cfg.env not in game_names() and cfg.env in CONTINUOUS_GAMES:
        return _selfplay_continuous(cfg, report)
    say = report or (lambda line: None)
    entries, env_kwargs, reference, n, hyperparameters = _matrix_game(cfg)
    with ExitStack() as stack:
        run = open_run(cfg, stack, report)
        env_kwargs, reference, n = _resumed_game(cfg, run, entries, env_kwargs, reference, n, say)
        L, value = reference.payoff, reference.value
        parallel = make_multi_agent(cfg.env, env_kwargs).parallel
        per_iteration, algo, stop = _start_selfplay(
            run, cfg, env_kwargs, hyperparameters, reference
        )
        run_dir = run.run_dir
        policies = {
            side: policy_of(algo, side, parallel.action_space(side), False) for side in SIDES
        }
        # each RLlib iteration's current mixes (a resumed run's from its progress records)
        mixes = {side: _saved_mixes(run, side, n[side]) for side in SIDES}

        def on_iteration(rec: dict[str, Any]) -> None:
            now = initial_mixes(policies, parallel)
            for side in SIDES:
                mixes[side].append(now[side])
            half = len(mixes["attacker"]) // 2
            avg = {side: np.mean(mixes[side][half:], axis=0) for side in SIDES}
            last = exploitability(L, now["defender"], now["attacker"], value)
            mean = exploitability(L, avg["defender"], avg["attacker"], value)
            rec.update(
                last_nash_conv=last.nash_conv,
                last_relative_nash_conv=last.nash_conv / abs(value),
                defender=mean.defender,
                attacker=mean.attacker,
                nash_conv=mean.nash_conv,
                relative_nash_conv=mean.nash_conv / abs(value),
                x=avg["defender"].tolist(),
                y=avg["attacker"].tolist(),
                last_defender=now["defender"].tolist(),
                last_attacker=now["attacker"].tolist(),
            )
            if len(mixes["attacker"]) % (per_iteration // hyperparameters["n_steps"]) == 0:
                say(_selfplay_line(rec, value))

        history, steps, seconds = _iterate_selfplay(
            cfg, algo, run, stop, per_iteration, on_iteration
        )
        if not history:
            return SelfPlayResult(
                run_dir, "selfplay", np.zeros(0), np.zeros(0), value, [], interrupted=stop.signum
            )
        x, y = np.array(history[-1]["x"]), np.array(history[-1]["y"])
        evaluations = _final_evaluations(entries, env_kwargs, reference, x, y, cfg)
        algo.save_to_path(str((run_dir / "checkpoint").resolve()))
        run.folder.write_scores(
            game_scores(
                "selfplay", value, x, y, history, steps, seconds,
                backend="rllib",
                last_iterate_relative_nash_conv=history[-1]["last_relative_nash_conv"],
                agent_returns=history[-1]["agent_returns"],
                resumed=run.resumed,
            ),
            evaluations,
        )  # fmt: skip
        return SelfPlayResult(
            run_dir,
            "selfplay",
            x,
            y,
            value,
            history,
            evaluations,
            {},
            seconds,
            interrupted=stop.signum,
        )


def _saved_mixes(run: Session, side: str, n: int) -> list[np.ndarray]:
    """A resumed self-play run's current mixes of ``side``, one per saved progress record.

    Raises:
        ValueError: When a record has no mix of ``n`` probabilities.
    """
    out = []
    for h in run.history:
        mix = np.asarray(h.get(f"last_{side}", ()), dtype=float)
        if mix.shape != (n,) or not np.all(np.isfinite(mix)):
            raise ValueError(
                f"cannot resume {run.run_dir}: progress.jsonl record {h.get('iteration')} has "
                f"no last_{side} mix of {n} probabilities"
            )
        out.append(mix)
    return out


def _selfplay_line(rec: dict[str, Any], value: float) -> str:
    returns = "  ".join(f"{k} {v:+.4g}" for k, v in rec["agent_returns"].items())
    return (
        f"iter {rec['iteration']:3d}  steps {rec['timesteps']:8d}  returns {returns}  "
        f"NashConv last {rec['last_nash_conv']:.4f} ({rec['last_relative_nash_conv']:.2%})  "
        f"average {rec['nash_conv']:.4f} ({rec['relative_nash_conv']:.2%} of value {value:.4g})"
    )


# ----------------------------------------------------------------------- PSRO, FSP, IBR


def learn_best_response_rllib(
    entry: Trainable,
    env_kwargs: dict[str, Any],
    opponent: np.ndarray,
    cfg: GameConfig,
    seed: int,
) -> tuple[Any, int, dict[str, float]]:
    """A fresh RLlib PPO learner trained against the fixed mix ``opponent``.

    Returns the learned policy, its pure strategy (the deterministic action at the initial
    state) and its last per-agent returns.
    """
    from agents.population import initial_action
    from agents.rllib.policy import policy_of

    env_config = {**env_kwargs, "opponent": [float(p) for p in opponent], "opponent_seed": seed}
    config = _ppo(cfg, entry.gym_id, env_config, seed, cfg.steps_per_iteration)
    with warnings.catch_warnings():  # each learner re-registers RLlib's internal env id
        warnings.filterwarnings("ignore", message="Overriding environment rllib-")
        algo = config.build_algo()
    try:
        from agents.rllib.config import agent_returns, steps_sampled

        steps, returns = 0, {}
        while steps < cfg.steps_per_iteration:
            result = algo.train()
            steps += steps_sampled(result)
            returns = agent_returns(result)
        with entry.make_resolved(env_kwargs) as env:
            policy = policy_of(algo, None, env.action_space, False)
        return policy, initial_action(policy, entry, env_kwargs), returns
    finally:
        algo.stop()


class RLlibOracle(LearnedOracle):
    """Best responses learned by a fresh RLlib PPO learner each (the ``rllib`` oracle).

    Each answer is :func:`learn_best_response_rllib` (seed derived from the run's, the
    iteration and the side); it is saved as ``policies/<side>_<k>.pt`` (weights only).
    """

    def learn(self, side: str, opponent: np.ndarray, iteration: int) -> Any:
        """A fresh RLlib learner's answer to ``opponent`` (it runs to the end)."""
        from agents.population import BestResponse

        policy, action, returns = learn_best_response_rllib(
            self.entries[side], self.env_kwargs, opponent, self.cfg, self.seed(side, iteration)
        )
        return BestResponse(policy, action, returns)

    def save(self, side: str, index: int, response: Any) -> dict[str, Any]:
        """Save the RL module's weights as ``policies/<side>_<index>.pt``; returns its record."""
        return save_module(response.policy.module, self.policy_path(side, index, ".pt"))


def psro_rllib(cfg: GameConfig, report: Callable[[str], None] | None = print) -> Any:
    """PSRO, FSP or IBR (``cfg.method``) with RLlib PPO best responses, scored exactly.

    The loop of :mod:`agents.selfplay` (same meta-solver, same exploitability records) with a
    fresh RLlib PPO learner per best response (single-agent view, the other side's current mix
    as its fixed opponent). The run folder holds config.json, progress.jsonl (one record per
    iteration), scores.json, each best response's weights (``policies/<side>_<k>.pt``) and
    ``rllib_state.json`` (populations, meta-game, mixes, after every iteration), from which
    ``--resume`` continues to ``cfg.n_iterations`` in all (PSRO's meta-game needs the earlier
    policies: they are rebuilt from their weights, never unpickled).

    Raises:
        ImportError: Without ray.
        ValueError: As :func:`selfplay_rllib`.
        FileExistsError: When a new run's folder exists.
    """
    from agents.population import METHODS, MatrixGame, PopulationState, report_line, run_population
    from agents.runs import write_jsonl
    from agents.selfplay import SelfPlayResult, _final_evaluations

    if cfg.method not in METHODS:
        raise ValueError(f"unknown method {cfg.method!r}; valid methods: {', '.join(METHODS)}")
    if cfg.env not in game_names() and cfg.env in CONTINUOUS_GAMES:
        return _selfplay_continuous(cfg, report)
    say = report or (lambda line: None)
    entries, env_kwargs, reference, n, hyperparameters = _matrix_game(cfg)
    with ExitStack() as stack:
        run = open_run(cfg, stack, report, with_algorithm=False)
        env_kwargs, reference, n = _resumed_game(cfg, run, entries, env_kwargs, reference, n, say)
        L, value = reference.payoff, reference.value
        run_dir = run.run_dir
        seed_everything(cfg.run.seed, cfg.run.torch_threads)
        loop = _psro_loop_state(cfg, run, entries, env_kwargs, n)
        init_ray(cfg.run)
        begin(run, None)
        _write_config(run, "game", cfg, cfg.env, env_kwargs, hyperparameters, reference)
        stop = run.folder.watch_signals()
        oracle = RLlibOracle(cfg, run_dir, entries, env_kwargs)

        def on_iteration(rec: dict[str, Any], state: PopulationState) -> None:
            write_jsonl(run_dir / "progress.jsonl", state.history)
            run.extra = state.saved()
            run.save(None, rec["timesteps"], rec["train_seconds"])
            say(report_line(rec))

        game = MatrixGame(entries, env_kwargs, L, value)
        history = run_population(
            cfg.method, oracle, game, loop, cfg.n_iterations, cfg.run.seed, cfg.steps_per_iteration,
            lambda: stop.requested, on_iteration,
        )  # fmt: skip
        pops, meta, x, y = loop.actions, loop.meta, loop.x, loop.y
        if not history:
            return SelfPlayResult(
                run_dir, cfg.method, np.zeros(0), np.zeros(0), value, [], interrupted=stop.signum
            )
        seconds = history[-1]["train_seconds"]
        evaluations = _final_evaluations(entries, env_kwargs, reference, x, y, cfg)
        run.folder.write_scores(
            game_scores(
                cfg.method, value, x, y, history, history[-1]["timesteps"], seconds,
                backend="rllib", populations=pops, meta_payoff=meta.tolist(),
                resumed=run.resumed,
            ),
            evaluations,
        )  # fmt: skip
        return SelfPlayResult(
            run_dir, cfg.method, x, y, value, history, evaluations, pops, seconds,
            interrupted=stop.signum,
        )  # fmt: skip


def _psro_loop_state(
    cfg: GameConfig,
    run: Session,
    entries: dict[str, Trainable],
    env_kwargs: dict[str, Any],
    n: dict[str, int],
) -> Any:
    """PSRO/FSP/IBR's populations, policies, policy records, meta-game and mixes to continue.

    A new run's are empty (uniform mixes); a resumed run's are read from its state and checked
    (PSRO's earlier policies rebuilt from their weight files, :func:`load_module`).

    Raises:
        ValueError: For a state that is corrupt or does not fit the game.
    """
    from agents.population import SIDES, PopulationState

    if not run.resumed:
        state = PopulationState.new(n)
        state.history = run.history
        return state
    state, done, where = run.meta, len(run.history), run.run_dir / STATE
    pops, records = state.get("populations"), state.get("policies")
    ok = isinstance(pops, dict) and isinstance(records, dict)
    for side in SIDES:
        ok = ok and isinstance(pops.get(side), list) and isinstance(records.get(side), list)
        ok = ok and len(pops[side]) == done == len(records[side])
        ok = ok and all(isinstance(a, int) and 0 <= a < n[side] for a in pops[side])
    try:
        meta = np.array(state.get("meta_payoff"), dtype=float).reshape(
            (done, done) if cfg.method == "psro" else (0, 0)
        )
        x, y = np.array(state.get("x"), dtype=float), np.array(state.get("y"), dtype=float)
    except (TypeError, ValueError):
        ok = False
    if not ok or x.shape != (n["defender"],) or y.shape != (n["attacker"],):
        raise ValueError(f"cannot resume {run.run_dir}: {where} is corrupt or not of this game")
    models: dict[str, list[Any]] = {side: [] for side in SIDES}
    if cfg.method == "psro":  # the meta-game plays new policies against the earlier ones
        from agents.rllib.config import ppo_config
        from agents.rllib.envs import make_view
        from agents.rllib.policy import RLlibPolicy

        for side in SIDES:
            gym_id = entries[side].gym_id
            config = ppo_config(gym_id, env_kwargs, hp=cfg.hp, total_timesteps=1)
            with make_view(gym_id, env_kwargs) as env:
                for record in records[side]:
                    module = load_module(config, env, record, run.run_dir / "policies", run.run_dir)
                    models[side].append(RLlibPolicy(module, env.action_space, False))
    return PopulationState(pops, models, records, meta, x, y, run.history, run.seconds)


def _selfplay_continuous(cfg: GameConfig, report: Callable[[str], None] | None = print) -> Any:
    """Self-play on a continuous-action game: both players learn; per-agent returns reported.

    There is no exact payoff matrix, so no exploitability: after training, each side with a
    registered view (for ``detection_game_v0`` the defender, scored against OBDD's α) plays its
    view against the view's fixed opponent, scored by :func:`agents.evaluate.evaluate`.
    """
    from agents.evaluate import evaluate
    from agents.population import SIDES
    from agents.registry import REGISTRY
    from agents.rllib.config import rllib_hyperparameters
    from agents.rllib.policy import policy_of
    from agents.selfplay import SelfPlayResult
    from agents.training import check_env_kwargs, saved_env_kwargs

    check_algo(cfg.algo)
    say = report or (lambda line: None)
    entries = {side: REGISTRY[cfg.env, side] for side in SIDES if (cfg.env, side) in REGISTRY}
    first = next(iter(entries.values()))
    hyperparameters = rllib_hyperparameters(cfg.hp)
    env_kwargs = first.env_kwargs(cfg.scenario, **parse_env_kwargs(cfg.env_kwargs))
    check_env_kwargs(first.gym_id, env_kwargs)
    with ExitStack() as stack:
        run = open_run(cfg, stack, report)
        saved = saved_env_kwargs(env_kwargs, run.folder.saved_resolved, say)
        if saved != env_kwargs:  # a resume plays the game its run was resolved with
            env_kwargs = saved
            check_env_kwargs(first.gym_id, env_kwargs)
        per_iteration, algo, stop = _start_selfplay(run, cfg, env_kwargs, hyperparameters, None)
        run_dir = run.run_dir

        def on_iteration(rec: dict[str, Any]) -> None:
            if rec["timesteps"] % per_iteration == 0:
                returns = "  ".join(f"{k} {v:+.4g}" for k, v in rec["agent_returns"].items())
                say(f"iter {rec['iteration']:3d}  steps {rec['timesteps']:8d}  returns {returns}")

        history, steps, seconds = _iterate_selfplay(
            cfg, algo, run, stop, per_iteration, on_iteration
        )
        evaluations = {}
        seed = derived_seed(cfg.run.seed, 20_000)
        for side, entry in entries.items():
            with entry.make_resolved(env_kwargs) as env:
                policy = policy_of(algo, side, env.action_space, False)
                reference = entry.reference_of(env)
                evaluations[f"{side} (learned, vs the view's opponent)"] = evaluate(
                    policy, env, cfg.final_eval_episodes, seed, reference
                )
                if reference is not None and reference.policy is not None:
                    evaluations[f"{side}: {reference.name}"] = evaluate(
                        reference.policy, env, cfg.final_eval_episodes, seed, reference
                    )
        algo.save_to_path(str((run_dir / "checkpoint").resolve()))
        scores = _run_scores(run, history, steps, seconds, method="selfplay", backend="rllib")
        run.folder.write_scores(scores, evaluations)
        return SelfPlayResult(
            run_dir, "selfplay", np.zeros(0), np.zeros(0), math.nan, history, evaluations, {},
            seconds, interrupted=stop.signum,
        )  # fmt: skip
