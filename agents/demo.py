"""``make demo``: train a small MaskablePPO attacker and score it against the analytic optimum.

The attacker learns ``fdia_env/SparseAttack-v0`` on ``ch4-position`` (N = 6, c = 5); the score
is its deterministic episode return (``tr P[K+N|K+N]``, expected dynamics) divided by the
exhaustive-search optimum (EXS) and compared with the greedy SFS answer.

Run ``python -m agents.demo --help`` for the options.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence

import gymnasium as gym
import numpy as np
import torch
from sb3_contrib import MaskablePPO

import fdia_env  # noqa: F401 - registers the Gymnasium ids
from baselines.sparse import exhaustive, sfs


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """Command-line options of the demo."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=50_000, help="PPO environment steps")
    p.add_argument("--seed", type=int, default=0, help="training seed")
    p.add_argument("--scenario", default="ch4-position", help="scenario preset")
    p.add_argument("--budget", type=int, default=5, help="sparsity budget c")
    p.add_argument("--horizon", type=int, default=6, help="attack window N")
    return p.parse_args(argv)


def rollout(model: MaskablePPO, env: gym.Env) -> tuple[float, list[int]]:
    """Deterministic episode return and the actions taken."""
    obs, info = env.reset(seed=0)
    total, actions, done = 0.0, [], False
    while not done:
        action, _ = model.predict(
            obs, action_masks=info["action_mask"].astype(bool), deterministic=True
        )
        actions.append(int(action))
        obs, reward, terminated, truncated, info = env.step(int(action))
        total += float(reward)
        done = terminated or truncated
    return total, actions


def main(argv: Sequence[str] | None = None) -> dict[str, float]:
    """Train, evaluate and print the score table; returns the numbers."""
    args = parse_args(argv)
    torch.set_num_threads(1)
    kwargs = {"scenario": args.scenario, "budget": args.budget, "horizon": args.horizon}
    env = gym.make("fdia_env/SparseAttack-v0", **kwargs)
    model = MaskablePPO(
        "MlpPolicy",
        env,
        seed=args.seed,
        n_steps=512,
        batch_size=128,
        learning_rate=1e-3,
        gamma=1.0,
        ent_coef=0.01,
        verbose=0,
    )
    t0 = time.perf_counter()
    model.learn(total_timesteps=args.steps)
    train_s = time.perf_counter() - t0
    learned, actions = rollout(model, env)
    opt = exhaustive(args.scenario, budget=args.budget, horizon=args.horizon)
    greedy = sfs(args.scenario, budget=args.budget, horizon=args.horizon)
    plan = [[(a >> i) & 1 for i in range(env.unwrapped.parallel.system.M)] for a in actions]
    print(
        f"\nMaskablePPO attacker on fdia_env/SparseAttack-v0 ({args.scenario}, c={args.budget}, "
        f"N={args.horizon}), {args.steps} steps in {train_s:.0f} s (seed {args.seed})"
    )
    print(f"  learned plan (rows = steps K+1.., columns = sensors): {plan}")
    print(f"  {'policy':28s} {'tr P[K+N|K+N]':>14s} {'score vs EXS':>13s}")
    for name, value in (
        ("learned (MaskablePPO)", learned),
        ("SFS (greedy)", greedy.value),
        ("EXS (optimum)", opt.value),
    ):
        print(f"  {name:28s} {value:14.6f} {value / opt.value:12.1%}")
    return {
        "learned": learned,
        "exs": opt.value,
        "sfs": greedy.value,
        "score": learned / opt.value,
        "train_seconds": train_s,
    }


if __name__ == "__main__":
    np.set_printoptions(precision=4)
    main()
