"""``make demo``: a learned sparse attack that beats the greedy heuristic and reaches the optimum.

The instance: ``fdia_env/SparseAttack-v0`` on the ``ch4-random`` preset drawn with seed 5 (10
position sensors, σ_w ~ U(0, 1), σ_v = 0.1), budget c = 6 sensor-time pairs, window N = 2, the
trace objective ``tr P[K+N|K+N]`` in expected dynamics (docs/math.md §4). On it the greedy
heuristic SFS reaches 82.9 % of the optimum, while exhaustive search (EXS, all C(20, 6) = 38,760
attack sets) certifies the optimum.

sb3-contrib's ``MaskablePPO`` learns the attack in the env's sequential, masked format
(``action="sequential"``: each window step's set is built one sensor per decision, then a stop).
Rewards are divided by Φ of the unattacked filter (a scale the learner may know; it does not
depend on the answer). The learned plan is the deterministic policy's episode, scored against
uniform random play in the same format (mean over episodes), SFS and the EXS optimum.

Run ``python -m agents.demo --help`` for the options; ``--seeds 0 1 2 3 4`` trains one learner
per seed and adds the worst seed's score.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence
from dataclasses import dataclass

import gymnasium as gym
import numpy as np
import torch
from sb3_contrib import MaskablePPO

import fdia_env  # noqa: F401 - registers the Gymnasium ids
from baselines.sparse import exhaustive, make_problem, sfs
from fdia_env import scenarios
from fdia_env.scenarios import Scenario
from fdia_env.tasks.task import make_pinned

ENV_ID = "fdia_env/SparseAttack-v0"
PRESET = "ch4-random"
DEFAULTS = {"instance_seed": 5, "budget": 6, "horizon": 2, "steps": 12_000}
PPO_SETTINGS = {
    "n_steps": 256,
    "batch_size": 128,
    "n_epochs": 4,
    "learning_rate": 1e-3,
    "gamma": 1.0,
    "ent_coef": 0.01,
}
"""MaskablePPO's settings (stable-baselines3's defaults for the rest)."""


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """Command-line options of the demo."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument(
        "--steps", type=int, default=DEFAULTS["steps"], help="PPO decisions per training run"
    )
    p.add_argument(
        "--seeds", type=int, nargs="+", default=[0], help="training seeds (one run each)"
    )
    p.add_argument(
        "--instance-seed",
        type=int,
        default=DEFAULTS["instance_seed"],
        help=f"seed of the {PRESET} preset's sensor noise draw",
    )
    p.add_argument("--budget", type=int, default=DEFAULTS["budget"], help="sparsity budget c")
    p.add_argument("--horizon", type=int, default=DEFAULTS["horizon"], help="attack window N")
    p.add_argument(
        "--random-episodes", type=int, default=500, help="episodes of random play to average"
    )
    args = p.parse_args(argv)
    for name in ("steps", "budget", "horizon", "random_episodes"):
        if getattr(args, name) < 1:
            p.error(f"--{name.replace('_', '-')} must be at least 1")
    return args


class _ScaledReward(gym.RewardWrapper):
    """Rewards divided by ``scale``; passes ``action_masks()`` through for MaskablePPO."""

    def __init__(self, env: gym.Env, scale: float) -> None:
        super().__init__(env)
        self.scale = scale

    def reward(self, reward: float) -> float:
        return float(reward) / self.scale

    def action_masks(self) -> np.ndarray:
        return self.env.unwrapped.action_masks()


@dataclass(frozen=True)
class Instance:
    """The demo's problem and its reference values (Φ = tr P[K+N|K+N]).

    Attributes:
        scenario: The preset drawn with the instance seed.
        budget: Sparsity budget c.
        horizon: Window N.
        optimum: EXS's optimal value (certified: every C(M·N, c) set is evaluated).
        optimum_sets: Number of sets EXS evaluated.
        optimum_attacks: EXS's set of (step, sensor) pairs, 0-based.
        sfs: SFS's value.
        sfs_attacks: SFS's set.
        unattacked: Φ with nothing attacked (the reward scale).
    """

    scenario: Scenario
    budget: int
    horizon: int
    optimum: float
    optimum_sets: int
    optimum_attacks: tuple[tuple[int, int], ...]
    sfs: float
    sfs_attacks: tuple[tuple[int, int], ...]
    unattacked: float

    def make_env(self) -> _ScaledReward:
        """The training env: sequential format, rewards in units of ``unattacked``."""
        # pinned to v0 (docs/results/training_runs.md's figures were made there; its sequential
        # format's order is the time-major one), built like a benchmark task's pinned env: no
        # out-of-date notice
        kwargs = {"budget": self.budget, "horizon": self.horizon, "action": "sequential"}
        env = make_pinned(ENV_ID, None, {"scenario": self.scenario, **kwargs})
        return _ScaledReward(env, self.unattacked)


def instance(
    instance_seed: int = DEFAULTS["instance_seed"],
    budget: int = DEFAULTS["budget"],
    horizon: int = DEFAULTS["horizon"],
) -> Instance:
    """Build the demo's instance and solve it with EXS and SFS."""
    scenario = scenarios.get(PRESET, seed=instance_seed)
    opt = exhaustive(scenario, budget=budget, horizon=horizon)
    greedy = sfs(scenario, budget=budget, horizon=horizon)
    unattacked = make_problem(scenario, budget, horizon).evaluate([])
    return Instance(
        scenario=scenario,
        budget=budget,
        horizon=horizon,
        optimum=opt.value,
        optimum_sets=opt.evaluations,
        optimum_attacks=tuple(opt.attacks),
        sfs=greedy.value,
        sfs_attacks=tuple(greedy.attacks),
        unattacked=unattacked,
    )


