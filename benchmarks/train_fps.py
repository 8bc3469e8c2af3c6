"""SB3 PPO training speed on fdia_env/SparseAttack-v0 against CartPole-v1, same settings.

Both runs use one env (DummyVecEnv), the same PPO settings (n_steps, batch size, epochs,
network) and one torch thread, so the ratio measures what the env costs inside a training loop.
Target: SparseAttack-v0 at >= 90 % of CartPole-v1's steps/s, judged on CPU-time rates (this
process only), which other work on a shared machine does not move; wall-clock rates are printed
too. MaskablePPO on SparseAttack-v0 (what ``make demo`` trains) is printed for information.

    python benchmarks/train_fps.py [--steps 8192] [--repeats 5]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from collections.abc import Sequence

import gymnasium as gym
import numpy as np
import torch
from sb3_contrib import MaskablePPO
from stable_baselines3 import PPO

import fdia_env  # noqa: F401 - registers the Gymnasium ids

PPO_SETTINGS = {
    "n_steps": 512,
    "batch_size": 128,
    "n_epochs": 10,
    "learning_rate": 1e-3,
    "policy_kwargs": {"net_arch": [64, 64]},
}
TARGET = 0.90


def learn_rate(algo: type, env_id: str, steps: int, seed: int) -> tuple[float, float]:
    """Steps per wall-clock second and per CPU second of one fresh model's ``learn(steps)``."""
    model = algo("MlpPolicy", gym.make(env_id), seed=seed, device="cpu", **PPO_SETTINGS)
    wall, cpu = time.perf_counter(), time.process_time()
    model.learn(steps)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    return model.num_timesteps / wall, model.num_timesteps / cpu


def measure(
    settings: dict[str, tuple[type, str]], steps: int, repeats: int
) -> dict[str, tuple[float, float]]:
    """Median (wall, CPU) steps/s per setting.

    The settings take turns within each repeat, so a change in the machine's load during the
    run hits them alike; the CPU-time rate (this process only, one torch thread) is the one
    that other work on a shared machine does not move.
    """
    for algo, env_id in settings.values():  # warm-up: imports, caches, first allocations
        learn_rate(algo, env_id, PPO_SETTINGS["n_steps"], seed=0)
    rates: dict[str, list[tuple[float, float]]] = {name: [] for name in settings}
    for r in range(repeats):
        for name, (algo, env_id) in settings.items():
            rates[name].append(learn_rate(algo, env_id, steps, seed=r))
    return {name: tuple(np.median(np.array(v), axis=0)) for name, v in rates.items()}


def main(argv: Sequence[str] | None = None) -> dict[str, float]:
    """Measure and print steps/s of each setting and the ratio to CartPole-v1."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=8192, help="PPO steps per measurement")
    p.add_argument("--repeats", type=int, default=5, help="measurements per setting (median)")
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, python "
        f"{platform.python_version()}, torch {torch.__version__}, 1 torch thread; PPO n_steps "
        f"{PPO_SETTINGS['n_steps']}, batch {PPO_SETTINGS['batch_size']}, "
        f"{PPO_SETTINGS['n_epochs']} epochs, MLP 64x64, 1 env; median of {args.repeats} x "
        f"{args.steps} steps"
    )
    settings = {
        "PPO on fdia_env/SparseAttack-v0": (PPO, "fdia_env/SparseAttack-v0"),
        "PPO on CartPole-v1": (PPO, "CartPole-v1"),
        "MaskablePPO on fdia_env/SparseAttack-v0": (MaskablePPO, "fdia_env/SparseAttack-v0"),
    }
    rates = measure(settings, args.steps, args.repeats)
    print(f"{'':42s} {'wall':>9s} {'CPU':>9s}  (steps/s)")
    for name, (wall, cpu) in rates.items():
        print(f"{name:42s} {wall:9,.0f} {cpu:9,.0f}")
    sparse, cartpole = rates["PPO on fdia_env/SparseAttack-v0"], rates["PPO on CartPole-v1"]
    ratio_wall, ratio_cpu = sparse[0] / cartpole[0], sparse[1] / cartpole[1]
    verdict = "met" if ratio_cpu >= TARGET else "NOT met"
    print(
        f"\nSparseAttack-v0 / CartPole-v1: {ratio_cpu:.1%} of CPU-time rate, {ratio_wall:.1%} of "
        f"wall-clock rate (target >= {TARGET:.0%}: {verdict})"
    )
    return {**{k: v[0] for k, v in rates.items()}, "ratio": ratio_cpu, "ratio_wall": ratio_wall}


if __name__ == "__main__":
    main()
