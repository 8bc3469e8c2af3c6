"""Timing helper shared by the benchmark scripts: median rate over repeats."""

from __future__ import annotations

import time
from collections.abc import Callable


def rate(run: Callable[[int], None], steps: int, repeats: int = 5) -> float:
    """Median steps per second of ``run(steps)`` over ``repeats`` runs (after one warm-up)."""
    run(max(steps // 10, 1))
    rates = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        run(steps)
        rates.append(steps / (time.perf_counter() - t0))
    rates.sort()
    return rates[len(rates) // 2]
