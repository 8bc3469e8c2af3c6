"""Train RL attackers and defenders on fdia_env and score them against the analytic optima.

``python train.py --help`` lists the commands and every option with its default; the module's
``main(argv)`` runs the same command line from Python.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Annotated

import tyro

from agents.config import GameConfig, TrainConfig
from agents.evaluate import Evaluation

COMMANDS = ("attacker", "defender", "game")

DESCRIPTION = "\n\n".join(
    [
        "Train RL attackers and defenders on fdia_env and score them against the analytic optima.",
        "attacker: the attacker of a registered env, against a fixed defender or a passive "
        "filter. defender: the defender of a two-player env, against a fixed attacker. game: "
        "self-play (PSRO, fictitious self-play, iterated best response) with learned best "
        "responses, reporting the exploitability after every iteration.",
        "Each run writes runs/<env>-<algo>-s<seed>-<time>/ (config.json, checkpoints/, tb/, "
        "evaluations.jsonl, scores.json, learning_curve.png) and prints the learned policy, the "
        "analytic answer and random play, scored by one evaluation loop (agents.evaluate).",
        "Examples: "
        "python train.py attacker --env sparse_attack_v0 --algo MaskablePPO; "
        "python train.py attacker --env covariance_attack_v0 --algo SAC; "
        "python train.py defender --algo DQN; "
        "python train.py game --method psro; "
        "python train.py attacker --resume (continues the latest run of that env, algo, seed).",
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
            default=TrainConfig(agent="defender", env="sensor_game_v0"),
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
)


def parse(argv: Sequence[str]) -> TrainConfig | GameConfig:
    """Parse the command line (``--help`` alone prints every command's options)."""
    argv = list(argv)
    if argv in (["-h"], ["--help"]):
        for args in (["--help"], *([c, "--help"] for c in COMMANDS)):
            try:
                tyro.cli(Command, args=args, prog="train.py", description=DESCRIPTION)
            except SystemExit:
                print()
        raise SystemExit(0)
    return tyro.cli(Command, args=argv, prog="train.py", description=DESCRIPTION)


def with_saved_options(cfg: TrainConfig | GameConfig, argv: Sequence[str]):
    """For ``--resume``: re-parse ``argv`` with the resumed run's saved options as defaults.

    So ``train.py attacker --resume`` continues the latest run of its env, algo and seed with
    its own settings; an option given explicitly must agree with it (checked by the trainer),
    except the training length, which may be extended.
    """
    from agents.runs import config_from_dict, latest_run

    if isinstance(cfg, GameConfig):
        from agents.selfplay import game_prefix as prefix_of
    else:
        from agents.training import train_prefix as prefix_of
    run_dir = cfg.run.run_dir or latest_run(cfg.run.runs_root, prefix_of(cfg))
    if run_dir is None or not (Path(run_dir) / "config.json").is_file():
        return cfg  # the trainer reports what is missing
    saved = json.loads((Path(run_dir) / "config.json").read_text())["config"]
    default = config_from_dict(type(cfg), saved)
    default.run.run_dir = Path(run_dir)
    argv = list(argv)
    command = next(a for a in argv if a in COMMANDS)
    return tyro.cli(type(cfg), args=argv[argv.index(command) + 1 :], default=default)


def format_table(rows: dict[str, Evaluation]) -> str:
    """The final table: policy, mean ± 95 % CI, reference, score."""
    ref = next(iter(rows.values()))
    ref_head = f"reference ({ref.reference_name})" if ref.reference_name else "reference"
    lines = [f"  {'policy':28s} {'mean ± 95% CI':>26s} {ref_head:>26s}  score"]
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

    Raises:
        ValueError: For an unknown env, scenario, algorithm or method (listing the valid names).
        FileExistsError: When the run folder exists and ``--resume`` is not given.
    """
    argv = sys.argv[1:] if argv is None else list(argv)
    cfg = parse(argv)
    if cfg.run.resume:
        cfg = with_saved_options(cfg, argv)
    if isinstance(cfg, GameConfig):
        from agents.selfplay import run_selfplay

        game = run_selfplay(cfg)
        last = game.history[-1]
        print(
            f"\n{game.method.upper()} on {cfg.env}: {len(game.history)} iterations, "
            f"{last['timesteps']} steps in {game.train_seconds:.0f} s (seed {cfg.run.seed}); "
            f"NashConv {last['nash_conv']:.4g} = {last['relative_nash_conv']:.2%} of the value "
            f"{game.value:.6g}"
        )
        print(f"  run folder: {game.run_dir}")
        print(format_table(game.evaluations))
        return game

    from agents.training import train

    result = train(cfg)
    learned = next(iter(result.evaluations.values()))
    print(
        f"\n{learned.policy} {cfg.agent} on {learned.env_id}, {result.model.num_timesteps} "
        f"steps in {result.train_seconds:.0f} s (seed {cfg.run.seed})"
        + (" (resumed)" if result.resumed else "")
    )
    print(f"  run folder: {result.run_dir}")
    print(format_table(result.evaluations))
    return result


if __name__ == "__main__":
    try:
        main()
    except (ValueError, FileExistsError) as exc:
        print(f"train.py: error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
