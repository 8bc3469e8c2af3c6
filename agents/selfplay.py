"""Equilibrium finding with learned best responses on a one-shot two-player game.

Each iteration trains a fresh SB3 learner (PPO, A2C or DQN) for each side on its Gymnasium view
against the other side's current mixed strategy (a :class:`~fdia_env.envs.opponents.FixedMix`),
then updates the mixes:

- ``ibr`` (iterated best response): each side's mix is its latest best response;
- ``fsp`` (fictitious self-play): the uniform average of all its best responses so far;
- ``psro`` (policy-space response oracles, Lanctot et al., NeurIPS 2017): the learned policies
  form two populations; their payoff against each other is measured by playing them in the env
  (the empirical meta-game), and ``baselines.game.solve_zero_sum`` (the LP) gives the meta mix
  over each population.

In the one-shot game a policy acts once, on the constant initial observation, so a learned
deterministic policy is a pure strategy (its action there) and a mix over policies is a mixed
strategy over actions. After every iteration the exploitability of the current pair is measured
exactly on ``baselines.game.payoff_matrix`` (:func:`baselines.game.exploitability`).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.logger import configure
from stable_baselines3.common.vec_env import DummyVecEnv

from agents.config import GameConfig, algo_kwargs, parse_env_kwargs, resolved_hyperparameters
from agents.evaluate import Evaluation, evaluate
from agents.plots import exploitability_curve
from agents.registry import Reference, Trainable, game_names, get
from agents.runs import (
    atomic_write,
    check_resumable,
    config_dict,
    prepare_run_dir,
    run_prefix,
    write_json,
)
from agents.seeding import seed_everything
from agents.training import ALGO_CLASSES, build_model, env_thunk
from baselines.game import MixedStrategyPolicy, exploitability, solve_zero_sum
from fdia_env.envs.opponents import FixedMix

METHODS = ("psro", "fsp", "ibr")
SIDES = ("attacker", "defender")


@dataclass
class SelfPlayResult:
    """What :func:`run_selfplay` returns.

    Attributes:
        run_dir: The run folder.
        method: ``"psro"``, ``"fsp"`` or ``"ibr"``.
        x: (m,) the defender's final mixed strategy over its actions.
        y: (n,) the attacker's final mixed strategy.
        value: The game value (LP).
        history: One record per iteration (exploitabilities, NashConv, best responses).
        evaluations: Final evaluations (learned mixes and the LP equilibrium) by row name.
        populations: The learned pure strategies (actions) of each side, in order.
        train_seconds: Wall time of the iterations.
    """

    run_dir: Path
    method: str
    x: np.ndarray
    y: np.ndarray
    value: float
    history: list[dict[str, Any]]
    evaluations: dict[str, Evaluation] = field(default_factory=dict)
    populations: dict[str, list[int]] = field(default_factory=dict)
    train_seconds: float = 0.0


def one_hot(action: int, n: int) -> np.ndarray:
    """The pure strategy ``action`` as an (n,) probability vector."""
    out = np.zeros(n)
    out[action] = 1.0
    return out


def mix_of(population: list[int], weights: np.ndarray, n: int) -> np.ndarray:
    """The mixed strategy over actions of a weighted population of pure strategies."""
    out = np.zeros(n)
    np.add.at(out, population, weights)
    return out / out.sum()


def initial_action(model: BaseAlgorithm, entry: Trainable, env_kwargs: dict[str, Any]) -> int:
    """The pure strategy of a learned policy: its deterministic action at the initial state."""
    with entry.make(**env_kwargs) as env:
        obs, _ = env.reset(seed=0)
    return int(model.predict(obs, deterministic=True)[0])


def learn_best_response(
    entry: Trainable,
    env_kwargs: dict[str, Any],
    opponent: np.ndarray,
    algo: str,
    kwargs: dict[str, Any],
    steps: int,
    seed: int,
    device: str = "cpu",
    tb_dir: Path | None = None,
) -> tuple[BaseAlgorithm, int]:
    """A fresh ``algo`` learner trained against the fixed mix ``opponent``, and its action.

    The learner plays ``entry``'s side; the action is its pure strategy (:func:`initial_action`).
    """
    seed_everything(seed)
    make = env_thunk(
        entry.gym_id, env_kwargs, lambda: FixedMix(opponent, seed=seed + 1), monitor=True
    )
    vec_env = DummyVecEnv([make])
    model = build_model(algo, vec_env, kwargs, seed, device)
    if tb_dir is not None:
        model.set_logger(configure(str(tb_dir), ["tensorboard"]))
    model.learn(steps)
    vec_env.close()
    return model, initial_action(model, entry, env_kwargs)


def empirical_payoff(
    attacker: BaseAlgorithm,
    defender: BaseAlgorithm,
    entry: Trainable,
    env_kwargs: dict[str, Any],
    n_episodes: int,
    seed: int,
) -> float:
    """The attacker's mean return when the two learned policies play each other in the env."""
    with entry.view(opponent=defender, **env_kwargs) as env:
        return evaluate(attacker, env, n_episodes, seed, reference=None).mean


