"""``general``: one sparse attacker for many systems, scored on held-out systems.

MaskablePPO is trained on :class:`fdia_env.envs.system_family.SystemFamilyEnv` (a new random
tracking system at every reset, as in ``ch4-random``, with a fixed-size description of the
system in the observation; sequential picks with slots sorted by attack effect, the last
step's budget always spent), then played once on each of ``n_heldout`` held-out systems (system
seeds disjoint from the training seeds). Each system's value is scored against its own optimum
(branch and bound, proved) and against SFS run on that system. Compared: the same training
without the description, a policy trained on one system of the family, and random play.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from sb3_contrib import MaskablePPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import DummyVecEnv

from agents.evaluate import RandomPolicy
from baselines.sparse import branch_and_bound, sfs
from experiments.markdown import table
from experiments.results.common import mean_ci95, write_rows
from fdia_env._validation import check_int
from fdia_env.envs.grid_family import GridFamily
from fdia_env.envs.system_family import SystemFamilyEnv, TrackingFamily

TRAIN_SEEDS = range(0, 1_000_000)
"""System seeds of training (the family and the no-description runs)."""
VALIDATION_SEEDS = range(2_000_000, 2_000_050)
"""Systems of the learning curve (disjoint from training and held-out seeds)."""
HELDOUT_START = 1_000_000
"""Held-out systems are ``range(HELDOUT_START, HELDOUT_START + n_heldout)``."""
SINGLE_SYSTEM_SEED = 0
"""The one system (a training seed) of the single-system policy."""
OPTIMAL = 0.99  # a score at or above this counts as optimal
RANDOM_EPISODES = 10  # random-play episodes per held-out system (its value: their mean)

POLICY_NAMES = (
    "MaskablePPO, family + description",
    "MaskablePPO, family, no description",
    f"MaskablePPO, one system (seed {SINGLE_SYSTEM_SEED})",
    "SFS (per system)",
    "random play",
)
"""The rows of the table, in order."""

FULL_FAMILY = TrackingFamily()  # ch4-random-like: M = 10, c = 10, N = 6, σ_v ∈ [0.1, 1]
QUICK_FAMILY = TrackingFamily(num_sensors=6, budget=6, horizon=4)

LEARNING_RATE = 1e-3


def _decayed(progress_remaining: float) -> float:
    """Learning rate decayed linearly from :data:`LEARNING_RATE` to 0 over training."""
    return LEARNING_RATE * progress_remaining


PPO_KWARGS: dict[str, Any] = {
    "n_steps": 512,
    "batch_size": 512,
    "n_epochs": 10,
    "learning_rate": _decayed,
    "gamma": 1.0,
    "gae_lambda": 0.95,
    "ent_coef": 0.0,
    "policy_kwargs": {"net_arch": [128, 128]},
}
N_ENVS = 8
ACTION = "sequential"  # SystemFamilyEnv action format of every learned policy
REWARD_REFERENCE: Any = None  # per-system reward scale in training (None: tr P̄)
SORT_SENSORS = True  # slots ordered by attack effect (SystemFamilyEnv sort_sensors)


@dataclass(frozen=True)
class Settings:
    """One run of the table: the family, training steps and held-out count.

    ``ppo`` overrides entries of :data:`PPO_KWARGS` for this run (``None``: none).
    """

    family: TrackingFamily | GridFamily
    timesteps: int
    single_timesteps: int
    n_heldout: int
    curve_every: int
    ppo: dict[str, Any] | None = None


FULL = Settings(FULL_FAMILY, 250_000, 30_000, 200, 25_000)
QUICK = Settings(QUICK_FAMILY, 12_288, 4_096, 100, 4_096)


def heldout_seeds(n_heldout: int) -> range:
    """The held-out system seeds (disjoint from :data:`TRAIN_SEEDS` and the validation seeds)."""
    check_int("n_heldout", n_heldout, minimum=1, maximum=VALIDATION_SEEDS.start - HELDOUT_START)
    return range(HELDOUT_START, HELDOUT_START + n_heldout)


def references(family: TrackingFamily, seeds: Sequence[int]) -> list[dict[str, Any]]:
    """Per system: its optimum (branch and bound), whether it is proved, and SFS's value."""
    rows = []
    for k in seeds:
        sc = family.scenario(int(k))
        best = branch_and_bound(sc, family.budget, family.horizon)
        greedy = sfs(sc, family.budget, family.horizon)
        rows.append(
            {
                "system_seed": int(k),
                "optimum": best.value,
                "proved": bool(best.proved_optimal),
                "optimal_actions": best.actions().tolist(),
                "sfs": greedy.value,
            }
        )
    return rows


