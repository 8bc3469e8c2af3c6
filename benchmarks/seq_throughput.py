"""MaskablePPO training throughput: the sequential format against the ``Discrete(2**M)`` bitmask.

The bitmask format exists up to 16 sensors only, so the comparison runs on the 14-RTU IEEE 14
grid (``grid_system("ieee14", sensors="bus")``: 16,384 masked actions per window step), budget
c = 6, window N = 6, log det, where both formats play the identical instance; the sequential
format (``Discrete(M + 1)`` time-major and ``Discrete(N·M + 1)`` plan-first) is also timed on
the ``grid-ieee14`` preset (34 meters, c = 6, N = 6, log det), which has no bitmask format.
Every setting trains a fresh MaskablePPO (same settings, one env, one torch thread) for the
same number of decisions; the settings take turns within each repeat so a change of load hits
them alike. Rates are env decisions per CPU second of this process (wall-clock rates printed
too). Target: the sequential format at >= 20x the bitmask's decisions per second.

    python benchmarks/seq_throughput.py [--steps 1024] [--repeats 2]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from sb3_contrib import MaskablePPO

import fdia_env  # noqa: F401 - registers the Gymnasium ids

SETTINGS = {"n_steps": 256, "batch_size": 64, "n_epochs": 10, "learning_rate": 1e-3}
TARGET = 20.0
GYM_ID = "fdia_env/SparseAttack-v1"


def formats() -> dict[str, dict[str, Any]]:
    """Name -> env options of each timed setting."""
    from fdia_env.systems import grid_system

    rtu = grid_system("ieee14", sensors="bus")
    base = {"budget": 6, "horizon": 6, "objective": "logdet"}
    return {
        "ieee14-rtu bitmask": {"scenario": rtu, "action": "bitmask", **base},
        "ieee14-rtu sequential (time)": {"scenario": rtu, "action": "sequential", **base},
        "ieee14-rtu sequential (plan)": {
            "scenario": rtu, "action": "sequential", "order": "plan", **base
        },
        "grid-ieee14 sequential (time)": {
            "scenario": "grid-ieee14", "action": "sequential", **base
        },
        "grid-ieee14 sequential (plan)": {
            "scenario": "grid-ieee14", "action": "sequential", "order": "plan", **base
        },
    }  # fmt: skip


def learn_rate(kwargs: dict[str, Any], steps: int, seed: int) -> tuple[float, float]:
    """Decisions per wall-clock second and per CPU second of one fresh model's ``learn``."""
    model = MaskablePPO(
        "MlpPolicy", gym.make(GYM_ID, **kwargs), seed=seed, device="cpu", **SETTINGS
    )
    wall, cpu = time.perf_counter(), time.process_time()
    model.learn(steps)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    return model.num_timesteps / wall, model.num_timesteps / cpu


def main(argv: Sequence[str] | None = None) -> int:
    """Print the rates and the sequential/bitmask ratios; 0 when the target is met."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=1024, help="decisions per timed run")
    parser.add_argument("--repeats", type=int, default=2, help="timed runs per setting")
    args = parser.parse_args(argv)
    if args.steps < SETTINGS["n_steps"] or args.repeats < 1:
        parser.error(f"--steps must be >= {SETTINGS['n_steps']} and --repeats >= 1")
    torch.set_num_threads(1)
    settings = formats()
    for kwargs in settings.values():  # warm-up: imports, the grid build, first allocations
        learn_rate(kwargs, SETTINGS["n_steps"], seed=0)
    rates: dict[str, list[tuple[float, float]]] = {name: [] for name in settings}
    for r in range(args.repeats):
        for name, kwargs in settings.items():
            rates[name].append(learn_rate(kwargs, args.steps, seed=r))
    median = {name: tuple(np.median(np.array(v), axis=0)) for name, v in rates.items()}
    print(
        f"MaskablePPO {SETTINGS}, {args.steps} decisions x {args.repeats} repeats, one torch "
        f"thread; {platform.processor() or platform.machine()}, load {os.getloadavg()[0]:.1f}"
    )
    base_cpu = median["ieee14-rtu bitmask"][1]
    print(f"{'setting':32s} {'decisions/s (CPU)':>18s} {'(wall)':>10s} {'x bitmask (CPU)':>16s}")
    ok = True
    for name, (wall, cpu) in median.items():
        ratio = cpu / base_cpu
        print(f"{name:32s} {cpu:18.0f} {wall:10.0f} {ratio:15.1f}x")
        if "sequential" in name:
            ok = ok and ratio >= TARGET
    print(
        f"target: every sequential setting >= {TARGET:.0f}x the bitmask: "
        + ("met" if ok else "NOT met")
    )
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