def _report_line(rec: dict[str, Any]) -> str:
    return (
        f"iter {rec['iteration']:3d}  steps {rec['timesteps']:8d}  "
        f"BR attacker {rec['br_attacker']} (gap {rec['br_gap_attacker']:.3g})  "
        f"BR defender {rec['br_defender']} (gap {rec['br_gap_defender']:.3g})  "
        f"expl def {rec['defender']:.4f} att {rec['attacker']:.4f}  "
        f"NashConv {rec['nash_conv']:.4f} ({rec['relative_nash_conv']:.2%} of value)"
    )


def game_prefix(cfg: GameConfig) -> str:
    """Run folder name without its time: ``<env>-<method>-<algo>-s<seed>``."""
    algo = get(cfg.env, "attacker").algorithm(cfg.algo)
    return run_prefix(f"{cfg.env}-{cfg.method}", algo, cfg.run.seed)


def run_selfplay(cfg: GameConfig, report: Callable[[str], None] | None = print) -> SelfPlayResult:
    """Run ``cfg.method`` for ``cfg.iterations`` iterations and write the run folder.

    Args:
        cfg: The game command's settings.
        report: Called with one line per iteration (None: silent).

    Raises:
        ValueError: For an env that is not a registered two-player game, an unknown method,
            scenario or algorithm (listing the valid names), a repeated game (``rounds > 1``),
            or a resume whose options differ.
        FileExistsError: When a new run's folder exists.
    """
    if cfg.method not in METHODS:
        raise ValueError(f"unknown method {cfg.method!r}; valid methods: {', '.join(METHODS)}")
    if cfg.env not in game_names():
        raise ValueError(f"unknown game {cfg.env!r}; valid games: {', '.join(game_names())}")
    if cfg.iterations < 1 or cfg.steps_per_iteration < 1 or cfg.final_eval_episodes < 1:
        raise ValueError("iterations, steps-per-iteration and final-eval-episodes must be >= 1")
    entries = {side: get(cfg.env, side) for side in SIDES}
    algo = entries["attacker"].algorithm(cfg.algo)
    kwargs = algo_kwargs(algo, cfg.hp)
    env_kwargs = entries["attacker"].env_kwargs(cfg.scenario, **parse_env_kwargs(cfg.env_kwargs))
    with entries["attacker"].make(**env_kwargs) as env:
        reference = entries["attacker"].reference_of(env)
        n = {side: int(env.unwrapped.parallel.action_space(side).n) for side in SIDES}
    if reference is None or not reference.is_game:
        raise ValueError(f"{cfg.env} with {env_kwargs} is not a one-shot matrix game")
    L, value = reference.payoff, reference.value

    run_dir, resumed = prepare_run_dir(
        cfg.run.runs_root, cfg.run.run_dir, game_prefix(cfg), cfg.run.resume
    )
    given = config_dict(cfg)
    state_path = run_dir / "state.json"
    state: dict[str, Any] = {"populations": {"attacker": [], "defender": []}, "history": []}
    if resumed:
        saved = json.loads((run_dir / "config.json").read_text())
        check_resumable(saved["config"], given, run_dir)
        if state_path.is_file():
            state = json.loads(state_path.read_text())
    write_json(
        run_dir / "config.json",
        {
            "command": "game",
            "config": given,
            "resolved": {
                "algo": algo,
                "env_kwargs": env_kwargs,
                "hyperparameters": resolved_hyperparameters(algo, cfg.hp),
                "reference": {"name": reference.name, "value": value},
            },
        },
    )
    seed_everything(cfg.run.seed, cfg.run.torch_threads)

    policies_dir = run_dir / "policies"
    pops: dict[str, list[int]] = state["populations"]
    models: dict[str, list[BaseAlgorithm]] = {
        side: [
            ALGO_CLASSES[algo].load(policies_dir / f"{side}_{k}.zip", device=cfg.run.device)
            for k in range(len(pops[side]))
        ]
        for side in SIDES
    }
    meta = np.array(state.get("meta_payoff", np.zeros((0, 0))), dtype=np.float64)
    meta = meta.reshape(len(pops["defender"]), len(pops["attacker"]))
    history: list[dict[str, Any]] = state["history"]
    x = np.array(state.get("x", np.full(n["defender"], 1.0 / n["defender"])))
    y = np.array(state.get("y", np.full(n["attacker"], 1.0 / n["attacker"])))
    seconds0 = float(state.get("train_seconds", 0.0))
    start = time.perf_counter()
    tb = configure(str(run_dir / "tb"), ["tensorboard"])

    iterations = range(len(history) + 1, cfg.iterations + 1)
    if cfg.run.progress_bar:
        from tqdm.auto import tqdm

        iterations = tqdm(iterations, desc=f"{cfg.method} on {cfg.env}", unit="iter")
    for it in iterations:
        opponents = {"attacker": x, "defender": y}  # each side answers the other's mix
        new: dict[str, tuple[BaseAlgorithm, int]] = {}
        for s, side in enumerate(SIDES):
            new[side] = learn_best_response(
                entries[side],
                env_kwargs,
                opponents[side],
                algo,
                kwargs,
                cfg.steps_per_iteration,
                cfg.run.seed + 1000 * it + s,
                cfg.run.device,
                run_dir / "tb" / f"{side}_br_{it:03d}",
            )
        for side in SIDES:
            model, action = new[side]
            atomic_write(policies_dir / f"{side}_{len(pops[side])}.zip", model.save)
            models[side].append(model)
            pops[side].append(action)
        # how far each learned response is from an exact best response to the mix it answered
        gap_att = float((x @ L).max() - (x @ L)[pops["attacker"][-1]])
        gap_def = float((L @ y)[pops["defender"][-1]] - (L @ y).min())

        if cfg.method == "ibr":
            x, y = (
                one_hot(pops["defender"][-1], n["defender"]),
                one_hot(pops["attacker"][-1], n["attacker"]),
            )
        elif cfg.method == "fsp":
            x = mix_of(pops["defender"], np.ones(len(pops["defender"])), n["defender"])
            y = mix_of(pops["attacker"], np.ones(len(pops["attacker"])), n["attacker"])
        else:
            meta = _grow_meta(meta, models, entries["attacker"], env_kwargs, cfg.run.seed)
            sx, sy, _ = solve_zero_sum(meta)
            x = mix_of(pops["defender"], sx, n["defender"])
            y = mix_of(pops["attacker"], sy, n["attacker"])

        e = exploitability(L, x, y, value)
        rec = {
            "iteration": it,
            "timesteps": 2 * it * cfg.steps_per_iteration,
            "train_seconds": round(seconds0 + time.perf_counter() - start, 3),
            "defender": e.defender,
            "attacker": e.attacker,
            "nash_conv": e.nash_conv,
            "relative_nash_conv": e.nash_conv / abs(value),
            "br_attacker": pops["attacker"][-1],
            "br_defender": pops["defender"][-1],
            "br_gap_attacker": gap_att,
            "br_gap_defender": gap_def,
            "x": x.tolist(),
            "y": y.tolist(),
        }
        history.append(rec)
        for key in ("defender", "attacker", "nash_conv", "relative_nash_conv"):
            tb.record(f"selfplay/{key}", rec[key])
        tb.dump(it)
        write_json(
            state_path,
            {
                "populations": pops,
                "meta_payoff": meta.tolist(),
                "history": history,
                "x": x.tolist(),
                "y": y.tolist(),
                "train_seconds": rec["train_seconds"],
            },
        )
        if report is not None:
            report(_report_line(rec))

    train_seconds = history[-1]["train_seconds"] if history else 0.0
    evaluations = _final_evaluations(entries, env_kwargs, reference, x, y, cfg)
    write_json(
        run_dir / "scores.json",
        {
            "method": cfg.method,
            "value": value,
            "x": x.tolist(),
            "y": y.tolist(),
            "final": {k: history[-1][k] for k in ("defender", "attacker", "nash_conv")},
            "relative_nash_conv": history[-1]["relative_nash_conv"],
            "iterations": len(history),
            "timesteps": history[-1]["timesteps"],
            "train_seconds": train_seconds,
            "evaluations": {k: v.to_dict() for k, v in evaluations.items()},
        },
    )
    exploitability_curve(
        run_dir / "learning_curve.png",
        history,
        value,
        f"{cfg.method.upper()} ({algo} best responses) on {cfg.env} ({env_kwargs['scenario']})",
    )
    return SelfPlayResult(
        run_dir, cfg.method, x, y, value, history, evaluations, pops, train_seconds
    )


