"""RLlib scale-out on fdia_env: sampling rate per env-runner count, iteration time, defaults.

Run: ``python benchmarks/rllib.py [--iterations 3] [--runners 0 1 2] [--num-cpus 2]``
(needs the fdia-env[rllib] extra). On multi-agent PPO on ``sensor_game_v0`` (ch5-game,
one-step episodes) it prints

- the bare env loop (the PettingZoo parallel env stepped with random actions, no RLlib), the
  reference every rate is divided by;
- env steps sampled per second of sampling time with the shipped config
  (:func:`agents.rllib.config.ppo_config`) and 0, 1, 2 remote env runners;
- the wall time of one training iteration (sampling and learning) with the shipped config and
  with RLlib's defaults (``fast=False``: 4,000-step batches, 30 epochs, episodes converted to
  numpy at every step, one env per runner, 256×256 networks), and the steps each iteration
  trains on.

Every figure is the median over ``--iterations`` iterations after one warm-up iteration (RLlib's
defaults: ``--defaults-iterations``, default 1, without warm-up: one takes minutes here). The
machine's load average is printed too: on a shared machine the absolute times scale with it,
the ratios much less.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.append(str(Path(__file__).resolve().parent.parent))  # after PYTHONPATH: it wins

import numpy as np

from experiments.reproduce import machine
from fdia_env import sensor_game_v0

ENV = "sensor_game_v0"
ENV_CONFIG = {"scenario": "ch5-game"}


def bare_rate(steps: int = 20_000) -> float:
    env = sensor_game_v0.parallel_env(**ENV_CONFIG)
    rng = np.random.default_rng(0)
    n = {a: int(env.action_space(a).n) for a in env.possible_agents}
    env.reset(seed=0)
    t0 = time.perf_counter()
    for i in range(steps):
        _, _, terms, _, _ = env.step({a: int(rng.integers(n[a])) for a in n})
        if all(terms.values()):
            env.reset(seed=i)
    return steps / (time.perf_counter() - t0)


def measure(config, iterations: int, warm_up: bool = True) -> dict[str, float]:
    from agents.rllib.config import steps_sampled

    algo = config.build_algo()
    try:
        if warm_up:
            algo.train()
        walls, rates, steps = [], [], []
        for _ in range(iterations):
            t0 = time.perf_counter()
            result = algo.train()
            walls.append(time.perf_counter() - t0)
            n = steps_sampled(result)
            sampling = result["timers"]["env_runner_sampling_timer"]
            rates.append(n / sampling)
            steps.append(n)
            learning = result["timers"].get("learner_update_timer", float("nan"))
            print(
                f"    iteration {walls[-1]:.2f} s: sampling {sampling:.2f} s, learning "
                f"{learning:.2f} s",
                flush=True,
            )
        return {
            "iteration_s": statistics.median(walls),
            "sample_rate": statistics.median(rates),
            "steps": statistics.median(steps),
        }
    finally:
        algo.stop()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--iterations", type=int, default=3)
    parser.add_argument("--runners", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--num-cpus", type=int, default=2)
    parser.add_argument(
        "--defaults-iterations",
        type=int,
        default=1,
        help="iterations of RLlib's defaults (no warm-up: each takes minutes here)",
    )
    args = parser.parse_args()

    import ray
    import torch

    from agents.rllib.config import ppo_config

    torch.set_num_threads(1)
    print(machine())
    bare = bare_rate()
    print(f"bare env loop ({ENV}, random actions): {bare:,.0f} env steps/s")
    ray.init(num_cpus=args.num_cpus, include_dashboard=False, log_to_driver=False)
    print(f"load average before: {os.getloadavg()[0]:.2f}")
    rows = []
    for k in args.runners:
        m = measure(ppo_config(ENV, ENV_CONFIG, num_env_runners=k), args.iterations)
        rows.append((f"shipped, {k} env runner(s)", m))
        print(
            f"  shipped config, {k} env runners: {m['sample_rate']:8,.0f} env steps/s sampled "
            f"({m['sample_rate'] / bare:.3f} × bare), iteration {m['iteration_s']:.2f} s "
            f"({m['steps']:.0f} steps)",
            flush=True,
        )
    m = measure(
        ppo_config(ENV, ENV_CONFIG, num_env_runners=0, fast=False),
        args.defaults_iterations,
        warm_up=False,
    )
    shipped = rows[0][1]
    print(
        f"  RLlib defaults, 0 env runners: {m['sample_rate']:8,.0f} env steps/s sampled "
        f"({m['sample_rate'] / bare:.3f} × bare), iteration {m['iteration_s']:.2f} s "
        f"({m['steps']:.0f} steps)"
    )
    per_step = (m["iteration_s"] / m["steps"]) / (shipped["iteration_s"] / shipped["steps"])
    print(
        f"shipped vs defaults: sampling {shipped['sample_rate'] / m['sample_rate']:.1f}× faster, "
        f"iteration {m['iteration_s'] / shipped['iteration_s']:.1f}× shorter "
        f"({per_step:.1f}× less time per step trained)"
    )
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    ray.shutdown()


if __name__ == "__main__":
    main()
