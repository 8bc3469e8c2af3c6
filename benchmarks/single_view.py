"""Steps per second of the Gymnasium single view against Gymnasium's CartPole-v1, interleaved.

Run: ``python benchmarks/single_view.py [--rounds R] [--clock cpu]``. Times
``gymnasium.make("fdia_env/SparseAttack-v0")`` (ch4-position, expected dynamics, random
actions) and ``gymnasium.make("CartPole-v1")`` (random actions) in alternating bursts of 2,000
steps, so both meet the same machine load; prints the median rates and the median of the
per-round ratios. Target: the view at >= 0.3x CartPole's single env. ``--clock cpu`` times this
process's CPU time (steadier on a shared machine than wall time, the default).
"""

from __future__ import annotations

import argparse
import os
import platform
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
import gymnasium as gym
import numpy as np

import fdia_env  # noqa: F401  (registers the ids)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rounds", type=int, default=15, help="alternating bursts per env (>= 1)")
    p.add_argument("--clock", choices=("wall", "cpu"), default="wall", help="what is timed")
    args = p.parse_args()
    if args.rounds < 1:
        p.error(f"--rounds must be >= 1, got {args.rounds}")
    clock = time.process_time if args.clock == "cpu" else time.perf_counter
    rng = np.random.default_rng(0)
    envs = {
        "view": (gym.make("fdia_env/SparseAttack-v0", scenario="ch4-position"), 8),
        "cartpole": (gym.make("CartPole-v1"), 2),
    }
    actions = {k: [int(a) for a in rng.integers(0, n, 2000)] for k, (_, n) in envs.items()}

    def burst(key: str) -> float:
        env = envs[key][0]
        t0 = clock()
        for a in actions[key]:
            _, _, term, trunc, _ = env.step(a)
            if term or trunc:
                env.reset()
        return len(actions[key]) / (clock() - t0)

    for env, _ in envs.values():
        env.reset(seed=0)
    for key in envs:  # warm-up
        burst(key)
    rates: dict[str, list[float]] = {k: [] for k in envs}
    for _ in range(args.rounds):
        for key in envs:
            rates[key].append(burst(key))
    ratio = np.array(rates["view"]) / np.array(rates["cartpole"])
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, python "
        f"{platform.python_version()}, numpy {np.__version__}; "
        f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; clock: {args.clock}"
    )
    print(f"gymnasium.make view (expected) {np.median(rates['view']):12,.0f} steps/s")
    print(f"gymnasium.make CartPole-v1     {np.median(rates['cartpole']):12,.0f} steps/s")
    print(
        f"view / CartPole-v1: {np.median(ratio):.2f}x (rounds from {ratio.min():.2f}x to "
        f"{ratio.max():.2f}x; target >= 0.3x)"
    )


if __name__ == "__main__":
    main()
