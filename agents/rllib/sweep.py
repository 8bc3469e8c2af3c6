"""``train.py sweep``: a Ray Tune grid of RLlib PPO trials, one results table.

Each trial (:func:`trial`) builds :func:`agents.rllib.config.ppo_config` for its seed,
scenario and hyperparameters, trains ``total_timesteps`` env steps (reporting per-agent returns
to Tune after every iteration) and is scored by :func:`agents.evaluate.evaluate` against the
analytic reference: the ratio to the optimum for one learning player, the exploitability of
the players' average mixes (:func:`agents.rllib.train.selfplay_rllib`'s measure) for
``--agent both``. The sweep's folder ``runs/sweep-<env>-<agent>-<time>/`` holds Tune's trial
folders (``tune/``), ``config.json``, ``results.csv`` and ``results.json``.
"""

from __future__ import annotations

import csv
import itertools
import math
import time
from typing import Any

import numpy as np

from agents.config import Hyperparameters, SweepConfig, parse_env_kwargs
from agents.registry import get
from agents.runs import config_dict, new_run_dir, write_json

COLUMNS = ("scenario", "seed", "learning_rate", "ent_coef")


def trial(config: dict[str, Any]) -> dict[str, Any]:
    """One Tune trial: train, report per-agent returns each iteration, score at the end."""
    import torch
    from ray import tune

    from agents.evaluate import evaluate
    from agents.rllib.config import agent_returns, ppo_config, steps_sampled
    from agents.rllib.envs import is_masked, make_multi_agent, make_view
    from agents.rllib.policy import policy_of
    from agents.rllib.train import initial_mixes
    from agents.seeding import derived_seed
    from baselines.game import exploitability

    torch.set_num_threads(1)
    hp = Hyperparameters(**config["hp"])
    both = config["agent"] == "both"
    entry = get(config["env"], "attacker" if both else config["agent"])
    env_kwargs = entry.env_kwargs(config["scenario"], **config["env_kwargs"])
    env_name = entry.env if both else entry.gym_id
    env_config = dict(env_kwargs)
    if not both and config.get("opponent_probs") is not None:
        env_config["opponent"] = config["opponent_probs"]
    algo = ppo_config(
        env_name,
        env_config,
        hp=hp,
        num_env_runners=config["num_env_runners"],
        envs_per_env_runner=config["envs_per_env_runner"],
        seed=config["seed"],
        total_timesteps=config["total_timesteps"],
        sample_timeout_s=config["sample_timeout_s"],
    ).build_algo()
    try:
        steps, start = 0, time.perf_counter()
        mixes: dict[str, list[np.ndarray]] = {"attacker": [], "defender": []}
        if both:
            parallel = make_multi_agent(entry.env, env_kwargs).parallel
            policies = {
                side: policy_of(algo, side, parallel.action_space(side), False) for side in mixes
            }
        returns: dict[str, float] = {}
        while steps < config["total_timesteps"]:
            result = algo.train()
            steps += steps_sampled(result)
            returns = agent_returns(result)
            metrics = {"timesteps": steps, **{f"return_{k}": v for k, v in returns.items()}}
            if both:
                now = initial_mixes(policies, parallel)
                for side in mixes:
                    mixes[side].append(now[side])
            tune.report(metrics)
        final: dict[str, Any] = {
            "timesteps": steps,
            "train_seconds": round(time.perf_counter() - start, 3),
            **{f"return_{k}": v for k, v in returns.items()},
        }
        seed = derived_seed(config["seed"], 10_000)
        if both:
            reference = entry.reference_of(entry.make_resolved(env_kwargs))
            half = len(mixes["attacker"]) // 2
            x = np.mean(mixes["defender"][half:], axis=0)
            y = np.mean(mixes["attacker"][half:], axis=0)
            e = exploitability(reference.payoff, x, y, reference.value)
            final.update(
                reference=reference.value,
                reference_name=reference.name,
                score=e.nash_conv,
                score_name="NashConv of the average mixes",
                relative_score=e.nash_conv / abs(reference.value),
            )
        else:
            from fdia_env.envs.opponents import FixedMix

            probs = config.get("opponent_probs")
            opponent = {} if probs is None else {"opponent": FixedMix(probs)}
            with make_view(entry.gym_id, env_config) as view:
                masked = is_masked(view.observation_space)
            with entry.make_resolved(env_kwargs, **opponent) as env:
                policy = policy_of(algo, None, env.action_space, masked)
                ev = evaluate(policy, env, config["final_eval_episodes"], seed)
            final.update(
                eval_mean=ev.mean,
                reference=ev.reference,
                reference_name=ev.reference_name,
                score=ev.score,
                score_name=ev.score_name,
                relative_score=ev.extras.get("relative_exploitability", ev.score),
            )
        tune.report(final)
    finally:
        algo.stop()


