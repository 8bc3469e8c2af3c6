"""Env-steps per second of the native vector env on the numpy and the torch backend.

Run: ``python benchmarks/backends.py [--device cpu|cuda] [--threads N] [--quick]``. Times
``gymnasium.make_vec(..., vectorization_mode="vector_entry_point")`` with ``backend="numpy"``
and ``backend="torch"`` in alternating short bursts in one process (medians over rounds; the
ratio is the median of the per-round ratios), for ch4-position (expected and sampled dynamics)
and the 13-state IEEE 14-bus grid. On a GPU, ``--device cuda`` synchronises after each burst.
No targets: the GPU targets (and why they were chosen) are in ``benchmarks/gpu.py``.
"""

from __future__ import annotations

import argparse
import os
import platform

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
import gymnasium as gym
import numpy as np
import torch
from _timing import burst, warm_up

import fdia_env  # noqa: F401

CASES = [
    ("ch4-position, expected", {}, 1024, 8),
    ("ch4-position, expected", {}, 65536, 8),
    ("ch4-position, sampled", {"dynamics": "sampled"}, 65536, 8),
    ("grid-ieee14, expected", {"scenario": "grid-ieee14", "action": "single"}, 1024, 35),
]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default="cpu", help="torch device (default cpu)")
    p.add_argument("--threads", type=int, default=None, help="torch.set_num_threads")
    p.add_argument("--quick", action="store_true", help="shorter runs")
    args = p.parse_args()
    if args.threads is not None:
        torch.set_num_threads(args.threads)
    sync = torch.cuda.synchronize if args.device.startswith("cuda") else (lambda: None)
    seconds, rounds = (0.1, 3) if args.quick else (0.3, 5)
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, python "
        f"{platform.python_version()}, numpy {np.__version__}, torch {torch.__version__} "
        f"({torch.get_num_threads()} threads), device {args.device}"
    )
    print(f"{'case':26s} {'B':>6} {'numpy':>12} {'torch':>12} {'torch/numpy':>12}")
    for name, kw, B, n_actions in CASES:
        common = {"num_envs": B, "vectorization_mode": "vector_entry_point", **kw}
        envs = {
            "numpy": gym.make_vec("fdia_env/SparseAttack-v0", **common),
            "torch": gym.make_vec(
                "fdia_env/SparseAttack-v0", backend="torch", device=args.device, **common
            ),
        }
        rng = np.random.default_rng(0)
        raw = [rng.integers(0, n_actions, size=B) for _ in range(14)]
        actions = {"numpy": raw, "torch": [torch.as_tensor(a, device=args.device) for a in raw]}
        for key, env in envs.items():  # warm-up
            env.reset(seed=0)
            warm_up(env, actions[key][:2], sync=sync)
        rates: dict[str, list[float]] = {key: [] for key in envs}
        for _ in range(rounds):
            for key, env in envs.items():
                rates[key].append(burst(env, actions[key], seconds, sync=sync))
        med = {key: float(np.median(r)) for key, r in rates.items()}
        ratio = float(np.median(np.array(rates["torch"]) / np.array(rates["numpy"])))
        print(f"{name:26s} {B:6d} {med['numpy']:12,.0f} {med['torch']:12,.0f} {ratio:11.2f}x")


if __name__ == "__main__":
    main()