def _grow_meta(
    meta: np.ndarray,
    models: dict[str, list[BaseAlgorithm]],
    attacker_entry: Trainable,
    env_kwargs: dict[str, Any],
    seed: int,
) -> np.ndarray:
    """Extend the empirical meta-payoff (defender rows, attacker columns) to the new policies.

    Only the new row and column are played (one episode per pair: the payoff of two
    deterministic policies in the expected-dynamics game is exact; sampled dynamics would
    need more).
    """
    m, k = len(models["defender"]), len(models["attacker"])
    out = np.zeros((m, k))
    out[: meta.shape[0], : meta.shape[1]] = meta
    for i in range(m):
        for j in range(k):
            if i < meta.shape[0] and j < meta.shape[1]:
                continue
            out[i, j] = empirical_payoff(
                models["attacker"][j], models["defender"][i], attacker_entry, env_kwargs, 1, seed
            )
    return out


def _final_evaluations(
    entries: dict[str, Trainable],
    env_kwargs: dict[str, Any],
    reference: Reference,
    x: np.ndarray,
    y: np.ndarray,
    cfg: GameConfig,
) -> dict[str, Evaluation]:
    """Each side's learned mix and LP equilibrium mix, played against the other learned mix."""
    seed = cfg.run.seed + 20_000
    x_eq, y_eq, _ = solve_zero_sum(reference.payoff)
    rows = {}
    for label, side, probs, other in (
        ("attacker mix (learned)", "attacker", y, x),
        ("attacker LP equilibrium", "attacker", y_eq, x),
        ("defender mix (learned)", "defender", x, y),
        ("defender LP equilibrium", "defender", x_eq, y),
    ):
        entry = entries[side]
        with entry.make(opponent=MixedStrategyPolicy(other, seed=seed + 1), **env_kwargs) as env:
            rows[label] = evaluate(
                MixedStrategyPolicy(probs, seed=seed),
                env,
                cfg.final_eval_episodes,
                seed,
                entry.reference_of(env),
            )
    return rows