def trial_grid(cfg: SweepConfig) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """The settings every trial shares, and one dict per trial (the swept values)."""
    both = cfg.agent == "both"
    entry = get(cfg.env, "attacker" if both else cfg.agent)
    if both and not entry.game:
        raise ValueError(f"--agent both needs a two-player game; {cfg.env} is not one")
    env_kwargs = parse_env_kwargs(cfg.env_kwargs)
    scenarios = list(cfg.scenarios) or [entry.default_scenario]
    for scenario in scenarios:
        entry.env_kwargs(scenario, **env_kwargs)  # an unknown scenario lists the valid ones
    from agents.rllib.config import rllib_hyperparameters

    base = {k: v for k, v in config_dict(cfg.hp).items() if v is not None}
    defaults = rllib_hyperparameters(cfg.hp)
    opponent_probs = None
    if not both and entry.game and cfg.opponent == "equilibrium":
        from agents.training import opponent_factory

        opponent_probs = [float(p) for p in opponent_factory(entry, "equilibrium", {})().probs]
    common = {
        "env": cfg.env,
        "agent": cfg.agent,
        "env_kwargs": env_kwargs,
        "opponent_probs": opponent_probs,
        "total_timesteps": cfg.total_timesteps,
        "final_eval_episodes": cfg.final_eval_episodes,
        "num_env_runners": cfg.run.num_env_runners,
        "envs_per_env_runner": cfg.run.envs_per_env_runner,
        "sample_timeout_s": cfg.run.sample_timeout_s,
    }
    grid = []
    for scenario, seed, lr, ent in itertools.product(
        scenarios,
        cfg.seeds,
        cfg.learning_rates or [defaults["learning_rate"]],
        cfg.ent_coefs or [defaults["ent_coef"]],
    ):
        hp = {**base, "learning_rate": lr, "ent_coef": ent}
        if "net_arch" in hp:
            hp["net_arch"] = tuple(hp["net_arch"])
        grid.append(
            {"scenario": scenario, "seed": seed, "learning_rate": lr, "ent_coef": ent, "hp": hp}
        )
    return common, grid


def _trial_entry(config: dict[str, Any]) -> None:
    trial({**config["common"], **config["point"]})


def run_sweep(cfg: SweepConfig, report: Any = print) -> dict[str, Any]:
    """Run the sweep with Ray Tune and write its results table; returns the run folder and rows.

    Raises:
        agents.rllib.MissingExtraError: Without ray.
        ValueError: For an unknown env, scenario or hyperparameter, or ``--agent both`` on an
            env that is not a game.
        FileExistsError: When the run folder exists.
    """
    from agents.rllib import require_ray

    require_ray()
    from ray import tune

    from agents.rllib.train import init_ray

    if cfg.run.resume:
        raise ValueError("--resume is not supported by train.py sweep; start a new sweep")
    common, grid = trial_grid(cfg)
    run_dir = new_run_dir(
        cfg.run.runs_root, cfg.run.run_dir, f"sweep-{cfg.env}-{cfg.agent}".replace("/", "_")
    )
    run_dir.mkdir(parents=True)
    write_json(run_dir / "config.json", {"command": "sweep", "config": config_dict(cfg)})
    init_ray(cfg.run)
    cpus = 1 + cfg.run.num_env_runners
    tuner = tune.Tuner(
        tune.with_resources(_trial_entry, {"cpu": cpus}),
        param_space={"common": common, "point": tune.grid_search(grid)},
        tune_config=tune.TuneConfig(max_concurrent_trials=cfg.max_concurrent_trials),
        run_config=tune.RunConfig(name="tune", storage_path=str(run_dir.resolve()), verbose=0),
    )
    results = tuner.fit()
    rows = []
    for res in results:
        point = res.config["point"]
        row = {k: point[k] for k in COLUMNS}
        metrics = res.metrics or {}
        for key in sorted(metrics):
            if key.startswith("return_") or key in (
                "timesteps",
                "train_seconds",
                "eval_mean",
                "reference",
                "reference_name",
                "score",
                "score_name",
                "relative_score",
            ):
                row[key] = metrics[key]
        row["error"] = None if res.error is None else str(res.error).splitlines()[0][:300]
        rows.append(row)
    rows.sort(key=lambda r: tuple(r[k] for k in COLUMNS))
    keys = list(dict.fromkeys(k for r in rows for k in r))
    with open(run_dir / "results.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=keys)
        writer.writeheader()
        writer.writerows(rows)
    write_json(run_dir / "results.json", rows)
    if report is not None:
        report(format_results(rows))
        report(f"  sweep folder: {run_dir} (results.csv, results.json, tune/)")
    return {"run_dir": run_dir, "rows": rows}


def format_results(rows: list[dict[str, Any]]) -> str:
    """The results table: swept values, per-agent returns, reference and score."""
    returns = sorted({k for r in rows for k in r if k.startswith("return_")})
    evals = ["eval_mean"] if any("eval_mean" in r for r in rows) else []
    head = [*COLUMNS, *returns, *evals, "reference", "score"]
    lines = ["  " + "  ".join(f"{h:>14s}" for h in head)]
    for r in rows:
        cells = []
        for h in head:
            v = r.get(h)
            if isinstance(v, float) and math.isnan(v):
                v = "nan"
            elif (
                h == "score"
                and isinstance(v, float)
                and r.get("score_name", "").startswith("ratio")
            ):
                v = f"{v:.2%}"
            elif isinstance(v, float):
                v = f"{v:.6g}"
            cells.append(f"{'-' if v is None else v!s:>14s}")
        line = "  " + "  ".join(cells)
        if r.get("score_name"):
            line += f"  ({r['score_name']})"
        if r.get("error"):
            line += f"  FAILED: {r['error']}"
        lines.append(line)
    return "\n".join(lines)
