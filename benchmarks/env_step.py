"""Steps per second of sparse_attack_v0 against reference loops measured in the same run.

Run: ``python benchmarks/env_step.py``. Prints the rates and the ratios the project tracks:
the Gymnasium view (through ``gymnasium.make`` with its default wrappers) against 50,000
steps/s and against Gymnasium's CartPole-v1 made the same way, and the PettingZoo parallel env
against PettingZoo's own ``rps_v2`` parallel env.
"""

from __future__ import annotations

import os
import platform
import sys
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as benchmarks/sparse.py: tiny LAPACK calls
import gymnasium as gym
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _timing import rate

import fdia_env  # noqa: F401
from fdia_env import scenarios, sparse_attack_v0


def parallel_runner(dynamics: str):
    env = sparse_attack_v0.parallel_env(scenario="ch4-position", dynamics=dynamics)
    rng = np.random.default_rng(0)
    actions = rng.integers(0, 8, size=100_000)

    def run(steps: int) -> None:
        env.reset(seed=0)
        for i in range(steps):
            if not env.agents:
                env.reset()
            env.step({"attacker": int(actions[i % actions.size])})

    return run


def gym_loop(env: gym.Env, actions: np.ndarray):
    """A loop of ``steps`` steps of a Gymnasium env playing ``actions`` in turn."""

    def run(steps: int) -> None:
        env.reset(seed=0)
        for i in range(steps):
            _, _, term, trunc, _ = env.step(int(actions[i % actions.size]))
            if term or trunc:
                env.reset()

    return run


def gym_runner(dynamics: str):
    env = gym.make("fdia_env/SparseAttack-v0", scenario="ch4-position", dynamics=dynamics)
    return gym_loop(env, np.random.default_rng(0).integers(0, 8, size=100_000))


def cartpole_runner():
    env = gym.make("CartPole-v1")  # Gymnasium's own single env, through the same make()
    return gym_loop(env, np.random.default_rng(0).integers(0, 2, size=100_000))


def filterpy_runner():
    from filterpy.kalman import KalmanFilter

    system = scenarios.get("ch4-position").system
    kf = KalmanFilter(dim_x=system.n, dim_z=system.nz)
    kf.F, kf.Q, kf.H, kf.R = (np.array(a) for a in (system.F, system.Q, system.H, system.R))
    zs = np.random.default_rng(0).standard_normal((1000, system.nz))

    def run(steps: int) -> None:
        for i in range(steps):
            kf.predict()
            kf.update(zs[i % 1000])

    return run


def rps_runner():
    from pettingzoo.classic import rps_v2

    env = rps_v2.parallel_env()
    acts = np.random.default_rng(0).integers(0, 3, size=(100_000, 2))

    def run(steps: int) -> None:
        env.reset(seed=0)
        for i in range(steps):
            if not env.agents:
                env.reset()
            a = acts[i % acts.shape[0]]
            env.step({"player_0": int(a[0]), "player_1": int(a[1])})

    return run


def main() -> None:
    steps = 20_000
    results = {
        "parallel env (expected)": rate(parallel_runner("expected"), steps),
        "parallel env (sampled)": rate(parallel_runner("sampled"), steps),
        "gymnasium.make view (expected)": rate(gym_runner("expected"), steps),
        "gymnasium.make view (sampled)": rate(gym_runner("sampled"), steps),
        "gymnasium.make CartPole-v1": rate(cartpole_runner(), steps),
        "filterpy KalmanFilter predict+update": rate(filterpy_runner(), steps),
        "pettingzoo rps_v2 parallel": rate(rps_runner(), steps),
    }
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, "
        f"python {platform.python_version()}, numpy {np.__version__}, "
        f"OPENBLAS_NUM_THREADS={os.environ['OPENBLAS_NUM_THREADS']}"
    )
    for name, r in results.items():
        print(f"{name:40s} {r:12,.0f} steps/s")
    rps = results["pettingzoo rps_v2 parallel"]
    par, view = results["parallel env (expected)"], results["gymnasium.make view (expected)"]
    fp = results["filterpy KalmanFilter predict+update"]
    print()
    print(f"parallel env / rps_v2:            {par / rps:6.2f}x  (target >= 3)")
    print(f"gymnasium view / 50,000 steps/s:  {view / 50_000:6.2f}x  (target >= 1)")
    cart = results["gymnasium.make CartPole-v1"]
    print(f"gymnasium view / CartPole-v1:     {view / cart:6.2f}x  (target >= 0.3)")
    print(f"gymnasium view / filterpy step:   {view / fp:6.2f}x")
    print(f"sampled parallel / filterpy step: {results['parallel env (sampled)'] / fp:6.2f}x")


if __name__ == "__main__":
    main()
