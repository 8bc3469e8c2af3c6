"""Env-steps per second of the native vector env against reference loops in the same run.

Run: ``python benchmarks/vector.py [--quick] [--sizes B ...] [--clock cpu]``. For B = 1, 64,
1024, 65536 envs (or ``--sizes``) it times ``fdia_env/SparseAttack-v0`` (ch4-position, expected
dynamics, random actions) as the native batched vector env and as Gymnasium's ``SyncVectorEnv``
of the same single env (B ≤ 1024), and Gymnasium's own native CartPole vector env, in
alternating short bursts (medians over rounds; ratios are medians of the per-round ratios).
Targets: at B = 65536 ≥ 1.5× CartPole's env-steps/s (CartPole's native vector env is
Gymnasium's reference for a cheap batched env; a step here is a few small matrix operations per
member, so it should not be slower), and at B = 1024 ≥ 50× ``SyncVectorEnv`` of the same env (the
gain that justifies a batched engine over Gymnasium's generic loop of single envs). To compare
two versions of the package in one sitting, run this script with ``PYTHONPATH`` set to each
checkout: the CartPole reference is measured in the same process. It times ``-v0`` on purpose
(the figures of every round since the first are of it), so Gymnasium's notice that a newer
version exists is silenced.
"""

from __future__ import annotations

import argparse
import os
import platform
import time
import warnings
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
import gymnasium as gym
import numpy as np
from _timing import burst, warm_up

import fdia_env

# -v0 is the env every figure of this benchmark is of; Gymnasium's "out of date" notice is noise
warnings.filterwarnings(
    "ignore", message=r".*SparseAttack-v0 is out of date", category=DeprecationWarning
)

CLOCK = time.perf_counter  # --clock cpu: time.process_time (this process's CPU time)


def interleaved(
    venvs: dict[str, gym.vector.VectorEnv], n_actions: dict[str, int], rounds: int, seconds: float
) -> dict[str, list[float]]:
    """Rates of several vector envs measured in alternating short bursts.

    The machines here drift in speed over tens of seconds; alternating bursts exposes every env
    to the same drift, so the per-round ratios are stable where back-to-back runs are not.
    """
    rng = np.random.default_rng(0)
    actions = {
        k: [rng.integers(0, n_actions[k], size=v.num_envs) for _ in range(14)]
        for k, v in venvs.items()
    }
    for k, v in venvs.items():  # warm-up
        v.reset(seed=0)
        warm_up(v, actions[k][:7])
    rates: dict[str, list[float]] = {k: [] for k in venvs}
    for _ in range(rounds):
        for k, v in venvs.items():
            rates[k].append(burst(v, actions[k], seconds, CLOCK))
    return rates


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="shorter runs")
    p.add_argument(
        "--sizes",
        type=int,
        nargs="+",
        default=[1, 64, 1024, 65536],
        help="batch sizes B (default: 1 64 1024 65536)",
    )
    p.add_argument(
        "--clock",
        choices=("wall", "cpu"),
        default="wall",
        help="wall time (default) or this process's CPU time, steadier on a shared machine",
    )
    args = p.parse_args()
    bad = [b for b in args.sizes if b < 1]
    if bad:
        p.error(f"--sizes must be positive batch sizes, got {bad}")
    global CLOCK
    CLOCK = time.process_time if args.clock == "cpu" else time.perf_counter
    budget = 0.1 if args.quick else 0.25
    print(
        f"machine: {_cpu_model()}, {platform.machine()}, {os.cpu_count()} cores, "
        f"python {platform.python_version()}, numpy {np.__version__}, "
        f"OPENBLAS_NUM_THREADS={os.environ['OPENBLAS_NUM_THREADS']}; "
        f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; clock: {args.clock}"
    )
    print(f"fdia_env from {os.path.relpath(Path(fdia_env.__file__).resolve().parent.parent)}")
    print(
        f"{'B':>6} {'native (env-steps/s)':>21} {'SyncVectorEnv':>14} {'CartPole native':>16} "
        f"{'native/Sync':>12} {'native/CartPole':>16}"
    )
    spread: dict[int, tuple[float, float]] = {}
    for B in args.sizes:
        kw = {"num_envs": B}
        venvs = {
            "native": gym.make_vec(
                "fdia_env/SparseAttack-v0", vectorization_mode="vector_entry_point", **kw
            ),
            "cartpole": gym.make_vec("CartPole-v1", vectorization_mode="vector_entry_point", **kw),
        }
        n_actions = {"native": 8, "cartpole": 2, "sync": 8}
        if B <= 1024:
            venvs["sync"] = gym.make_vec(
                "fdia_env/SparseAttack-v0", vectorization_mode="sync", **kw
            )
        rates = interleaved(venvs, n_actions, rounds=5 if args.quick else 9, seconds=budget)
        med = {k: float(np.median(v)) for k, v in rates.items()}
        per_round = np.array(rates["native"]) / np.array(rates["cartpole"])
        vs_cart = np.median(per_round)
        spread[B] = (float(per_round.min()), float(per_round.max()))
        vs_sync = (
            np.median(np.array(rates["native"]) / np.array(rates["sync"]))
            if "sync" in rates
            else float("nan")
        )
        print(
            f"{B:6d} {med['native']:21,.0f} {med.get('sync', float('nan')):14,.0f} "
            f"{med['cartpole']:16,.0f} {vs_sync:11.1f}x {vs_cart:15.2f}x"
        )
    for B, (lo, hi) in spread.items():
        print(f"B = {B}: native/CartPole per round from {lo:.2f}x to {hi:.2f}x")
    print("targets: native/Sync >= 50x at B = 1024; native/CartPole >= 1.5x at B = 65536")


def _cpu_model() -> str:
    """The CPU's model name (Linux), else the platform's processor string."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


if __name__ == "__main__":
    main()
