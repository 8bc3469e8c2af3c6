"""Branch and bound against EXS in the same process, and certified optima beyond enumeration.

Run: ``python benchmarks/bnb.py [--repeats R] [--time-limit S] [--scenario NAME ...]``.

1. ch4-position at size 60 (N = 20, c = 5): median wall time of B&B and of EXS over R calls
   (after one warm-up call each) and their ratio (target: B&B ≤ 0.5 × EXS, optimum proved).
2. 14 sensors over N = 6 (84 pairs, c = 5): the 14-sensor mixed tracking system of
   :mod:`baselines.sparse.testbeds` (EXS in the same process for the ratio) and the DC IEEE
   14-bus model of the testbeds (13 states, 14 injection meters; EXS on it takes over 10
   minutes and runs only with ``--exs-grid``). Target: certified optimum in ≤ 10 s.
3. About 300 pairs, c = 5: certified optimum or certified gap ≤ 1 % within the time limit
   (default 60 s), on the 50-sensor mixed tracking system and the 50-meter DC model over N = 6,
   and pandapower's ``grid-ieee14`` (34 meters) over N = 9 (306 pairs).
4. The grid presets at their own budget and horizon (``grid-ieee14``: 204 pairs, c = 6;
   ``grid-ieee30``, ``grid-ieee57``), plus preset names given with ``--scenario``: what B&B
   certifies within the time limit (no target; reported as reached).

``--old-bounds`` runs B&B without the mixed (tail-enumeration) bound, as before it existed;
``--no-split`` without the split bound (:mod:`baselines.sparse.split`), as before it existed.
BLAS runs single-threaded unless ``OPENBLAS_NUM_THREADS`` is set.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.append(str(Path(__file__).resolve().parent.parent))  # after PYTHONPATH: it wins
from baselines.sparse import branch_and_bound, exhaustive
from baselines.sparse.testbeds import dc_grid14, mixed_tracking
from experiments.reproduce import machine
from experiments.reproduce.common import timed
from fdia_env import scenarios

GRID_PRESETS = ("grid-ieee14", "grid-ieee30", "grid-ieee57")


def describe(result) -> str:
    status = "proved optimal" if result.proved_optimal else f"gap {100 * result.gap:.3f} %"
    return (
        f"value {result.value:.10g}, bound {result.upper_bound:.10g}, {status}, "
        f"{result.nodes} nodes, {result.seconds:.2f} s"
    )


def preset(name: str):
    """The named preset, or None (with a message) when fdia_env.scenarios does not have it."""
    if name not in scenarios.names():
        print(f"  {name}: not a preset of fdia_env.scenarios here; skipped")
        return None
    return scenarios.get(name)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=3, help="timed calls in part 1")
    parser.add_argument("--time-limit", type=float, default=60.0, help="B&B limit, parts 2-3")
    parser.add_argument("--scenario", action="append", default=[], help="extra preset names")
    parser.add_argument("--skip-exs", action="store_true", help="no EXS reference in part 2")
    parser.add_argument("--exs-grid", action="store_true", help="EXS on dc-ieee14-14 too (slow)")
    parser.add_argument(
        "--old-bounds", action="store_true", help="B&B without the mixed bound (before/after)"
    )
    parser.add_argument("--no-split", action="store_true", help="B&B without the split bound")
    parser.add_argument("--parts", default="1234", help="which parts to run, e.g. 34")
    args = parser.parse_args(argv)
    mixed = not args.old_bounds
    opts = {"mixed_bound": mixed, "split": not args.no_split}
    names = ["smoother", "allocation"] + ["mixed"] * mixed + ["split"] * opts["split"]
    print(f"bounds: {' + '.join(names)}")
    print(f"machine: {machine()} ({platform.node()})")

    if "1" in args.parts:
        print("\n1. ch4-position, size 60 (N = 20, c = 5), median of", args.repeats, "calls")
        sys60 = scenarios.get("ch4-position").system
        bnb, t_bnb = timed(lambda: branch_and_bound(sys60, 5, 20, **opts), args.repeats)
        exs, t_exs = timed(lambda: exhaustive(sys60, 5, 20), args.repeats)
        same = abs(bnb.value - exs.value) <= 1e-12 * exs.value
        print(f"  EXS {t_exs:.3f} s; B&B {t_bnb:.3f} s ({describe(bnb)})")
        print(
            f"  B&B / EXS = {t_bnb / t_exs:.3f} (target ≤ 0.5: "
            f"{'met' if t_bnb <= 0.5 * t_exs and bnb.proved_optimal else 'MISSED'}); "
            f"same optimum: {same}"
        )

    if "2" in args.parts:
        print("\n2. 14 sensors, N = 6, c = 5 (84 pairs)")
        instances = [("mixed-tracking-14", mixed_tracking(14))]
        instances.append(("dc-ieee14-14 (13 states, 14 injection meters)", dc_grid14(14)))
        for name, system in instances:
            exs_here = not args.skip_exs and (system.n <= 2 or args.exs_grid)
            for objective in ("trace", "logdet"):
                t0 = time.perf_counter()
                res = branch_and_bound(system, 5, 6, objective, time_limit=args.time_limit, **opts)
                t_b = time.perf_counter() - t0
                line = f"  {name} {objective}: B&B {describe(res)}"
                ok = res.proved_optimal and t_b <= 10.0
                if exs_here:
                    t0 = time.perf_counter()
                    ref = exhaustive(system, 5, 6, objective)
                    t_e = time.perf_counter() - t0
                    match = abs(ref.value - res.value) <= 1e-9 * max(abs(ref.value), 1.0)
                    line += f"; EXS {t_e:.2f} s, B&B / EXS = {t_b / t_e:.3f}, same optimum: {match}"
                if not exs_here:
                    line += "; EXS not run (--exs-grid: 3·10⁷ sets of 13×13 recursions, > 10 min)"
                print(line + f" (target certified ≤ 10 s: {'met' if ok else 'MISSED'})")

    if "3" in args.parts:
        print(f"\n3. about 300 pairs, c = 5, time limit {args.time_limit:.0f} s")
        big = [("mixed-tracking-50 (N = 6)", mixed_tracking(50), 5, 6)]
        big.append(("dc-ieee14-50 (50 meters, N = 6)", dc_grid14(50), 5, 6))
        sc = preset("grid-ieee14")
        if sc is not None:
            big.append(("grid-ieee14 (34 meters, N = 9)", sc, 5, 9))
        for name, system, c, N in big:
            for objective in ("trace", "logdet"):
                res = branch_and_bound(system, c, N, objective, time_limit=args.time_limit, **opts)
                ok = res.proved_optimal or res.gap <= 0.01
                target = "met" if ok else "MISSED"
                print(f"  {name} {objective}: {describe(res)} (target ≤ 1 %: {target})")

    if "4" in args.parts:
        print(f"\n4. grid presets at their budget and horizon, time limit {args.time_limit:.0f} s")
        for name in dict.fromkeys([*GRID_PRESETS, *args.scenario]):
            sc = preset(name)
            if sc is None:
                continue
            c, N = sc.budget or 5, sc.horizon or 6
            pairs = sc.system.M * N
            for objective in ("trace", "logdet"):
                res = branch_and_bound(sc, c, N, objective, time_limit=args.time_limit, **opts)
                print(f"  {name} ({pairs} pairs, c = {c}) {objective}: {describe(res)}")

    return 0


if __name__ == "__main__":
    raise SystemExit(main())
