"""Speed of the power-grid presets against ch4-position, measured in the same run.

Run: ``python benchmarks/grid.py [--quick] [--max-batch B] [--presets P ...] [--vector-only]
[--clock cpu]``.
For ch4-position (the reference) and each grid preset (``grid-ieee14/30/57/118``, needs the
``[grid]`` extra) it prints:

- env-steps/s of the single ``gymnasium.make("fdia_env/SparseAttack-v0")`` view (expected
  dynamics, random actions: a few sensors per step), and its ratio to ch4-position's;
- env-steps/s of the native vector env for B = 64, 256, 1024, 4096, of ``SyncVectorEnv`` of the
  same single env at B = 64 and 1024, measured in alternating bursts (as benchmarks/vector.py),
  and native/Sync at B = 1024;
- the sparse solvers' times (SFS, SFS-SS, SBS, DP at the preset's c and N) and the sensor
  game's double oracle (the preset's ``max_subset_size``), with ratios to ch4-position's.

Targets: the single view on grid-ieee14 ≥ 5,000 steps/s (several times what a CPU learner such
as stable-baselines3's PPO consumes, so the env does not limit single-env training); native
≥ 10× SyncVectorEnv at B = 1024 on grid-ieee14 (the gain that makes the batched engine worth
using) and ≥ 1× on grid-ieee118 (where the per-member n×n algebra dominates, batching must at
least not lose). The machine line comes first; figures on a
shared machine are noisy (the bursts alternate so that drift hits every env alike; ``--clock cpu``
times this process's CPU time, steadier under load than wall time, the default).

Two versions in one sitting: the script puts its own checkout after ``PYTHONPATH`` on the path,
so ``PYTHONPATH=<other checkout> python benchmarks/grid.py --presets grid-ieee118 --max-batch 256
--vector-only --clock cpu`` measures that checkout's package (docs/benchmarks.md's grid-ieee118
per member-step against the code of the time the target was set was measured so, alternating).
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
import gymnasium as gym
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.append(str(Path(__file__).resolve().parent.parent))  # after PYTHONPATH (see above)
from _timing import burst, rate

import fdia_env
from baselines.game import solve_double_oracle
from baselines.sparse import dp, sbs, sfs, sfs_ss
from fdia_env import scenarios

ENV_ID = "fdia_env/SparseAttack-v0"
PRESETS = ("ch4-position", "grid-ieee14", "grid-ieee30", "grid-ieee57", "grid-ieee118")
BATCHES = (64, 256, 1024, 4096)
CLOCK = time.perf_counter  # --clock cpu: time.process_time (this process's CPU time)
SYNC_BATCHES = (64, 1024)


def actions_for(space: gym.Space, batch: int | None, count: int, rng: np.random.Generator):
    """``count`` random actions (or (batch, ...) batches) attacking about two sensors a step."""
    shape = () if batch is None else (batch,)
    if isinstance(space, gym.spaces.MultiBinary):
        return [
            (rng.random((*shape, space.n)) < 2.0 / space.n).astype(np.int8) for _ in range(count)
        ]
    return [rng.integers(0, space.n, size=shape or None) for _ in range(count)]


def single_rate(name: str, steps: int) -> float:
    env = gym.make(ENV_ID, scenario=name)
    acts = actions_for(env.action_space, None, 256, np.random.default_rng(0))

    def run(n: int) -> None:
        env.reset(seed=0)
        for i in range(n):
            _, _, term, trunc, _ = env.step(acts[i % len(acts)])
            if term or trunc:
                env.reset()

    return rate(run, steps, repeats=3)


def vector_rates(name: str, batches, rounds: int, seconds: float) -> dict[str, float]:
    """Median env-steps/s per (kind, B), native and sync bursts alternating."""
    venvs = {}
    for B in batches:
        venvs[f"native B={B}"] = gym.make_vec(
            ENV_ID, num_envs=B, vectorization_mode="vector_entry_point", scenario=name
        )
        if B in SYNC_BATCHES:
            venvs[f"sync B={B}"] = gym.make_vec(
                ENV_ID, num_envs=B, vectorization_mode="sync", scenario=name
            )
    rng = np.random.default_rng(0)
    n = scenarios.get(name).system.n
    # a burst steps through its action list at least once: one action where a step is slow
    acts = {
        k: actions_for(v.single_action_space, v.num_envs, 4 if v.num_envs * n * n < 5e6 else 1, rng)
        for k, v in venvs.items()
    }
    for k, v in venvs.items():  # warm-up
        v.reset(seed=0)
        v.step(acts[k][0])
    rates: dict[str, list[float]] = {k: [] for k in venvs}
    for _ in range(rounds):
        for k, v in venvs.items():
            rates[k].append(burst(v, acts[k], seconds, CLOCK))
    for v in venvs.values():
        v.close()
    return {k: float(np.median(r)) for k, r in rates.items()}


def timed(call) -> float:
    t0 = time.perf_counter()
    call()
    return time.perf_counter() - t0


def solver_times(name: str, quick: bool) -> dict[str, float]:
    sc = scenarios.get(name)
    out = {
        "SFS": timed(lambda: sfs(sc)),
        "SFS-SS": timed(lambda: sfs_ss(sc)),
        "DP": timed(lambda: dp(sc)),
    }
    big = sc.system.M > 100
    out["SBS"] = float("nan") if quick and big else timed(lambda: sbs(sc))
    game = "ch5-game" if name == "ch4-position" else sc
    out["DO"] = float("nan") if quick and big else timed(lambda: solve_double_oracle(game))
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="shorter runs; no SBS/DO above 100 sensors")
    p.add_argument("--max-batch", type=int, default=4096, help="largest B of the native env")
    p.add_argument(
        "--presets", nargs="+", default=list(PRESETS), choices=PRESETS, help="presets measured"
    )
    p.add_argument(
        "--vector-only", action="store_true", help="the native vector env only (with its Sync)"
    )
    p.add_argument("--clock", choices=("wall", "cpu"), default="wall", help="what is timed")
    args = p.parse_args()
    global CLOCK
    CLOCK = time.process_time if args.clock == "cpu" else time.perf_counter
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, "
        f"python {platform.python_version()}, numpy {np.__version__}, "
        f"OPENBLAS_NUM_THREADS={os.environ['OPENBLAS_NUM_THREADS']} "
        f"(shared machine: figures are noisy); clock: {args.clock}; "
        f"fdia_env from {Path(fdia_env.__file__).parent.parent}"
    )
    rounds, seconds = (3, 0.3) if args.quick else (5, 0.5)
    # the slow configurations (a step of seconds) run 3 rounds of one step each
    singles, vectors, solvers = {}, {}, {}
    for name in args.presets:
        sc = scenarios.get(name)
        t0 = time.perf_counter()
        batches = [B for B in BATCHES if B <= args.max_batch]
        vectors[name] = vector_rates(name, batches, rounds, seconds)
        if not args.vector_only:
            singles[name] = single_rate(name, 2000 if sc.system.n > 50 else 5000)
            solvers[name] = solver_times(name, args.quick)
        print(
            f"  measured {name} (n = {sc.system.n}, M = {sc.system.M}) in "
            f"{time.perf_counter() - t0:.0f} s",
            flush=True,
        )
    first = args.presets[0]
    print("\nnative vector env, env-steps/s (SyncVectorEnv of the single env for comparison)")
    keys = list(vectors[first])
    at_1024 = "sync B=1024" in keys
    tail = f"{'native/Sync@1024':>18}" if at_1024 else ""
    print(f"{'preset':<14}" + "".join(f"{k:>16}" for k in keys) + tail)
    for name, rates in vectors.items():
        cells = "".join(f"{rates.get(k, np.nan):16,.0f}" for k in keys)
        if at_1024:
            cells += f"{rates['native B=1024'] / rates['sync B=1024']:17.1f}x"
        print(f"{name:<14}{cells}")
    if "native B=256" in vectors.get("grid-ieee118", {}):
        us = 1e6 / vectors["grid-ieee118"]["native B=256"]
        print(f"grid-ieee118 native B=256: {us:,.0f} µs per member-step")
    ref = "ch4-position"
    if args.vector_only or ref not in args.presets or "grid-ieee14" not in args.presets:
        return  # the ratios below need the reference and the full set
    print(f"\nsingle gymnasium.make view, {ENV_ID}, expected dynamics")
    print(f"{'preset':<14}{'steps/s':>12}{'vs ch4-position':>17}")
    for name, r in singles.items():
        print(f"{name:<14}{r:12,.0f}{r / singles[ref]:16.3f}x")
    print("\nsolver wall time (s); ratio to ch4-position (c = 5, N = 6; DO on ch5-game)")
    cols = list(solvers[ref])
    print(f"{'preset':<14}" + "".join(f"{c:>18}" for c in cols))
    for name, times in solvers.items():
        cells = "".join(f"{times[c]:9.3f} ({times[c] / solvers[ref][c]:5.0f}x)" for c in cols)
        print(f"{name:<14}{cells}")
    v14, v118 = vectors["grid-ieee14"], vectors.get("grid-ieee118", {})
    print(
        f"\ntargets: single view grid-ieee14 {singles['grid-ieee14']:,.0f} steps/s (>= 5,000); "
        f"native/Sync at B = 1024: grid-ieee14 "
        f"{v14.get('native B=1024', np.nan) / v14.get('sync B=1024', np.nan):.1f}x (>= 10x), "
        f"grid-ieee118 "
        f"{v118.get('native B=1024', np.nan) / v118.get('sync B=1024', np.nan):.2f}x (>= 1x)"
    )


if __name__ == "__main__":
    main()
