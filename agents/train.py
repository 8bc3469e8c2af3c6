"""Train RL attackers and defenders on fdia_env and score them against the analytic optima.

The command line of ``fdia-train`` (the console script of an installed fdia-env) and of
``python train.py`` in a checkout: ``fdia-train --help`` lists the commands and every option
with its default; :func:`main` runs the same command line from Python, :func:`cli` as a program.
"""

from __future__ import annotations

import signal
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Annotated, Any

import tyro

from agents.config import DEFENDER_ENV, GameConfig, SweepConfig, TrainConfig, is_torch_ppo
from agents.evaluate import Evaluation

COMMANDS = ("attacker", "defender", "game", "sweep")
CONSOLE_SCRIPT = "fdia-train"

DESCRIPTION = "\n\n".join(
    [
        "Train RL attackers and defenders on fdia_env and score them against the analytic optima.",
        "attacker: the attacker of a registered env, against a fixed defender or a passive "
        "filter. defender: the defender of a two-player env, against a fixed attacker. game: "
        "self-play (PSRO, fictitious self-play, iterated best response) with learned best "
        "responses (--algo PPO, A2C, DQN or torch-ppo; --algo exact answers exactly on the "
        "payoff matrix), reporting the exploitability after every iteration.",
        "Each run writes runs/<env>-<algo>-s<seed>-<time>/ (config.json, checkpoints/, tb/ with "
        "the tensorboard extra, evaluations.jsonl, scores.json, learning_curve.png) and prints "
        "the learned policy, the analytic answer and random play, scored by one evaluation loop "
        "(agents.evaluate).",
        "Examples: "
        "python train.py attacker --algo MaskablePPO (the sparse attack's newest version, "
        "sparse_attack_v2; an older one by name: --env sparse_attack_v0); "
        "python train.py attacker --scenario grid-ieee14 (the sequential format, with the "
        "scenario's defaults: agents.config.SCENARIO_DEFAULTS); "
        "python train.py attacker --task sparse/ch4-position-v0 (a benchmark task's env and "
        "player, scored on the task as python -m agents.bench score scores it); "
        "python train.py game --scenario grid-ieee14; "
        "python train.py attacker --env covariance_attack_v0 --algo SAC; "
        "python train.py defender --algo DQN; "
        "python train.py game --method psro; "
        "python train.py game --task sensor-game/m10-strong-defender-v0 (a benchmark game "
        "task: both players by double oracle with exact best responses, the task's player "
        "scored as python -m agents.bench score scores it); "
        "python train.py attacker --resume (continues the latest run of that env, algo, seed); "
        "python train.py attacker --algo torch-ppo --device cuda --num-envs 4096 "
        "--total-timesteps 2000000 (PPO with env, rollout buffer and policy on the device).",
        "--backend rllib runs the attacker, defender and game commands on Ray RLlib (PPO; "
        "--num-env-runners K, --ray-address ADDR for a running cluster; game adds --method "
        "selfplay, both players learning at once; --resume continues a run from its saved "
        "weights, optimizer state and counters); sweep runs a Ray Tune grid over seeds, "
        "scenarios and hyperparameters. Both need the fdia-env[rllib] extra.",
        "Checkpoints hold tensors and JSON only and load without unpickling; --trust-checkpoint "
        "allows resuming runs saved as stable-baselines3 .zip files (pickle: can run code). "
        "Ctrl-C (SIGINT) or SIGTERM stops at the next step and saves a checkpoint and the scores "
        "(exit status 130 or 143); a second Ctrl-C aborts at once. Exit status 2: bad options "
        "or an unusable checkpoint; 1: another I/O error.",
    ]
)

Command = (
    Annotated[
        TrainConfig,
        tyro.conf.subcommand(
            "attacker",
            default=TrainConfig(agent="attacker"),
            description="Train an attacker against a fixed defender (or a passive filter).",
        ),
    ]
    | Annotated[
        TrainConfig,
        tyro.conf.subcommand(
            "defender",
            default=TrainConfig(agent="defender", env=DEFENDER_ENV),
            description="Train a defender against a fixed attacker.",
        ),
    ]
    | Annotated[
        GameConfig,
        tyro.conf.subcommand(
            "game",
            default=GameConfig(),
            description="Self-play on a two-player game with learned best responses.",
        ),
    ]
    | Annotated[
        SweepConfig,
        tyro.conf.subcommand(
            "sweep",
            default=SweepConfig(),
            description="A Ray Tune sweep of RLlib PPO runs over seeds, scenarios and "
            "hyperparameters: one results table (needs the fdia-env[rllib] extra).",
        ),
    ]
)