def play_values(
    policy: Any,
    family: TrackingFamily,
    seeds: Sequence[int],
    describe: bool = True,
    episodes: int = 1,
    deterministic: bool = True,
) -> np.ndarray:
    """Φ at the end of the window (``info["phi"]``) of ``policy`` on each system, (len(seeds),).

    With ``episodes > 1`` the value is the mean over that many episodes (random play).
    """
    env = SystemFamilyEnv(
        family,
        system_seeds=TRAIN_SEEDS,
        describe=describe,
        action=ACTION,
        sort_sensors=SORT_SENSORS,
    )
    values = np.zeros(len(seeds))
    for j, k in enumerate(seeds):
        total = 0.0
        for e in range(episodes):
            obs, _ = env.reset(seed=e, options={"system_seed": int(k)})
            if hasattr(policy, "seed_episodes"):
                policy.seed_episodes([int(k) * 1000 + e])
            done = False
            while not done:
                action, _ = policy.predict(
                    obs, deterministic=deterministic, action_masks=env.action_masks()
                )
                obs, _, term, trunc, info = env.step(int(action))
                done = term or trunc
            total += info["phi"]
        values[j] = total / episodes
    return values


class _Curve(BaseCallback):
    """Mean score on the validation systems every ``every`` steps."""

    def __init__(self, family: TrackingFamily, optima: np.ndarray, describe: bool, every: int):
        super().__init__()
        self.family, self.optima, self.describe, self.every = family, optima, describe, every
        self.history: list[dict[str, Any]] = []
        self._next = 0

    def _on_step(self) -> bool:
        if self.num_timesteps >= self._next:
            self._record()
            self._next += self.every
        return True

    def _record(self) -> None:
        values = play_values(self.model, self.family, VALIDATION_SEEDS, self.describe)
        mean, half = mean_ci95(values / self.optima)
        self.history.append({"timesteps": int(self.num_timesteps), "mean": mean, "ci95": half})

    def _on_training_end(self) -> None:
        self._record()


def sfs_value(system: Any, budget: int, horizon: int) -> float:
    """SFS's value of the system's sparse problem (the training reward's per-system scale)."""
    return sfs(system, budget, horizon).value


def train_policy(
    family: TrackingFamily,
    timesteps: int,
    seed: int,
    system_seeds: range = TRAIN_SEEDS,
    describe: bool = True,
    curve: tuple[np.ndarray, int] | None = None,
    ppo: dict[str, Any] | None = None,
) -> tuple[MaskablePPO, list[dict[str, Any]]]:
    """MaskablePPO on the family env; returns the model and its learning curve (if asked).

    Args:
        family: The system distribution.
        timesteps: Training steps.
        seed: Seed of the model and the envs.
        system_seeds: Systems trained on (one seed: the single-system policy).
        describe: Observe the system description.
        curve: ``(optima of VALIDATION_SEEDS, every)`` to record a learning curve.
        ppo: Entries replacing those of :data:`PPO_KWARGS` (``None``: none).
    """
    check_int("timesteps", timesteps, minimum=1)
    vec = DummyVecEnv(
        [
            lambda: SystemFamilyEnv(
                family,
                system_seeds=system_seeds,
                describe=describe,
                action=ACTION,
                reward_reference=REWARD_REFERENCE,
                sort_sensors=SORT_SENSORS,
            )
            for _ in range(N_ENVS)
        ]
    )
    kwargs = {**PPO_KWARGS, **(ppo or {})}
    model = MaskablePPO("MlpPolicy", vec, seed=seed, device="cpu", verbose=0, **kwargs)
    callback = None if curve is None else _Curve(family, curve[0], describe, curve[1])
    model.learn(total_timesteps=timesteps, callback=callback)
    return model, ([] if callback is None else callback.history)


