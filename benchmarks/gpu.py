"""GPU benchmark: env-only steps/s of the torch vector envs, and end-to-end torch PPO.

Run: ``python benchmarks/gpu.py [--device cuda] [--batches 16 18 20 22 24] [--grid-batches ...]
[--ppo-envs B] [--ppo-steps N]``. Prints the device (``torch.cuda.get_device_name`` or
``cpu``), then

- env-only env-steps/s of ``SparseAttack-v0`` ch4-position (expected dynamics) at
  B = 2^k for each ``--batches`` k (random actions drawn on the device beforehand; the device is
  synchronised before the clock stops);
- member-steps/s of the grid presets grid-ieee14 and grid-ieee118 (``action="single"``, the
  generic n×n path) at B = 2^k for each ``--grid-batches`` k; a batch that does not fit in the
  device's memory is reported as such;
- end-to-end torch PPO (:mod:`agents.torch_ppo`: rollouts and updates) on ch4-position with
  ``--ppo-envs`` members for ``--ppo-steps`` env steps: env-steps/s, the score against EXS
  (:func:`agents.evaluate.evaluate`) and the wall time,

each with its target next to it (met / MISSED). The targets are for one H100 and are set so that
on a GPU the environment is not what limits training: ch4-position at ≥ 2·10⁹ env-steps/s at
B = 2²², grid-ieee118 at ≥ 2·10⁵ member-steps/s (the generic n×n path, the most expensive
preset), and end-to-end torch PPO at ≥ 2·10⁶ env-steps/s reaching ≥ 99 % of the EXS optimum in at
most 30 s of wall time. On the CPU the defaults are small batches so that the script finishes
in about a minute.
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

import gymnasium as gym
import numpy as np
import torch

import fdia_env  # noqa: F401

CH4_TARGET = (22, 2e9)  # ≥ 2·10^9 env-steps/s at B = 2^22
GRID118_TARGET = 2e5  # member-steps/s
PPO_TARGET_SPS, PPO_TARGET_SCORE, PPO_TARGET_SECONDS = 2e6, 0.99, 30.0
SPARSE = "fdia_env/SparseAttack-v0"


def _verdict(ok: bool) -> str:
    return "met" if ok else "MISSED"


def _sync(device: str) -> None:
    if device.startswith("cuda"):
        torch.cuda.synchronize()


def env_steps_per_second(
    kwargs: dict, B: int, device: str, seconds: float, warmup: int = 2
) -> float | str:
    """Member-steps/s of ``SparseAttack-v0`` with ``kwargs`` at B members (or why not)."""
    try:
        env = gym.make_vec(
            SPARSE,
            num_envs=B,
            vectorization_mode="vector_entry_point",
            backend="torch",
            device=device,
            **kwargs,
        )
        env.reset(seed=0)
        n = int(env.single_action_space.n)
        gen = torch.Generator(device=device).manual_seed(0)
        actions = [torch.randint(0, n, (B,), generator=gen, device=device) for _ in range(8)]
        for a in actions[:warmup]:
            env.step(a)
        _sync(device)
        steps, t0 = 0, time.perf_counter()
        while True:
            for a in actions:
                env.step(a)
            steps += len(actions)
            _sync(device)
            if time.perf_counter() - t0 >= seconds:
                break
        return steps * B / (time.perf_counter() - t0)
    except torch.cuda.OutOfMemoryError:
        return "out of device memory"
    except (RuntimeError, MemoryError) as exc:
        if "out of memory" in str(exc).lower() or isinstance(exc, MemoryError):
            return "out of memory"
        raise
    finally:
        if device.startswith("cuda"):
            torch.cuda.empty_cache()


def ppo_end_to_end(B: int, total: int, device: str, seed: int) -> dict:
    """Train torch PPO on ch4-position; env-steps/s, score against EXS, wall time."""
    from agents.evaluate import evaluate
    from agents.registry import get
    from agents.torch_ppo import TorchPPOConfig, make_torch_env, train_torch_ppo

    entry = get("sparse_attack_v0")
    kwargs = entry.env_kwargs("ch4-position")
    wall0 = time.perf_counter()
    env = make_torch_env(entry.gym_id, B, device, **kwargs)
    result = train_torch_ppo(env, TorchPPOConfig(total_timesteps=total, num_envs=B), seed=seed)
    _sync(device)
    wall = time.perf_counter() - wall0
    ev = evaluate(result.policy, entry.gym_id, 3, 0, **kwargs)
    return {
        "timesteps": result.timesteps,
        "train_seconds": result.train_seconds,
        "wall": wall,
        "sps": result.steps_per_second,
        "score": ev.score,
        "reference": ev.reference_name,
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    p.add_argument("--batches", type=int, nargs="+", default=None, help="log2 B, ch4-position")
    p.add_argument("--grid-batches", type=int, nargs="+", default=None, help="log2 B, grids")
    p.add_argument("--ppo-envs", type=int, default=None, help="PPO members (B)")
    p.add_argument("--ppo-steps", type=int, default=None, help="PPO env steps")
    p.add_argument("--seconds", type=float, default=1.0, help="timing per env-only case")
    p.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--skip-ppo", action="store_true")
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    device = args.device
    gpu = device.startswith("cuda")
    if gpu and not torch.cuda.is_available():
        p.error(f"--device {device}: CUDA is not available here; use --device cpu")
    batches = args.batches or ([16, 18, 20, 22, 24] if gpu else [10, 12, 14])
    grid_batches = args.grid_batches or ([10, 12, 14, 16] if gpu else [4, 6])
    ppo_envs = args.ppo_envs or (65536 if gpu else 256)
    ppo_steps = args.ppo_steps or (30_000_000 if gpu else 60_000)
    for name, ks in (("--batches", batches), ("--grid-batches", grid_batches)):
        if any(k < 0 or k > 24 for k in ks):
            p.error(f"{name} takes log2 B in [0, 24], got {ks}")

    name = torch.cuda.get_device_name(device) if gpu else "cpu"
    print(
        f"device: {name} | machine: {platform.machine()}, {os.cpu_count()} cores, python "
        f"{platform.python_version()}, torch {torch.__version__} ({torch.get_num_threads()} "
        f"CPU threads), numpy {np.__version__}"
    )
    print("\nenv-only, torch backend, expected dynamics (random actions, prepared on the device)")
    print(f"  {'case':22s} {'B':>10} {'steps/s':>16}  target")
    for k in batches:
        sps = env_steps_per_second({"scenario": "ch4-position"}, 2**k, device, args.seconds)
        target = ""
        if k == CH4_TARGET[0]:
            target = f">= {CH4_TARGET[1]:.0e} at 2^22: " + (
                _verdict(sps >= CH4_TARGET[1]) if isinstance(sps, float) else "MISSED"
            )
        shown = f"{sps:16,.0f}" if isinstance(sps, float) else f"{sps:>16}"
        print(f"  {'ch4-position':22s} {'2^' + str(k):>10} {shown}  {target}", flush=True)
    if CH4_TARGET[0] not in batches:
        print(f"  ch4-position target >= {CH4_TARGET[1]:.0e} at B = 2^22: not measured (--batches)")
    for scenario in ("grid-ieee14", "grid-ieee118"):
        best = 0.0
        for k in grid_batches:
            kw = {"scenario": scenario, "action": "single"}
            sps = env_steps_per_second(kw, 2**k, device, args.seconds, warmup=1)
            if isinstance(sps, float):
                best = max(best, sps)
            shown = f"{sps:16,.0f}" if isinstance(sps, float) else f"{sps:>16}"
            print(f"  {scenario:22s} {'2^' + str(k):>10} {shown}  member-steps/s", flush=True)
        if scenario == "grid-ieee118":
            print(
                f"  grid-ieee118 best {best:,.0f} member-steps/s; target >= "
                f"{GRID118_TARGET:.0e}: {_verdict(best >= GRID118_TARGET)}"
            )
    if args.skip_ppo:
        return
    print(f"\nend-to-end torch PPO on ch4-position, B = {ppo_envs}, {ppo_steps:,} env steps")
    r = ppo_end_to_end(ppo_envs, ppo_steps, device, args.seed)
    print(
        f"  {r['timesteps']:,} steps in {r['train_seconds']:.1f} s training "
        f"({r['wall']:.1f} s wall with env build): {r['sps']:,.0f} env-steps/s; target >= "
        f"{PPO_TARGET_SPS:.0e}: {_verdict(r['sps'] >= PPO_TARGET_SPS)}"
    )
    print(
        f"  score {r['score']:.4%} of {r['reference']}; target >= {PPO_TARGET_SCORE:.0%} in <= "
        f"{PPO_TARGET_SECONDS:.0f} s wall: "
        f"{_verdict(r['score'] >= PPO_TARGET_SCORE and r['wall'] <= PPO_TARGET_SECONDS)}"
    )


if __name__ == "__main__":
    main()