def program() -> tuple[str, str]:
    """``(name, invocation)`` of the running program, for its messages.

    ``("fdia-train", "fdia-train")`` when run as the console script, otherwise
    ``("train.py", "python train.py")`` (the checkout's script, or :func:`main` from Python).
    """
    if Path(sys.argv[0] if sys.argv else "").name == CONSOLE_SCRIPT:
        return CONSOLE_SCRIPT, CONSOLE_SCRIPT
    return "train.py", "python train.py"


def parse(argv: Sequence[str]) -> TrainConfig | GameConfig:
    """Parse the command line (``--help`` alone prints every command's options)."""
    argv = list(argv)
    prog, invocation = program()
    description = DESCRIPTION.replace("python train.py", invocation)
    if argv in (["-h"], ["--help"]):
        for args in (["--help"], *([c, "--help"] for c in COMMANDS)):
            try:
                tyro.cli(Command, args=args, prog=prog, description=description)
            except SystemExit:
                print()
        raise SystemExit(0)
    return tyro.cli(Command, args=argv, prog=prog, description=description)


def with_saved_options(cfg: TrainConfig | GameConfig, argv: Sequence[str]):
    """For ``--resume``: re-parse ``argv`` with the resumed run's saved options as defaults.

    So ``train.py attacker --resume`` continues the latest run of its env, algo and seed with
    its own settings; an option given explicitly must agree with it (checked by the trainer),
    except the training length, which may be extended. A run's ``--task`` is kept; another one
    is refused here (:func:`agents.lifecycle.check_same_task`).
    """
    from agents.checkpoint import read_json
    from agents.lifecycle import check_same_task
    from agents.runs import config_from_dict, resume_dir

    if cfg.run.backend == "rllib":
        from agents.rllib.state import STATE as marker
        from agents.rllib.train import rllib_prefix as prefix_of
    elif isinstance(cfg, GameConfig):
        from agents.selfplay import STATE as marker
        from agents.selfplay import game_prefix as prefix_of
    else:
        from agents.training import CHECKPOINT_STATE as marker
        from agents.training import train_prefix as prefix_of
    # a run without a checkpoint (stopped before its first) starts again from step 0
    run_dir = resume_dir(cfg.run.runs_root, cfg.run.run_dir, prefix_of(cfg), marker, fresh=True)
    config_path = Path(run_dir) / "config.json"
    saved = read_json(config_path, "run config").get("config")
    if not isinstance(saved, dict):
        raise ValueError(f"run config {config_path} is corrupt: it has no 'config' object")
    try:
        default = config_from_dict(type(cfg), saved)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"run config {config_path} is corrupt: {exc}") from None
    default.run.run_dir = Path(run_dir)
    argv = list(argv)
    if "--env-kwargs" in argv:  # given again: parsed as given (tyro reads a non-empty dict
        default.env_kwargs = {}  # default as --env-kwargs.NAME options), checked by the trainer
    command = next(a for a in argv if a in COMMANDS)
    resumed = tyro.cli(type(cfg), args=argv[argv.index(command) + 1 :], default=default)
    # before the task's options are checked against the run's (its --env, say)
    check_same_task(saved.get("task"), getattr(resumed, "task", None), Path(run_dir))
    return resumed