def summarize(name: str, scores: np.ndarray, sfs_suboptimal: np.ndarray) -> dict[str, Any]:
    """One table row: mean score ± 95 % CI, fraction >= 99 %, mean where SFS is suboptimal."""
    mean, half = mean_ci95(scores)
    sub = scores[sfs_suboptimal]
    sub_mean, sub_half = mean_ci95(sub) if sub.size else (float("nan"), float("nan"))
    return {
        "policy": name,
        "mean": mean,
        "ci95": half,
        "at_least_99": float(np.mean(scores >= OPTIMAL)),
        "min": float(scores.min()),
        "sfs_suboptimal_mean": sub_mean,
        "sfs_suboptimal_ci95": sub_half,
    }


def format_general(rows: list[dict[str, Any]], n: int, n_sub: int) -> str:
    """The summary rows as a Markdown table."""
    header = [
        "policy",
        f"score on {n} held-out systems (mean ± 95 % CI)",
        "systems ≥ 99 %",
        "worst",
        f"on the {n_sub} where SFS < 99 %",
    ]
    lines = []
    for r in rows:
        sub = r["sfs_suboptimal_mean"]
        on_sub = "none" if sub != sub else f"{sub:.1%} ± {r['sfs_suboptimal_ci95']:.1%}"
        lines.append(
            [
                r["policy"],
                f"{r['mean']:.1%} ± {r['ci95']:.1%}",
                f"{r['at_least_99']:.0%}",
                f"{r['min']:.1%}",
                on_sub,
            ]
        )
    return table(header, lines)


def plot(
    out: Path,
    curves: dict[str, list[dict]],
    scores: dict[str, np.ndarray],
    prefix: str = "results_general",
) -> None:
    """Learning curves (validation score) and sorted held-out scores, optimum as a line.

    The files are ``<prefix>_curve.png`` and ``<prefix>_scores.png`` in ``out``.
    """
    from agents.plots import plt, save_figure

    fig, ax = plt.subplots(figsize=(7, 4))
    for name, hist in curves.items():
        steps = [h["timesteps"] for h in hist]
        mean = np.array([h["mean"] for h in hist])
        half = np.array([h["ci95"] for h in hist])
        ax.plot(steps, mean, marker="o", ms=3, label=name)
        ax.fill_between(steps, mean - half, mean + half, alpha=0.2)
    ax.axhline(1.0, color="k", ls="--", label="per-system optimum (B&B)")
    ax.set_xlabel("environment steps")
    ax.set_ylabel(f"mean score on {len(VALIDATION_SEEDS)} validation systems")
    ax.set_title("One attacker for many systems: learning curve")
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right")
    fig.tight_layout()
    save_figure(fig, out / f"{prefix}_curve.png")

    fig, ax = plt.subplots(figsize=(7, 4))
    for name, s in scores.items():
        ax.plot(np.arange(1, s.size + 1), np.sort(s)[::-1], label=name)
    ax.axhline(1.0, color="k", ls="--", label="per-system optimum (B&B)")
    ax.set_xlabel("held-out systems, sorted by score")
    ax.set_ylabel("score (value / per-system optimum)")
    ax.set_title("Score per held-out system")
    ax.grid(alpha=0.3)
    ax.legend(loc="lower left")
    fig.tight_layout()
    save_figure(fig, out / f"{prefix}_scores.png")


