"""Time to the exact equilibrium of the sensor-selection game, M = 3 … 16 sensors.

Run: ``python benchmarks/game.py [--max-m 16] [--lp-max-m 11] [--nashpy-max-m 10]
[--repeats 3]``. The game (docs/math.md §5) is built on tracking systems with M position sensors,
σ_w evenly spread over [1, 5], σ_v = 0.5, power 100, for both allocation rules. For each M it
prints the wall time of

- the double oracle (:func:`baselines.game.solve_double_oracle`, from the system: steady states,
  best responses and restricted LPs; it never builds the (2^M − 1)² matrix),
- the full LP (:func:`baselines.game.payoff_matrix` + :func:`baselines.game.solve_zero_sum`)
  up to ``--lp-max-m``,
- nashpy's ``Game.linear_program`` on the same matrix (two scipy LPs, default tolerances) up to
  ``--nashpy-max-m``,

each the median of up to ``--repeats`` calls (fewer once a method has used 10 s), then the double
oracle's value, its certified gap and the largest |value difference| to the other methods.
Targets: M = 10 ≤ 1 s and M = 16 ≤ 60 s with gap ≤ 1e-9 × value. BLAS runs single-threaded
unless ``OPENBLAS_NUM_THREADS`` is set.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.append(str(Path(__file__).resolve().parent.parent))  # after PYTHONPATH: it wins
import numpy as np

from baselines.game import payoff_matrix, solve_double_oracle, solve_zero_sum, to_nashpy
from experiments.reproduce import machine
from fdia_env.systems import tracking_system

TARGETS_S = {10: 1.0, 16: 60.0}
GAP_TARGET = 1e-9


def timed(run: Callable[[], Any], repeats: int, budget_s: float = 10.0) -> tuple[Any, float]:
    """Result and median wall time of up to ``repeats`` calls (stop once ``budget_s`` is spent)."""
    times, result = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = run()
        times.append(time.perf_counter() - t0)
        if sum(times) > budget_s:
            break
    return result, statistics.median(times)


def nashpy_value(L: np.ndarray) -> float:
    with warnings.catch_warnings():  # nashpy's scipy call may warn about its own options
        warnings.simplefilter("ignore")
        x, y = to_nashpy(L).linear_program()
    return float(x @ L @ y)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--max-m", type=int, default=16, help="largest number of sensors")
    parser.add_argument("--lp-max-m", type=int, default=11, help="largest M for the full LP")
    parser.add_argument("--nashpy-max-m", type=int, default=10, help="largest M for nashpy")
    parser.add_argument("--repeats", type=int, default=3, help="timed calls per method")
    args = parser.parse_args(argv)
    print(f"machine: {machine()} ({platform.node()})")
    print(
        "tracking, σ_w evenly over [1, 5], σ_v = 0.5, power 100; times in s "
        f"(median of up to {args.repeats} calls)\n"
    )
    header = (
        f"{'M':>3}{'strategies':>11}  {'allocation':<12}{'DO (s)':>9}{'iters':>6}"
        f"{'LP (s)':>9}{'nashpy (s)':>11}{'value':>17}{'gap':>10}{'|Δ value|':>10}"
    )
    print(header)
    print("-" * len(header))
    missed = []
    for M in range(3, args.max_m + 1):
        system = tracking_system(0.5, list(np.linspace(1.0, 5.0, M)))
        for allocation in ("independent", "dependent"):
            result, t_do = timed(
                lambda s=system, a=allocation: solve_double_oracle(s, 100.0, a), args.repeats
            )
            values = []
            t_lp = t_np = "–"
            if M <= args.lp_max_m:
                (_, _, v_lp), seconds = timed(
                    lambda s=system, a=allocation: solve_zero_sum(payoff_matrix(s, 100.0, a)),
                    args.repeats,
                )
                values.append(v_lp)
                t_lp = f"{seconds:.3f}"
            if M <= args.nashpy_max_m:
                L = payoff_matrix(system, 100.0, allocation)
                v_np, seconds = timed(lambda L=L: nashpy_value(L), args.repeats)
                values.append(v_np)
                t_np = f"{seconds:.3f}"
            diff = max((abs(v - result.value) for v in values), default=None)
            print(
                f"{M:>3}{2**M - 1:>11}  {allocation:<12}{t_do:>9.3f}{result.iterations:>6}"
                f"{t_lp:>9}{t_np:>11}{result.value:>17.12f}{result.gap:>10.1e}"
                f"{'–' if diff is None else f'{diff:.1e}':>10}"
            )
            target = TARGETS_S.get(M)
            if target is not None and (
                t_do > target or result.gap > GAP_TARGET * abs(result.value)
            ):
                missed.append(f"M = {M} {allocation}: {t_do:.2f} s, gap {result.gap:.1e}")
    checked = [M for M in TARGETS_S if M <= args.max_m]
    if checked:
        status = "met" if not missed else "MISSED: " + "; ".join(missed)
        targets = ", ".join(f"M = {M} ≤ {TARGETS_S[M]:.0f} s" for M in checked)
        print(f"\ntargets ({targets}, gap ≤ {GAP_TARGET:g} × value): {status}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
