"""Run time of the sparse-attack solvers at the literature's sizes, and EXS's peak memory.

Run: ``python benchmarks/sparse.py [--repeats R]``. For ch4-position (c = 5) at sizes
M·N = 18 / 30 / 60 (N = 6, 10, 20) prints each solver's median wall time over R calls (after one
warm-up call), the literature's Matlab time and the ratio between them, then the peak memory of
EXS at size 60 (``tracemalloc`` peak of the Python/numpy allocations during one search, and the
process's ``ru_maxrss``). BLAS runs single-threaded unless ``OPENBLAS_NUM_THREADS`` is set. The
project's target for EXS at size 60 is ≤ 3 s and ≤ 2 GB.
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import sys
import tracemalloc
from pathlib import Path

# Single-threaded BLAS for tiny LAPACK calls (see experiments/reproduce/__init__.py); set before
# numpy loads.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.append(str(Path(__file__).resolve().parent.parent))  # after PYTHONPATH: it wins
from baselines.sparse import SOLVERS, exhaustive
from experiments.reproduce import machine
from experiments.reproduce.ch4 import literature_columns, solver_label
from experiments.reproduce.common import timed
from fdia_env import scenarios

SIZES = (6, 10, 20)  # horizons N; M = 3 gives sizes 18 / 30 / 60
EXS_TARGET_S = 3.0
EXS_TARGET_BYTES = 2 * 2**30


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=5, help="timed calls per solver and size")
    args = parser.parse_args(argv)
    system = scenarios.get("ch4-position").system
    print(f"machine: {machine()} ({platform.node()})")
    print(f"ch4-position, c = 5; median of {args.repeats} calls after one warm-up\n")
    print(f"{'solver':<8}{'size':>5}{'time (s)':>11}{'literature (s)':>16}{'lit / ours':>12}")
    exs_60 = None
    for col, N in enumerate(SIZES):
        for name, solver in SOLVERS.items():
            seconds = timed(lambda s=solver, n=N: s(system, 5, n), args.repeats)[1]
            lit_text, ratio = literature_columns(name, col, seconds)
            print(f"{solver_label(name):<8}{3 * N:>5}{seconds:>11.4f}{lit_text:>16}{ratio:>12}")
            if name == "exs" and N == 20:
                exs_60 = seconds

    tracemalloc.start()
    exhaustive(system, 5, 20)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    maxrss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # KiB on Linux
    ok = exs_60 <= EXS_TARGET_S and max(peak, maxrss) <= EXS_TARGET_BYTES
    print(
        f"\nEXS at size 60 (5,461,512 sets): {exs_60:.3f} s; tracemalloc peak "
        f"{peak / 2**20:.1f} MiB; process ru_maxrss {maxrss / 2**20:.1f} MiB "
        f"(target ≤ {EXS_TARGET_S:.0f} s, ≤ 2 GiB: {'met' if ok else 'MISSED'})"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