def general_table(
    settings: Settings, seed: int = 0
) -> tuple[list[dict], list[dict], dict[str, Any]]:
    """Train, score on held-out systems; returns (summary rows, per-system rows, extras)."""
    family = settings.family
    held = heldout_seeds(settings.n_heldout)
    refs = references(family, held)
    optima = np.array([r["optimum"] for r in refs])
    sfs_scores = np.array([r["sfs"] for r in refs]) / optima
    sfs_sub = sfs_scores < OPTIMAL
    val_optima = np.array([r["optimum"] for r in references(family, VALIDATION_SEEDS)])
    curve = (val_optima, settings.curve_every)
    timings = {}
    t0 = time.perf_counter()
    ppo = settings.ppo
    model, hist = train_policy(family, settings.timesteps, seed, curve=curve, ppo=ppo)
    timings["family"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    blind, hist_blind = train_policy(
        family, settings.timesteps, seed, describe=False, curve=curve, ppo=ppo
    )
    timings["no description"] = time.perf_counter() - t0
    one = range(SINGLE_SYSTEM_SEED, SINGLE_SYSTEM_SEED + 1)
    t0 = time.perf_counter()
    single, _ = train_policy(family, settings.single_timesteps, seed, one, describe=False, ppo=ppo)
    timings["single system"] = time.perf_counter() - t0
    random_policy = RandomPolicy(SystemFamilyEnv(family, action=ACTION).action_space, seed=seed)
    values = [
        play_values(model, family, held),
        play_values(blind, family, held, describe=False),
        play_values(single, family, held, describe=False),
        sfs_scores * optima,
        play_values(random_policy, family, held, episodes=RANDOM_EPISODES, deterministic=False),
    ]
    scores = {name: v / optima for name, v in zip(POLICY_NAMES, values, strict=True)}
    summary = [summarize(name, s, sfs_sub) for name, s in scores.items()]
    per_system = [
        {**r, **{name: float(s[j]) for name, s in scores.items()}} for j, r in enumerate(refs)
    ]
    extras = {
        "curves": {"family + description": hist, "family, no description": hist_blind},
        "scores": scores,
        "timings": timings,
        "n_sub": int(sfs_sub.sum()),
        "all_proved": all(r["proved"] for r in refs),
        "model": model,
    }
    return summary, per_system, extras


def report(settings: Settings, seed: int, out: Path | None, name: str, family: str) -> str:
    """Run :func:`general_table` and return it as Markdown (rows and plots to ``out``).

    Args:
        settings: The family and the training budgets.
        seed: Base seed.
        out: Folder for ``<name>.json`` and the ``results_<name>_*.png`` plots (None: none).
        name: The table's name.
        family: One line describing the family, printed under the table.
    """
    torch.set_num_threads(1)
    start = time.perf_counter()
    summary, per_system, extras = general_table(settings, seed)
    if out is not None:
        write_rows(out / f"{name}.json", summary + per_system)
        plot(out, extras["curves"], extras["scores"], prefix=f"results_{name}")
    timings = ", ".join(f"{k} {v:.0f} s" for k, v in extras["timings"].items())
    return (
        format_general(summary, settings.n_heldout, extras["n_sub"])
        + f"\n\nFamily: {family}; training "
        f"{settings.timesteps:,} steps (single system {settings.single_timesteps:,}), seed "
        f"{seed}; every optimum proved: {extras['all_proved']}. Training time: {timings}; "
        f"total {time.perf_counter() - start:.0f} s."
    )


def run(quick: bool = False, seed: int = 0, out: Path | None = None) -> str:
    """The ``general`` table (Markdown); ``quick``: M = 6, c = 6, N = 4, short training."""
    settings = QUICK if quick else FULL
    fam = settings.family
    family = (
        f"M = {fam.num_sensors} position sensors, σ_w ~ U{fam.sigma_w}, σ_v log-uniform on "
        f"{fam.sigma_v}, c = {fam.budget}, N = {fam.horizon}"
    )
    return report(settings, seed, out, "general", family)