def format_table(rows: dict[str, Evaluation]) -> str:
    """The final table: policy, mean ± 95 % CI, reference, the score against it.

    The score is the return as a percentage of the reference (the analytic answer of the run's
    env), or in a game the exploitability; a ``--task`` run's normalised score is printed
    above the table (:func:`agents.task_runs.score_lines`).
    """
    ref = next(iter(rows.values()))
    ref_head = f"reference ({ref.reference_name})" if ref.reference_name else "reference"
    game = any(ev.score_name == "exploitability" for ev in rows.values())
    score_head = "exploitability" if game else "% of reference"
    lines = [f"  {'policy':28s} {'mean ± 95% CI':>26s} {ref_head:>26s}  {score_head}"]
    for name, ev in rows.items():
        if ev.ci95 != ev.ci95:  # NaN: one episode
            ci = ""
        else:  # rounding noise of a deterministic env shows as ± 0
            ci = f" ± {0.0 if ev.ci95 <= 1e-12 * abs(ev.mean) else ev.ci95:.4g}"
        mean = f"{ev.mean:.6g}{ci}"
        reference = "-" if ev.reference is None else f"{ev.reference:.6g}"
        lines.append(f"  {name:28s} {mean:>26s} {reference:>26s}  {ev.score_text()}")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> object:
    """Run one command; returns its result (``TrainResult`` or ``SelfPlayResult``).

    A result whose ``interrupted`` is set was stopped by that signal (its checkpoint and scores
    are written); :func:`cli` turns it into the exit status.

    Raises:
        SystemExit: For an option outside its allowed values (status 2, message naming it).
        ValueError: For an unknown env, scenario, algorithm or method (listing the valid names),
            an env option the env does not take, a device not present, nothing to resume, or
            a checkpoint that is corrupt, outside its run folder or (without
            ``--trust-checkpoint``) pickle-based.
        FileExistsError: When the run folder exists and ``--resume`` is not given.
        agents.interrupt.Aborted: On a second SIGINT/SIGTERM.
    """
    argv = sys.argv[1:] if argv is None else list(argv)
    cfg = parse(argv)
    if isinstance(cfg, SweepConfig):
        from agents.rllib.sweep import run_sweep

        return run_sweep(cfg)
    if isinstance(cfg, GameConfig) and cfg.task is not None:  # before any backend or resume
        from agents.game_task_runs import game_task_setup

        game_task_setup(cfg)
    torch_ppo = isinstance(cfg, TrainConfig) and is_torch_ppo(cfg.algo)
    if torch_ppo and cfg.run.backend != "sb3":
        raise ValueError("--algo torch-ppo runs in this process (--backend sb3, the default)")
    if cfg.run.resume and cfg.run.run_dir is not None and _backend_of(cfg.run.run_dir) == "rllib":
        if cfg.run.backend != "rllib":
            raise ValueError(
                f"{cfg.run.run_dir} is an RLlib run: resume it with --backend rllib --resume"
            )
    rllib = cfg.run.backend == "rllib"
    if rllib:
        from agents.rllib import require_ray

        require_ray()
    elif isinstance(cfg, GameConfig) and cfg.method == "selfplay":
        raise ValueError("--method selfplay (both players learning at once) needs --backend rllib")
    if cfg.run.resume:
        cfg = with_saved_options(cfg, argv)
        torch_ppo = isinstance(cfg, TrainConfig) and is_torch_ppo(cfg.algo)
    if isinstance(cfg, TrainConfig) and cfg.num_envs is not None and not torch_ppo:
        from agents.training import setup_of

        algo = "RLlib" if rllib else setup_of(cfg).algo  # the scenario's default resolved
        if algo != "MaskablePPO":
            raise ValueError(
                "--num-envs applies to --algo torch-ppo and MaskablePPO only (MaskablePPO: the "
                f"env's native vector env of that many members), got {algo}; the other "
                "stable-baselines3 algorithms train on one env and RLlib chooses its own envs"
            )
    if torch_ppo:
        from agents.torch_ppo_train import train_torch_ppo_run

        run = train_torch_ppo_run(cfg)
        learned = next(iter(run.evaluations.values()))
        return _summary(
            run,
            f"\ntorch-ppo {cfg.agent} on {learned.env_id}, {run.timesteps} steps in "
            f"{run.train_seconds:.1f} s ({run.timesteps / max(run.train_seconds, 1e-9):,.0f} "
            f"env-steps/s, {run.num_envs} envs on {run.device}, seed {cfg.run.seed})",
        )
    if isinstance(cfg, GameConfig):
        if rllib:
            from agents.rllib.train import selfplay_rllib as run_selfplay
        else:
            from agents.selfplay import run_selfplay

        game = run_selfplay(cfg)
        if not game.history:  # stopped before its first iteration finished
            return game
        last = game.history[-1]
        if "nash_conv" not in last:  # a continuous game (RLlib self-play): no exact matrix game
            returns = ", ".join(f"{k} {v:.6g}" for k, v in last["agent_returns"].items())
            return _summary(
                game,
                f"\nSELFPLAY (RLlib PPO) on {cfg.env}: {last['timesteps']} steps in "
                f"{game.train_seconds:.0f} s (seed {cfg.run.seed}); last mean returns: {returns}",
                marks=(),
            )
        on = f"task {cfg.task}" if cfg.task is not None else cfg.env
        return _summary(
            game,
            f"\n{game.method.upper()}{' (RLlib PPO)' if rllib else ''} on {on}: "
            f"{len(game.history)} iterations",
            f", {last['timesteps']} steps in {game.train_seconds:.0f} s (seed {cfg.run.seed}); "
            f"NashConv {last['nash_conv']:.4g} = {last['relative_nash_conv']:.2%} of the value "
            f"{game.value:.6g}",
            marks=("interrupted",),
        )

    if rllib:
        from agents.rllib.train import train_rllib

        result = train_rllib(cfg)
        learned = next(iter(result.evaluations.values()))
        last = result.history[-1]["agent_returns"] if result.history else {}
        returns = ", ".join(f"{k} {v:.6g}" for k, v in last.items())
        return _summary(
            result,
            f"\nRLlib PPO {cfg.agent} on {learned.env_id}, {result.timesteps} steps in "
            f"{len(result.history)} iterations, {result.train_seconds:.0f} s (seed {cfg.run.seed})",
            f"; last iteration's mean return: {returns}" if returns else "",
        )

    from agents.training import train

    result = train(cfg)
    learned = next(iter(result.evaluations.values()))
    envs = f", {result.model.n_envs} envs" if result.model.n_envs > 1 else ""
    line = f"{result.model.num_timesteps} steps in {result.train_seconds:.0f} s"
    return _summary(
        result,
        f"\n{learned.policy} {cfg.agent} on {learned.env_id}, {line} (seed {cfg.run.seed}{envs})",
    )


