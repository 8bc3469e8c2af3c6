"""Env-steps per second of the native vector env against reference loops in the same run.

Run: ``python benchmarks/vector.py [--quick]``. For B = 1, 64, 1024, 65536 envs it times
``fdia_env/SparseAttack-v0`` (ch4-position, expected dynamics, random actions) as the native
batched vector env and as Gymnasium's ``SyncVectorEnv`` of the same single env (B ≤ 1024), and
Gymnasium's own native CartPole vector env. Targets (issue 8): at B = 65536 ≥ 1.5× CartPole's
env-steps/s, and at B = 1024 ≥ 50× ``SyncVectorEnv`` of the same env.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
import gymnasium as gym
import numpy as np

import fdia_env  # noqa: F401


def env_steps_per_second(venv: gym.vector.VectorEnv, n_actions: int, budget_s: float) -> float:
    """Median env-steps/s over 3 timed runs of about ``budget_s`` each (after a warm-up)."""
    B = venv.num_envs
    rng = np.random.default_rng(0)
    actions = [rng.integers(0, n_actions, size=B) for _ in range(16)]
    venv.reset(seed=0)
    for a in actions[:4]:
        venv.step(a)
    rates = []
    for _ in range(3):
        steps, t0 = 0, time.perf_counter()
        while time.perf_counter() - t0 < budget_s:
            for a in actions:
                venv.step(a)
            steps += len(actions)
        rates.append(steps * B / (time.perf_counter() - t0))
    return sorted(rates)[1]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="shorter runs")
    args = p.parse_args()
    budget = 0.3 if args.quick else 1.0
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, "
        f"python {platform.python_version()}, numpy {np.__version__}, "
        f"OPENBLAS_NUM_THREADS={os.environ['OPENBLAS_NUM_THREADS']}"
    )
    print(
        f"{'B':>6} {'native (env-steps/s)':>21} {'SyncVectorEnv':>14} {'CartPole native':>16} "
        f"{'native/Sync':>12} {'native/CartPole':>16}"
    )
    for B in (1, 64, 1024, 65536):
        kw = {"num_envs": B}
        native = gym.make_vec(
            "fdia_env/SparseAttack-v0", vectorization_mode="vector_entry_point", **kw
        )
        r_native = env_steps_per_second(native, 8, budget)
        r_sync = float("nan")
        if B <= 1024:
            sync = gym.make_vec("fdia_env/SparseAttack-v0", vectorization_mode="sync", **kw)
            r_sync = env_steps_per_second(sync, 8, budget)
        cart = gym.make_vec("CartPole-v1", vectorization_mode="vector_entry_point", **kw)
        r_cart = env_steps_per_second(cart, 2, budget)
        print(
            f"{B:6d} {r_native:21,.0f} {r_sync:14,.0f} {r_cart:16,.0f} "
            f"{r_native / r_sync:11.1f}x {r_native / r_cart:15.2f}x"
        )
    print("targets: native/Sync >= 50x at B = 1024; native/CartPole >= 1.5x at B = 65536")


if __name__ == "__main__":
    main()
