"""``stealth``: a learned stealthy attacker on IEEE 14 against the exact optimum, and protection.

Attacker rows: stable-baselines3 PPO trained on ``"fdia_env/StealthAttack-v0"`` (IEEE 14,
``action="shift"``: ``MultiBinary(13)``, bit j shifts state j's estimate by ``magnitude``;
``dynamics="expected"``, one snapshot per episode, so the reward is the exact expected damage
``(1 − p) · |K a|_∞``). Its deterministic action's payoff is set against random play and the
optimum of the same action space, found by enumerating all 8,191 non-zero shift vectors (exact).
Every seed's figure is reported, with the mean and its 95 % CI.

Protection rows: the protection game's value (double oracle, certified by its gap) against what
simple protections concede to a best-responding attacker (:func:`baselines.stealth.
protection_exploitability`): protecting the meters of the unprotected optimal attack, and the
first meters of a basic measurement set. No learned defender is trained here.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from experiments.results.common import mean_ci95, write_rows

SCENARIO = "grid-ieee14"
MAGNITUDE = 0.05


def _env_kwargs(budget: int) -> dict[str, Any]:
    return {
        "scenario": SCENARIO,
        "budget": budget,
        "magnitude": MAGNITUDE,
        "dynamics": "expected",
        "horizon": 1,
    }


def shift_payoffs(budget: int) -> np.ndarray:
    """(2^n − 1,) exact expected payoff of every non-zero shift action (bits in binary order)."""
    from fdia_env.stealth.vector import StealthVectorEnv

    venv = StealthVectorEnv(1, **_env_kwargs(budget))
    n = venv.env.estimation.n
    bits = ((np.arange(1, 2**n)[:, None] >> np.arange(n)) & 1).astype(np.int8)
    a = venv.injections(bits)
    damage = np.max(np.abs(a @ venv.env.estimation.K.T), axis=1)
    p = np.asarray(venv.env.estimation.detection_probability(a))
    return (1.0 - p) * damage


def _payoff(budget: int, action: np.ndarray) -> float:
    from fdia_env.stealth import stealth_attack_v0

    env = stealth_attack_v0.parallel_env(**_env_kwargs(budget))
    env.reset(seed=0)
    _, rewards, *_ = env.step({"attacker": np.asarray(action, dtype=np.int8)})
    return float(rewards["attacker"])


def learned_attacker(budget: int, steps: int, seeds: list[int]) -> dict[str, Any]:
    """PPO's payoff per seed against random play and the enumerated optimum."""
    import gymnasium as gym
    from stable_baselines3 import PPO

    import fdia_env  # noqa: F401 - registers the ids

    payoffs = shift_payoffs(budget)
    learned, seconds = [], []
    for seed in seeds:
        env = gym.make("fdia_env/StealthAttack-v0", **_env_kwargs(budget))
        start = time.perf_counter()
        model = PPO("MlpPolicy", env, n_steps=256, batch_size=64, seed=seed, verbose=0)
        model.learn(total_timesteps=steps)
        seconds.append(time.perf_counter() - start)
        obs, _ = env.reset(seed=seed)
        action, _ = model.predict(obs, deterministic=True)
        learned.append(_payoff(budget, action))
        env.close()
    mean, ci = mean_ci95(learned)
    best = float(np.max(payoffs))
    return {
        "budget": budget,
        "steps": steps,
        "seeds": seeds,
        "learned": learned,
        "learned_mean": mean,
        "learned_ci95": ci,
        "random": float(np.mean(payoffs)),  # uniform over the non-zero actions
        "optimum": best,
        "score": [v / best for v in learned],
        "train_seconds": seconds,
    }


def protection_rows(budget: int, protection: int) -> dict[str, Any]:
    """The game's value against two simple protections, on IEEE 14 with ``a_max = 0.5``."""
    from baselines.stealth import (
        basic_measurement_set,
        budgeted_attack,
        protection_exploitability,
        protection_game,
    )
    from fdia_env.stealth import static_estimation

    est = static_estimation("ieee14")
    start = time.perf_counter()
    game = protection_game(est, budget, protection, a_max=0.5)
    seconds = time.perf_counter() - start
    attack = budgeted_attack(est, budget, a_max=0.5)
    on_attack = attack.meters[:protection]
    basic = basic_measurement_set(est)[:protection]
    return {
        "budget": budget,
        "protection": protection,
        "value": game.value,
        "gap": game.gap,
        "iterations": game.iterations,
        "seconds": seconds,
        "defender": {str(k): v for k, v in game.defender.items()},
        "protect_optimal_attack": list(on_attack),
        "protect_optimal_attack_concedes": protection_exploitability(
            est, on_attack, budget, a_max=0.5
        )[0],
        "protect_basic": list(basic),
        "protect_basic_concedes": protection_exploitability(est, basic, budget, a_max=0.5)[0],
        "unprotected": attack.value,
    }


def format_rows(attackers: list[dict], protections: list[dict]) -> str:
    """The rows as Markdown tables."""
    lines = [
        f"Attacker (PPO, {SCENARIO}, shift actions of {MAGNITUDE} rad, expected dynamics):",
        "",
        "| budget | steps | PPO per seed (rad) | PPO mean ± 95 % CI | random | optimum "
        "(enumerated) | PPO / optimum per seed |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in attackers:
        per = ", ".join(f"{v:.4f}" for v in r["learned"])
        ratio = ", ".join(f"{s:.1%}" for s in r["score"])
        lines.append(
            f"| {r['budget']} | {r['steps']:,} | {per} | {r['learned_mean']:.4f} ± "
            f"{r['learned_ci95']:.2g} | {r['random']:.4f} | {r['optimum']:.4f} | {ratio} |"
        )
    lines += [
        "",
        "Protection game (IEEE 14, a_max = 0.5 pu; damage in rad a best-responding attacker gets):",
        "",
        "| attacker meters | protected | game value (gap) | protect the optimal attack's meters "
        "| protect basic-set meters | nothing protected |",
        "|---|---|---|---|---|---|",
    ]
    for r in protections:
        lines.append(
            f"| {r['budget']} | {r['protection']} | {r['value']:.4f} ({r['gap']:.1e}) | "
            f"{r['protect_optimal_attack_concedes']:.4f} | {r['protect_basic_concedes']:.4f} | "
            f"{r['unprotected']:.4f} |"
        )
    return "\n".join(lines)


def run(quick: bool = False, seed: int = 0, out: Path | None = None) -> str:
    """The ``stealth`` tables; ``quick``: budget 3 only, 2 seeds, 2,048 steps, no game."""
    if quick:
        attackers = [learned_attacker(3, 2048, [seed, seed + 1])]
        protections: list[dict] = []
    else:
        seeds = [seed, seed + 1, seed + 2]
        attackers = [learned_attacker(b, 20_000, seeds) for b in (3, 5)]
        protections = [protection_rows(3, 1), protection_rows(5, 2)]
    if out is not None:
        write_rows(out / "stealth.json", [*attackers, *protections])
    return format_rows(attackers, protections)
