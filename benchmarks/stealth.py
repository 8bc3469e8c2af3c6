"""Speed of the static stealthy-attack baselines and env on IEEE 118.

Run: ``python benchmarks/stealth.py [--quick] [--milp-states K]``. Prints, after the machine
line:

- the security index of every state of IEEE 118 (117 states, 304 meters: every branch flow and
  bus injection) by minimum cut, and by the exact MILP on the first K states (default 2,
  ``--milp-states 117`` for all; the MILP times are per state, so the whole-grid figure is
  extrapolated when K < 117 and measured otherwise); the two agree state by state;
- env-steps/s of the attacker's native numpy vector env (``gymnasium.make_vec(
  "fdia_env/StealthAttack-v0", vectorization_mode="vector_entry_point")``) on grid-ieee118 at
  B = 4,096 (random shift actions, sampled and expected dynamics), and of ``SyncVectorEnv`` of
  the single view at B = 64 for scale;
- the same native vector env on ``backend="torch"`` (``--device cpu``, the default, or
  ``cuda``), whose expected dynamics equal numpy's to 1e-10.

Target: the security indices of all states of IEEE 118 in ≤ 60 s on 2 cores. Figures on a
shared machine are noisy.
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
sys.path.append(str(Path(__file__).resolve().parent.parent))  # after PYTHONPATH: it wins
from _timing import rate

import fdia_env  # noqa: F401
from baselines.stealth import security_index
from fdia_env.stealth import GYM_ID, static_estimation

TARGET_SECONDS = 60.0


def security_indices(milp_states: int) -> dict[str, float]:
    """Seconds of the min cut over all states and of the MILP over ``milp_states`` states."""
    t0 = time.perf_counter()
    est = static_estimation("ieee118")
    print(f"IEEE 118 model built in {time.perf_counter() - t0:.1f} s (pandapower)", flush=True)
    t0 = time.perf_counter()
    cut = security_index(est, method="mincut")
    cut_s = time.perf_counter() - t0
    states = list(range(min(milp_states, est.n)))
    t0 = time.perf_counter()
    milp = security_index(est, method="milp", states=states)
    milp_s = time.perf_counter() - t0
    agree = bool(np.array_equal(cut.indices[states], milp.indices[states]))
    if not agree:
        raise AssertionError("min cut and MILP disagree on IEEE 118")
    values, counts = np.unique(cut.indices, return_counts=True)
    print(
        f"IEEE 118 ({est.m} meters, {est.n} states): security indices "
        + ", ".join(f"{int(v)}: {c} states" for v, c in zip(values, counts, strict=True))
    )
    print(f"  min cut, all {est.n} states: {cut_s:.2f} s (target <= {TARGET_SECONDS:.0f} s)")
    per_state = milp_s / len(states)
    whole = "measured" if len(states) == est.n else "extrapolated"
    print(
        f"  MILP, {len(states)} states: {milp_s:.1f} s ({per_state:.2f} s per state; all "
        f"{est.n} states {per_state * est.n:.0f} s, {whole}); agrees with the cut",
        flush=True,
    )
    return {"mincut_s": cut_s, "milp_per_state_s": per_state}


def vector_rate(
    num_envs: int, dynamics: str, steps: int, native: bool = True, device: str | None = None
) -> float:
    """Env-steps/s (members × steps) of the stealth attacker's vector env on grid-ieee118.

    ``device``: run the native env on ``backend="torch"`` on that device (None: numpy).
    """
    mode = "vector_entry_point" if native else "sync"
    options = {} if device is None else {"backend": "torch", "device": device}
    venv = gym.make_vec(
        GYM_ID,
        num_envs=num_envs,
        vectorization_mode=mode,
        scenario="grid-ieee118",
        budget=20,
        dynamics=dynamics,
        **options,
    )
    venv.reset(seed=0)
    rng = np.random.default_rng(0)
    actions = (rng.random((8, num_envs, 117)) < 0.02).astype(np.int8)
    if device is not None:
        import torch

        actions = torch.as_tensor(actions, device=device)

    def run(k: int) -> None:
        for i in range(k):
            venv.step(actions[i % 8])

    per_step = rate(run, steps)
    venv.close()
    return per_step * num_envs


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="fewer repeats")
    p.add_argument("--milp-states", type=int, default=2, help="states solved by the MILP (1..117)")
    p.add_argument("--device", default="cpu", help="torch device of the torch-backend line")
    args = p.parse_args()
    if not 1 <= args.milp_states <= 117:
        p.error(f"--milp-states must be 1..117 (IEEE 118's states), got {args.milp_states}")
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, "
        f"python {platform.python_version()}, numpy {np.__version__}, "
        f"OPENBLAS_NUM_THREADS={os.environ['OPENBLAS_NUM_THREADS']} "
        "(shared machine: figures are noisy)"
    )
    security_indices(args.milp_states)
    steps = 5 if args.quick else 20
    for dynamics in ("sampled", "expected"):
        native = vector_rate(4096, dynamics, steps)
        sync = vector_rate(64, dynamics, steps, native=False)
        print(
            f"grid-ieee118 native vector env, B = 4,096, {dynamics}: {native:,.0f} env-steps/s "
            f"({1e6 / native * 4096:,.0f} µs per batch step); SyncVectorEnv B = 64: "
            f"{sync:,.0f} env-steps/s; native/Sync {native / sync:.1f}x",
            flush=True,
        )
        on_torch = vector_rate(4096, dynamics, steps, device=args.device)
        print(
            f"grid-ieee118 native vector env, backend='torch' on {args.device}, B = 4,096, "
            f"{dynamics}: {on_torch:,.0f} env-steps/s (numpy/torch {native / on_torch:.2f}x)",
            flush=True,
        )


if __name__ == "__main__":
    main()