def random_play(inst: Instance, episodes: int, seed: int = 0) -> tuple[float, float]:
    """Mean and 95 % half-width of Φ under uniform random play over the legal actions."""
    env = inst.make_env()
    rng = np.random.default_rng(seed)
    values = np.empty(episodes)
    for ep in range(episodes):
        env.reset(seed=ep)
        total, done = 0.0, False
        while not done:
            action = int(rng.choice(np.flatnonzero(env.action_masks())))
            _, reward, terminated, truncated, _ = env.step(action)
            total += float(reward)
            done = terminated or truncated
        values[ep] = total * inst.unattacked
    half = 1.96 * values.std(ddof=1) / np.sqrt(episodes) if episodes > 1 else float("nan")
    return float(values.mean()), float(half)


def rollout(model: MaskablePPO, env: _ScaledReward) -> tuple[float, list[list[int]]]:
    """Deterministic episode: Φ reached (unscaled) and the 1-based sensors attacked per step."""
    obs, _ = env.reset(seed=0)
    horizon = env.unwrapped.parallel.spec.horizon
    plan: list[list[int]] = [[] for _ in range(horizon)]
    total, done = 0.0, False
    while not done:
        action, _ = model.predict(obs, action_masks=env.action_masks(), deterministic=True)
        action = int(action)
        if action:  # a pick in window step N − (steps left), read from feature 0 (steps left / N)
            plan[horizon - round(float(obs[0]) * horizon)].append(action)
        obs, reward, terminated, truncated, _ = env.step(action)
        total += float(reward)
        done = terminated or truncated
    return total * env.scale, [sorted(s) for s in plan]


def train(inst: Instance, steps: int, seed: int) -> tuple[float, list[list[int]], float]:
    """Train one MaskablePPO learner; returns its Φ, its plan and the training CPU seconds."""
    env = inst.make_env()
    model = MaskablePPO("MlpPolicy", env, seed=seed, verbose=0, **PPO_SETTINGS)
    start = time.process_time()
    model.learn(total_timesteps=steps)
    cpu = time.process_time() - start
    value, plan = rollout(model, env)
    return value, plan, cpu


def _plan_text(plan: list[list[int]]) -> str:
    return "; ".join(f"K+{k + 1}: {s or '-'}" for k, s in enumerate(plan))


def _pairs_plan(pairs: Sequence[tuple[int, int]], horizon: int) -> list[list[int]]:
    plan: list[list[int]] = [[] for _ in range(horizon)]
    for step, sensor in pairs:
        plan[step].append(sensor + 1)
    return [sorted(s) for s in plan]


def main(argv: Sequence[str] | None = None) -> dict[str, float]:
    """Train, evaluate and print the score table; returns the numbers.

    Returns:
        ``optimum``, ``sfs``, ``random`` (mean Φ), ``random_ci`` (95 % half-width), per seed
        ``learned_<seed>`` and ``cpu_seconds_<seed>``, and ``worst`` (lowest learned Φ).
    """
    args = parse_args(argv)
    torch.set_num_threads(1)
    inst = instance(args.instance_seed, args.budget, args.horizon)
    rand, rand_ci = random_play(inst, args.random_episodes)
    opt = inst.optimum
    M = inst.scenario.system.M
    print(
        f"\nAttacker on {ENV_ID}, {PRESET} drawn with seed {args.instance_seed} ({M} sensors), "
        f"c={args.budget}, N={args.horizon}, objective tr P[K+N|K+N], action='sequential'; "
        f"MaskablePPO, {args.steps:,} decisions per training run"
    )
    print(f"  sensors attacked at each window step (sensors numbered 1..{M}):")
    sets = [
        (f"optimum (EXS, all {inst.optimum_sets:,} sets)", inst.optimum_attacks),
        ("SFS (greedy)", inst.sfs_attacks),
    ]
    for name, pairs in sets:
        print(f"    {name:36s} {_plan_text(_pairs_plan(pairs, args.horizon))}")
    out: dict[str, float] = {"optimum": opt, "sfs": inst.sfs, "random": rand, "random_ci": rand_ci}
    learned: list[tuple[int, float, float]] = []
    for seed in args.seeds:
        value, plan, cpu = train(inst, args.steps, seed)
        learned.append((seed, value, cpu))
        out[f"learned_{seed}"] = value
        out[f"cpu_seconds_{seed}"] = cpu
        name = f"MaskablePPO seed {seed} ({cpu:.0f} s CPU)"
        print(f"    {name:36s} {_plan_text(plan)}", flush=True)
    out["worst"] = min(v for _, v, _ in learned)
    print(f"\n  {'policy':34s} {'tr P[K+N|K+N]':>14s} {'% of optimum':>13s}")
    rows = [(f"random play ({args.random_episodes} episodes)", rand, f" ± {rand_ci / opt:.1%}")]
    rows.append(("SFS (greedy)", inst.sfs, ""))
    rows += [(f"learned (MaskablePPO, seed {s})", v, "") for s, v, _ in learned]
    if len(learned) > 1:
        rows.append((f"learned, worst of {len(learned)} seeds", out["worst"], ""))
    rows.append(("optimum (EXS, certified)", opt, ""))
    for name, value, extra in rows:
        print(f"  {name:34s} {value:14.6f} {value / opt:12.1%}{extra}")
    return out


if __name__ == "__main__":
    main()