def _summary(
    run: Any, headline: str, tail: str = "", marks: tuple[str, ...] = ("resumed", "interrupted")
) -> Any:
    """Print a finished run's headline, its run folder and evaluations; return the run.

    Args:
        run: The run's result (``run_dir``, ``evaluations`` and the flags named in ``marks``).
        headline: The summary line's start.
        tail: The summary line's end, after the marks.
        marks: The run's boolean attributes shown as `` (name)`` where true.

    Returns:
        ``run``.
    """
    shown = "".join(f" ({mark})" for mark in marks if getattr(run, mark))
    print(headline + shown + tail)
    print(f"  run folder: {run.run_dir}")
    task_score = getattr(run, "task_score", None)
    if task_score is not None:
        from fdia_env.tasks import get

        task = get(task_score.task)
        if task.is_game:  # a game --task run: its player's final mix
            from agents.game_task_runs import score_lines as game_score_lines

            print("\n".join(game_score_lines(task_score, task)))
        else:
            from agents.task_runs import score_lines

            given = getattr(run, "task_given", True)
            print("\n".join(score_lines(task_score, task, given)))
    print(format_table(run.evaluations))
    return run


def _backend_of(run_dir: Path) -> str:
    """The backend a run folder was written by (``sb3`` for runs that do not say)."""
    import json

    try:
        saved = json.loads((Path(run_dir) / "config.json").read_text())
    except (OSError, ValueError):
        return "sb3"
    resolved = saved.get("resolved") if isinstance(saved, dict) else None
    backend = resolved.get("backend", "sb3") if isinstance(resolved, dict) else "sb3"
    return backend if isinstance(backend, str) else "sb3"


def cli(argv: Sequence[str] | None = None) -> int:
    """Run :func:`main` as a program: one-line messages on stderr, and the exit status.

    Exit status: 0 done; 2 bad options or an unusable checkpoint (``train.py: error: ...``);
    1 another I/O error; 128 + the signal number when SIGINT (130) or SIGTERM (143) stopped it,
    after writing the final checkpoint and scores, or when a second one aborted it at once.
    """
    from agents.interrupt import Aborted, exit_status
    from agents.rllib import MissingExtraError, ZeroStepsSampled

    prog, invocation = program()
    try:
        result = main(argv)
    except Aborted as exc:
        print(
            f"{prog}: aborted by a second {exc.args[0]}; what was saved before it is kept "
            "(the last checkpoint, if any)",
            file=sys.stderr,
        )
        return exit_status(exc.signum)
    except KeyboardInterrupt:
        print(
            f"{prog}: interrupted before training started; nothing new was saved", file=sys.stderr
        )
        return exit_status(signal.SIGINT)
    except (ValueError, FileExistsError, MissingExtraError) as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 2
    except (OSError, ZeroStepsSampled) as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 1
    signum = getattr(result, "interrupted", None)
    if signum is None:
        return 0
    name = signal.Signals(signum).name
    rllib = _backend_of(result.run_dir) == "rllib"
    if hasattr(result, "populations"):  # the game command
        if not result.history:
            print(
                f"{prog}: stopped by {name} before the first iteration finished; nothing was saved",
                file=sys.stderr,
            )
            return exit_status(signum)
        done = f"{len(result.history)} iterations"
        what = "state and scores" if rllib else "state, policies and scores"
    elif rllib:
        done = f"{result.timesteps} steps"
        what = "state and scores"
    elif not hasattr(result, "model"):  # torch-ppo
        done = f"{result.timesteps} steps"
        what = "training state, model and scores"
    else:
        done = f"{result.model.num_timesteps} steps"
        what = "checkpoint, model and scores"
    command = next((a for a in (sys.argv[1:] if argv is None else argv) if a in COMMANDS), "")
    backend = " --backend rllib" if rllib else ""
    print(
        f"{prog}: stopped by {name} after {done}; {what} saved in {result.run_dir}; "
        f"continue with: {invocation} {command}{backend} --resume --run-dir {result.run_dir}",
        file=sys.stderr,
    )
    return exit_status(signum)


if __name__ == "__main__":
    raise SystemExit(cli())
