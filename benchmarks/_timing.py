"""Timing helpers shared by the benchmark scripts: median rate over repeats, vector bursts."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any


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


def burst(
    venv: Any,
    actions: Sequence[Any],
    seconds: float,
    clock: Callable[[], float] = time.perf_counter,
    sync: Callable[[], None] | None = None,
) -> float:
    """Env-steps/s of stepping the vector env ``venv`` with ``actions`` for about ``seconds``.

    Args:
        venv: A Gymnasium vector env (its ``num_envs`` members count as steps).
        actions: Batched actions, stepped in turn (whole passes only).
        seconds: Keep stepping while less than this much ``clock`` time has passed (0: no step).
        clock: ``time.perf_counter`` (wall time) or ``time.process_time`` (CPU time).
        sync: Called before the clock stops (e.g. ``torch.cuda.synchronize``), or None.
    """
    steps, t0 = 0, clock()
    while clock() - t0 < seconds:
        for a in actions:
            venv.step(a)
        steps += len(actions)
    if sync is not None:
        sync()
    return steps * venv.num_envs / (clock() - t0)


def warm_up(venv: Any, actions: Sequence[Any], sync: Callable[[], None] | None = None) -> None:
    """Step ``venv`` once with each of ``actions`` (imports, caches, first allocations), untimed.

    (:func:`burst` with ``seconds=0`` takes no step, so it cannot warm up.)
    """
    for a in actions:
        venv.step(a)
    if sync is not None:
        sync()
