"""Reset time of the system-family env: cached systems against preparing every system afresh.

Run: ``python benchmarks/family_reset.py``. Builds the ``system-family/tracking-m6-v0`` task's
env (20 systems, one drawn at every reset) in both actions formats and times ``reset()``: the
env as shipped (each system's setup prepared once, then reused) against the same env with its
cache off (every reset draws, validates and solves its system and builds its sparse env), in
this process. The target is a reset of at most 1 ms.
"""

from __future__ import annotations

import os
import platform
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as benchmarks/sparse.py: tiny LAPACK calls

from fdia_env.envs import system_family
from fdia_env.tasks import get as get_task


def reset_ms(env, resets: int = 400) -> float:
    """Median over 5 repeats of the mean time of ``resets`` resets, in ms (after a warm-up)."""
    env.reset(seed=0)
    for _ in range(50):
        env.reset()
    times = []
    for _ in range(5):
        t0 = time.perf_counter()
        for _ in range(resets):
            env.reset()
        times.append((time.perf_counter() - t0) / resets * 1e3)
    return sorted(times)[2]


def main() -> None:
    task = get_task("system-family/tracking-m6-v0")
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs")
    print(f"{'action':<12}{'cached ms':>11}{'fresh ms':>11}{'ratio':>8}")
    for action in ("bitmask", "sequential"):
        cached = reset_ms(task.make_env(action=action).unwrapped)
        saved = system_family.CACHED_SYSTEMS
        system_family.CACHED_SYSTEMS = 0
        try:
            fresh = reset_ms(task.make_env(action=action).unwrapped, resets=100)
        finally:
            system_family.CACHED_SYSTEMS = saved
        print(f"{action:<12}{cached:>11.3f}{fresh:>11.3f}{fresh / cached:>7.1f}x")


if __name__ == "__main__":
    main()
